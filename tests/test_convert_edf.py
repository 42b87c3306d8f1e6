"""EDF/EDF+/BDF: the shared Trigno EDF (../shared/data/devices/edf) and EDF+/BDF files written by pyedflib, read
back against pyedflib's own reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, detect
from imulog.converters._common import G0
from imulog.converters.edf import read_edf

from imulog.cli import cli

EDF = "devices/edf/trigno_emg.edf"


def test_shared_trigno_edf(shared_data: Path):
    path = shared_data / EDF
    assert detect(path).name == "edf"
    rec = read_edf(path)
    emg = rec.analogs[0]
    assert emg.name == "edf" and emg.units == ["V", "V"] and len(emg) == 3 * 1259
    assert [c.split(": ")[1] for c in emg.channel_names] == ["EMG sensor #1", "EMG sensor #8"]
    # the value by the EDF scaling from the file's own header fields (mV -> V)
    raw = path.read_bytes()
    hdr = 256 * 16
    first = int(np.frombuffer(raw[hdr : hdr + 2], "<i2")[0])
    expect = -461.585 + (first + 32768) * (474.5098 + 461.585) / 65535
    assert emg.values[0, 0] == pytest.approx(expect * 1e-3, rel=1e-12)
    assert rec.metadata["imulog.trial"]["start_time"] == "2025-01-24T08:57:33"
    # this file's ACC/GYRO channels have physical min == max (pyedflib refuses it): every value 0, said per channel
    assert sum("physical min == max" in w for w in rec.warnings) == 12
    assert [i.name for i in rec.imus] == ["mini_sensor_10", "mini_sensor_11"]  # "ACC sensor" channels in g
    # "GYRO sensor" channels in "A /s": the degree sign of "Â°/s" (UTF-8 read as Latin-1) folded to ASCII
    assert np.all(rec.imus[0].acc == 0) and rec.imus[0].gyr is not None and np.all(rec.imus[0].gyr == 0)
    assert rec.imus[0].meta["channels"]["gyr.x"].endswith("Mini sensor 10:")
    assert all("A /s" not in u for a in rec.analogs for u in a.units)


def test_shared_trigno_edf_equals_mne(shared_data: Path):
    """MNE (BSD-3) reads the file pyedflib refuses; its EMG channels (V) equal ours. MNE resamples the 148 Hz
    channels to the file's highest rate, so only the full-rate channels are compared."""
    mne = pytest.importorskip("mne")
    path = shared_data / EDF
    raw = mne.io.read_raw_edf(path, preload=True, verbose="error")
    rec = read_edf(path)
    emg = rec.analogs[0]
    data = raw.get_data()
    assert raw.info["sfreq"] == 1259 and data.shape[1] == len(emg)
    np.testing.assert_allclose(emg.values[:, 0], data[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(emg.values[:, 1], data[7], rtol=0, atol=1e-12)
    assert raw.info["meas_date"].replace(tzinfo=None).isoformat() == rec.metadata["imulog.trial"]["start_time"]


def _write(path: Path, bdf: bool) -> tuple[list[np.ndarray], list[tuple[float, float, str]]]:
    """An EDF+/BDF+ walk: Acc X-Z (g), Gyro X-Z (deg/s), EMG RF (uV, 1 kHz), Temp (degC, 1 Hz), three annotations."""
    pyedflib = pytest.importorskip("pyedflib")
    kind = pyedflib.FILETYPE_BDFPLUS if bdf else pyedflib.FILETYPE_EDFPLUS
    labels = ["Acc X", "Acc Y", "Acc Z", "Gyro X", "Gyro Y", "Gyro Z", "EMG RF", "Temp"]
    dims = ["g", "g", "g", "deg/s", "deg/s", "deg/s", "uV", "degC"]
    rates = [100] * 6 + [1000, 1]
    rng = np.random.default_rng(3)
    n_s = 5
    data = [
        rng.uniform(-2, 2, r * n_s) * (100 if d == "deg/s" else 500 if d == "uV" else 1)
        for r, d in zip(rates, dims, strict=True)
    ]
    data[-1] = 30 + rng.uniform(0, 1, n_s)
    heads = []
    for lab, dim, r, x in zip(labels, dims, rates, data, strict=True):
        heads.append(
            {
                "label": lab,
                "dimension": dim,
                "sample_frequency": r,
                "physical_min": float(np.floor(x.min()) - 1),
                "physical_max": float(np.ceil(x.max()) + 1),
                "digital_min": -8388608 if bdf else -32768,
                "digital_max": 8388607 if bdf else 32767,
                "transducer": "",
                "prefilter": "",
            }
        )
    w = pyedflib.EdfWriter(str(path), len(labels), file_type=kind)
    w.setSignalHeaders(heads)
    from datetime import datetime

    w.setStartdatetime(datetime(2024, 3, 5, 14, 30, 7))
    events = [(0.5, 0.0, "start walking"), (2.25, 1.5, "turn"), (4.0, -1, "stop")]
    for on, dur, text in events:
        w.writeAnnotation(on, dur, text)
    w.writeSamples(data)
    w.close()
    return data, events


@pytest.mark.parametrize("bdf", [False, True])
def test_matches_pyedflib(tmp_path: Path, bdf: bool):
    pyedflib = pytest.importorskip("pyedflib")
    path = tmp_path / ("walk.bdf" if bdf else "walk.edf")
    _write(path, bdf)
    assert detect(path).name == "edf"
    rec = read_edf(path)
    ref = pyedflib.EdfReader(str(path))
    try:
        phys = [ref.readSignal(i) for i in range(ref.signals_in_file)]
        on, dur, text = ref.readAnnotations()
    finally:
        ref.close()
    (imu,) = rec.imus
    assert imu.name == "imu"  # 'Acc X'/'Gyro X' name no sensor: one IMU
    np.testing.assert_allclose(imu.acc / G0, np.column_stack(phys[:3]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.degrees(imu.gyr), np.column_stack(phys[3:6]), rtol=0, atol=1e-9)
    assert len(imu) == 500 and imu.t_ns[1] == 10_000_000 and imu.meta["rate_hz"] == 100
    emg = next(a for a in rec.analogs if a.channel_names == ["EMG RF"])
    np.testing.assert_allclose(emg.values[:, 0], phys[6] * 1e-6, rtol=0, atol=1e-15)
    assert emg.units == ["V"] and len(emg) == 5000 and emg.t_ns[1] == 1_000_000
    temp = next(a for a in rec.analogs if a.channel_names == ["Temp"])
    np.testing.assert_allclose(temp.values[:, 0], phys[7])
    assert temp.units == ["degC"] and temp.name == "edf_1hz"
    (ev,) = rec.events
    np.testing.assert_array_equal(ev.start_ns, np.round(on * 1e9).astype(np.int64))
    assert ev.labels == list(text)
    np.testing.assert_array_equal(ev.end_ns - ev.start_ns, np.round(np.maximum(dur, 0) * 1e9).astype(np.int64))
    assert rec.metadata["imulog.trial"]["start_time"] == "2024-03-05T14:30:07"
    assert rec.metadata["imulog.device.edf"]["format"] == ("bdf" if bdf else "edf+")


def test_discontinuous_records_keep_their_onsets(tmp_path: Path):
    """EDF+D: each record's first time-keeping annotation is its onset (a gap stays a gap)."""
    path = tmp_path / "c.edf"
    _write(path, False)
    data = bytearray(path.read_bytes())
    ns = int(data[252:256])
    data[192:236] = b"EDF+D".ljust(44)
    hdr = 256 * (ns + 1)
    spr = [int(data[256 + ns * 216 + 8 * i : 256 + ns * 216 + 8 * (i + 1)]) for i in range(ns)]
    rec_bytes = 2 * sum(spr)
    ann_off = 2 * sum(spr[:-1])
    r3 = hdr + 3 * rec_bytes + ann_off
    assert data[r3 : r3 + 4] == b"+3\x14\x14"
    data[r3 : r3 + 4] = b"+9\x14\x14"  # records 3 and 4 start 6 s later
    r4 = hdr + 4 * rec_bytes + ann_off
    data[r4 : r4 + 4] = b"+10\x14"[:4]
    data[r4 : r4 + 5] = b"+10\x14\x14"
    path.write_bytes(bytes(data))
    rec = read_edf(path)
    t = rec.imus[0].t_ns
    assert t[300] == 9_000_000_000 and t[400] == 10_000_000_000 and t[299] == 2_990_000_000


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda d: d[:200], r"ends inside the 256-byte EDF header"),
        (lambda d: b"9" + d[1:], r"neither EDF '0' nor BDF"),
        (lambda d: d[:184] + b"9999    " + d[192:], r"header bytes 9999"),
        (lambda d: d[:244] + b"0       " + d[252:], r"record duration 0"),
    ],
)
def test_damaged_header_one_line_error(tmp_path: Path, damage, message):
    good = tmp_path / "g.edf"
    _write(good, False)
    bad = tmp_path / "bad.edf"
    bad.write_bytes(damage(good.read_bytes()))
    with pytest.raises(ConversionError, match=message) as e:
        read_edf(bad)
    assert "\n" not in str(e.value) and "bad.edf" in str(e.value)


def test_truncated_data_reads_whole_records_with_a_warning(tmp_path: Path):
    good = tmp_path / "g.edf"
    _write(good, False)
    data = good.read_bytes()
    bad = tmp_path / "cut.edf"
    bad.write_bytes(data[: len(data) - 1000])
    rec = read_edf(bad)
    assert len(rec.imus[0]) == 400 and any("declares 5 data records, the file holds 4" in w for w in rec.warnings)


def test_cli_convert_and_doctor(shared_data: Path, tmp_path: Path):
    out = tmp_path / "emg.mcap"
    r = CliRunner().invoke(cli, ["convert", str(shared_data / EDF), "-o", str(out)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["doctor", str(out)])
    assert r.exit_code == 0, r.output


def test_pieces_equal_the_whole(tmp_path: Path):
    from imulog.converters.edf import iter_chunks

    path = tmp_path / "walk.bdf"
    _write(path, True)
    whole = read_edf(path)
    per_record = sum(s["samples"] for s in whole.metadata["imulog.device.edf"]["signals"])
    pieces = list(iter_chunks(path, max_samples=2 * per_record))  # 5 records of 1 s: pieces of 2, 2 and 1
    assert [len(p.imus[0]) for p in pieces] == [200, 200, 100]
    np.testing.assert_array_equal(np.concatenate([p.imus[0].acc for p in pieces]), whole.imus[0].acc)
    np.testing.assert_array_equal(np.concatenate([p.imus[0].t_ns for p in pieces]), whole.imus[0].t_ns)
    for j, a in enumerate(whole.analogs):
        np.testing.assert_array_equal(np.concatenate([p.analogs[j].values for p in pieces]), a.values)
        np.testing.assert_array_equal(np.concatenate([p.analogs[j].t_ns for p in pieces]), a.t_ns)
    assert len(pieces[0].events) == 1 and not pieces[1].events


def _set_dimensions(path: Path, dims: dict[int, bytes]) -> None:
    """Overwrite signals' 8-byte physical dimension fields (header byte 256 + ns*96 + i*8) with raw bytes."""
    raw = bytearray(path.read_bytes())
    ns = int(raw[252:256])
    for i, d in dims.items():
        at = 256 + ns * 96 + i * 8
        raw[at : at + 8] = d.ljust(8)[:8]
    path.write_bytes(bytes(raw))


@pytest.mark.parametrize(
    ("acc_dim", "acc_to_g", "gyr_dim", "gyr_to_deg"),
    [
        (b"m/s2", 1 / G0, "\u00c2\u00b0/s".encode("latin-1"), 1.0),  # UTF-8 degree sign read as Latin-1
        (b"m.s-2", 1 / G0, b"A /s", 1.0),  # ... and folded to ASCII (the shared Trigno file)
        (b"m s-2", 1 / G0, b"\xb0/s", 1.0),  # Latin-1 degree sign
        (b"mg", 1e-3, b"?/s", 1.0),  # unencodable character
        (b"G", 1.0, b"deg.s-1", 1.0),
        (b"m/s/s", 1 / G0, b"rad/s", 180 / np.pi),
        (b"m*s^-2", 1 / G0, b"mdps", 1e-3),
    ],
)
def test_physical_dimension_spellings(tmp_path: Path, acc_dim, acc_to_g, gyr_dim, gyr_to_deg):
    """Accelerometer and gyroscope channels are found from their physical dimension however the writer spelled it
    (EDF+ SI spellings, ``m/s/s``, and the degree sign's usual manglings), and scaled by what it says."""
    path = tmp_path / "walk.edf"
    data, _ = _write(path, bdf=False)
    _set_dimensions(path, {0: acc_dim, 1: acc_dim, 2: acc_dim, 3: gyr_dim, 4: gyr_dim, 5: gyr_dim})
    rec = read_edf(path)
    (imu,) = rec.imus
    assert imu.gyr is not None, [a.units for a in rec.analogs]
    np.testing.assert_allclose(imu.acc / G0, np.column_stack(data[:3]) * acc_to_g, rtol=0, atol=1e-2 * acc_to_g)
    np.testing.assert_allclose(
        np.degrees(imu.gyr), np.column_stack(data[3:6]) * gyr_to_deg, rtol=0, atol=0.01 * gyr_to_deg
    )
    assert [a.channel_names for a in rec.analogs] == [["EMG RF"], ["Temp"]]


def test_unknown_dimension_stays_analog(tmp_path: Path):
    """A gyroscope channel whose dimension names no rate (here amperes) is not guessed: kept analog, unit as found."""
    path = tmp_path / "walk.edf"
    _write(path, bdf=False)
    _set_dimensions(path, {3: b"A", 4: b"A", 5: b"A"})
    rec = read_edf(path)
    assert rec.imus[0].gyr is None
    gyro = next(a for a in rec.analogs if "Gyro X" in a.channel_names)
    assert gyro.units[gyro.channel_names.index("Gyro X")] == "A"
