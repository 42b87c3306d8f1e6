"""ActiGraph: the real GT9X Link .gt3x (AGread, MIT) against ActiLife's CSV exports of the same device, idle-sleep
gaps, the NEO activity.bin layout (built byte by byte from the published format description), and damaged files."""

from __future__ import annotations

import io
import struct
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, detect
from imulog.converters._common import G0
from imulog.converters.actigraph import iter_record_batches, read_gt3x, unpack_12bit_yxz
from imulog.converters.actilife_csv import read_actilife_csv

from imulog.archive import TrialReader
from imulog.cli import cli

TICKS_AT_1970 = 621_355_968_000_000_000


@pytest.fixture(scope="module")
def gt3x_dir(shared_data: Path) -> Path:
    return shared_data / "devices" / "actigraph_gt3x"


@pytest.fixture(scope="module")
def rec(gt3x_dir: Path):
    return read_gt3x(gt3x_dir / "example.gt3x")


def _records(log: bytes) -> list[tuple[int, int, int, int]]:
    """(offset, type, seconds, size) of every log.bin record, walked independently of the converter."""
    out, pos = [], 0
    while pos < len(log):
        assert log[pos] == 0x1E
        typ, sec, size = struct.unpack_from("<BIH", log, pos + 1)
        out.append((pos, typ, sec, size))
        pos += 9 + size
    return out


def _rezip(src: Path, dst: Path, log: bytes) -> Path:
    with zipfile.ZipFile(src) as z:
        info = z.read("info.txt")
    with zipfile.ZipFile(dst, "w") as z:
        z.writestr("log.bin", log)
        z.writestr("info.txt", info)
    return dst


def test_streams_rates_and_start_time(rec):
    acc, imu = rec.imus
    assert acc.name == "tas1e31150129" and imu.name == "tas1e31150129_imu"
    assert len(acc) == 180 * 90  # 180 ACTIVITY2 records of 90 samples
    assert acc.gyr is None and imu.gyr is not None and imu.mag is not None and imu.temperature is not None
    assert np.all(np.diff(acc.t_ns) > 0) and np.all(np.diff(imu.t_ns) > 0)
    assert acc.t_ns[0] == 0 and acc.t_ns[-1] == 179 * 10**9 + round(89 * 1e9 / 90)
    trial = rec.metadata["imulog.trial"]
    assert trial == {"start_time": "2019-02-14T08:58:00.000-05:00", "time_zone": "-05:00"}
    dev = rec.metadata["imulog.device.tas1e31150129"]
    assert dev["accel_scale"] == 256.0 and dev["imu_gyro_scale"] == pytest.approx(16.384, abs=1e-5)
    assert dev["idle_sleep_gaps"] == 0 and dev["serial"] == "TAS1E31150129" and dev["rate_hz"] == 90.0
    dev_imu = rec.metadata["imulog.device.tas1e31150129_imu"]
    assert dev_imu["rate_hz"] == 100.0 and dev_imu["model"] == "ActiGraph Link IMU"
    # at rest on a waist: |acc| near 1 g in both accelerometers
    assert np.median(np.linalg.norm(acc.acc, axis=1)) == pytest.approx(G0, rel=0.05)
    assert np.median(np.linalg.norm(imu.acc, axis=1)) == pytest.approx(G0, rel=0.05)
    battery = next(s for s in rec.signals if s.topic.endswith("_battery"))
    assert battery.units == ["V"] and np.all((battery.values > 3.5) & (battery.values < 4.3))


def test_imu_matches_actilife_imu_csv(rec, gt3x_dir: Path):
    """ActiLife writes the IMU at exactly 100 Hz: seconds where the device recorded 100 samples are copied as they
    are (6 decimals), so they must agree; seconds with 101 samples are resampled by ActiLife and are skipped."""
    imu = rec.imus[1]
    csv = read_actilife_csv(gt3x_dir / "example-IMU.csv").imus[0]
    assert csv.name == imu.name
    ours = np.column_stack([imu.acc, imu.gyr, imu.mag, imu.temperature])
    theirs = np.column_stack([csv.acc, csv.gyr, csv.mag, csv.temperature])
    sec_ours, sec_csv = imu.t_ns // 10**9, csv.t_ns // 10**9
    compared = 0
    for s in np.unique(sec_csv):
        a, b = ours[sec_ours == s], theirs[sec_csv == s]
        if len(a) != 100:
            continue
        np.testing.assert_allclose(a[:, :3] / G0, b[:, :3] / G0, atol=1e-6, rtol=0)  # g
        np.testing.assert_allclose(np.degrees(a[:, 3:6]), np.degrees(b[:, 3:6]), atol=1e-6, rtol=0)  # deg/s
        np.testing.assert_allclose(a[:, 6:], b[:, 6:], atol=1e-5, rtol=0)  # uT, degC
        np.testing.assert_array_equal(imu.t_ns[sec_ours == s], csv.t_ns[sec_csv == s])
        compared += 1
    assert compared >= 20  # of the CSV's 23 s


def test_accelerometer_matches_actilife_raw_csv(rec, gt3x_dir: Path):
    raw = read_actilife_csv(gt3x_dir / "exampleRAW.csv").imus[0]
    acc = rec.imus[0]
    assert raw.name == acc.name and len(raw) == 10800
    n = len(raw)
    # ActiLife rounds g to 3 decimals: the exact counts/256 are within half a unit of the last place
    assert np.abs(acc.acc[:n] / G0 - raw.acc / G0).max() <= 0.0005 + 1e-9
    np.testing.assert_array_equal(acc.t_ns[:n], raw.t_ns)


def test_idle_sleep_seconds_are_nan_samples_not_zeros(gt3x_dir: Path, tmp_path: Path):
    """While the device sleeps it writes no ACTIVITY2 records: those seconds become NaN samples on the sample grid
    (the project's gap rule, imulog.process.gaps), never zeros or repeated values."""
    src = gt3x_dir / "example.gt3x"
    whole = read_gt3x(src).imus[0]
    with zipfile.ZipFile(src) as z:
        log = z.read("log.bin")
    recs = _records(log)
    t0 = next(sec for _, typ, sec, _ in recs if typ == 0x1A)
    asleep = set(range(t0 + 60, t0 + 65))  # 5 s of idle sleep
    kept = b"".join(log[o : o + 9 + size] for o, typ, sec, size in recs if not (typ == 0x1A and sec in asleep))
    acc = read_gt3x(_rezip(src, tmp_path / "sleep.gt3x", kept)).imus[0]
    np.testing.assert_array_equal(acc.t_ns, whole.t_ns)  # the same regular 90 Hz grid
    missing = np.isnan(acc.acc).any(axis=1)
    assert np.array_equal(np.nonzero(missing)[0], np.arange(60 * 90, 65 * 90))
    np.testing.assert_array_equal(acc.acc[~missing], whole.acc[~missing])
    assert np.count_nonzero(np.all(acc.acc == 0, axis=1)) == 0
    rec = read_gt3x(tmp_path / "sleep.gt3x")
    dev = rec.metadata["imulog.device.tas1e31150129"]
    assert dev["idle_sleep_gaps"] == 1 and dev["idle_sleep_s"] == 5
    # asleep until the end: no records after second 170, but info.txt's Last Sample Time is second 180
    tail = b"".join(log[o : o + 9 + size] for o, typ, sec, size in recs if not (typ == 0x1A and sec >= t0 + 170))
    rec = read_gt3x(_rezip(src, tmp_path / "tail.gt3x", tail))
    acc = rec.imus[0]
    np.testing.assert_array_equal(acc.t_ns, whole.t_ns)
    assert np.array_equal(np.nonzero(np.isnan(acc.acc).any(axis=1))[0], np.arange(170 * 90, 180 * 90))
    dev = rec.metadata["imulog.device.tas1e31150129"]
    assert dev["idle_sleep_gaps"] == 1 and dev["idle_sleep_s"] == 10
    assert dev["recording_end"] == "2019-02-14T09:01:00.000-05:00"


def _record(typ: int, sec: int, payload: bytes) -> bytes:
    head = struct.pack("<BBIH", 0x1E, typ, sec, len(payload))
    x = 0
    for b in head + payload:
        x ^= b
    return head + payload + bytes([~x & 0xFF])


def test_a_clock_jump_is_not_idle_sleep(gt3x_dir: Path, tmp_path: Path):
    src = gt3x_dir / "example.gt3x"
    with zipfile.ZipFile(src) as z:
        log = z.read("log.bin")
    recs = _records(log)
    k = next(i for i, (_, typ, _, _) in enumerate(recs) if typ == 0x1A) + 100  # the 101st ACTIVITY2 record
    out = b""
    for i, (o, typ, sec, size) in enumerate(recs):
        late = i >= k and typ == 0x1A
        out += _record(typ, sec + 40 * 86400, log[o + 8 : o + 8 + size]) if late else log[o : o + 9 + size]
    bad = _rezip(src, tmp_path / "jump.gt3x", out)
    with pytest.raises(ConversionError, match=rf"jump\.gt3x: log\.bin record {k}: ACTIVITY resumes 40 days after"):
        read_gt3x(bad)


def test_long_idle_sleep_comes_in_bounded_pieces(monkeypatch, gt3x_dir: Path, tmp_path: Path):
    import imulog.converters.actigraph as ag
    import imulog.converters.actigraph_decode as decode
    import imulog.converters.actigraph_format as fmt

    monkeypatch.setattr(fmt, "INLINE_FILL", 900)  # 10 s at 90 Hz
    for module in (fmt, decode):  # where the gaps are cut and where the long ones are filled
        monkeypatch.setattr(module, "FILL_PIECE", 1000)
    src = gt3x_dir / "example.gt3x"
    with zipfile.ZipFile(src) as z:
        log = z.read("log.bin")
    recs = _records(log)
    t0 = next(sec for _, typ, sec, _ in recs if typ == 0x1A)
    kept = b"".join(
        log[o : o + 9 + size] for o, typ, sec, size in recs if not (typ == 0x1A and t0 + 50 <= sec < t0 + 80)
    )
    path = _rezip(src, tmp_path / "long_sleep.gt3x", kept)
    pieces = [p.imus for p in ag.iter_chunks(path)]
    acc_pieces = [s for imus in pieces for s in imus if s.name == "tas1e31150129"]
    assert len(acc_pieces) == 1 + 3 + 1  # samples before, 2700 NaN samples in pieces of <= 1000, samples after
    assert [len(s) for s in acc_pieces[1:4]] == [1000, 1000, 700]
    assert all(np.isnan(s.acc).all() for s in acc_pieces[1:4])
    t = np.concatenate([s.t_ns for s in acc_pieces])
    np.testing.assert_array_equal(t, read_gt3x(src).imus[0].t_ns)


# ------------------------------------------------------------------------------------------ NEO activity.bin
def _pack_12bit_yxz(xyz: np.ndarray) -> bytes:
    """Independent encoder: samples as Y, X, Z 12-bit two's complement, most significant nibble first."""
    bits = "".join(f"{int(v) & 0xFFF:012b}" for x, y, z in xyz for v in (y, x, z))
    bits += "0" * (-len(bits) % 8)
    return int(bits, 2).to_bytes(len(bits) // 8, "big")


def test_12bit_decoder_on_the_published_example():
    # actigraph/NHANES-GT3X-File-Format activity.bin.md: "00 60 08 EB D0 07 00 9E BF 00 70 08 EB F0" ->
    # (Y, X, Z) = (6, 8, -323), (7, 9, -321), (7, 8, -321)
    data = bytes.fromhex("006008EBD007009EBF007008EBF0")
    xyz = unpack_12bit_yxz(data[:9])
    np.testing.assert_array_equal(xyz, [[8, 6, -323], [9, 7, -321]])
    assert _pack_12bit_yxz(np.array([[8, 6, -323], [9, 7, -321], [8, 7, -321]])) == data


def _neo_gt3x(path: Path, xyz: np.ndarray, rate: int = 30) -> Path:
    start = TICKS_AT_1970 + 1_206_792_000 * 10**7  # 2008-03-29 12:00:00 (the format description's example)
    info = (
        "Serial Number: NEO1C16110020\r\nFirmware: 2.2.0\r\nBattery Voltage: 4.25\r\n"
        f"Sample Rate: {rate}\r\nStart Date: {start}\r\nStop Date: 0\r\nDownload Date: {start + 10**11}\r\n"
        "Board Revision: 2\r\nSubject Name: josfew2342\r\n"
    )
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("activity.bin", _pack_12bit_yxz(xyz))
        z.writestr("info.txt", info)
    return path


def test_neo_activity_bin_round_trip(tmp_path: Path):
    rng = np.random.default_rng(7)
    xyz = rng.integers(-2048, 2048, size=(301, 3))  # odd count: the last sample ends on half a byte
    xyz[:5] = [[0, 0, 341], [-341, 0, 0], [2047, -2048, 0], [1, -1, 0], [8, 6, -323]]
    path = _neo_gt3x(tmp_path / "neo.gt3x", xyz)
    assert detect(path).name == "actigraph"
    rec = read_gt3x(path)
    acc = rec.imus[0]
    assert acc.name == "neo1c16110020" and len(acc) == 301
    np.testing.assert_allclose(acc.acc / G0, xyz / 341.0, atol=1e-12)
    np.testing.assert_array_equal(acc.t_ns, np.round(np.arange(301) * (1e9 / 30)).astype(np.int64))
    assert rec.metadata["imulog.trial"] == {
        "start_time": "2008-03-29T12:00:00.000",
        "time_zone": "unknown (device local time)",
    }


# --------------------------------------------------------------------------------------------- damage and CLI
def test_record_batches_are_bounded(gt3x_dir: Path):
    with zipfile.ZipFile(gt3x_dir / "example.gt3x") as z, z.open("log.bin") as f:
        batches = list(iter_record_batches(f, gt3x_dir / "example.gt3x", batch_bytes=64 * 1024))
    assert len(batches) >= 7 and all(len(b.buf) < 64 * 1024 + 3000 for b in batches)
    assert sum(len(b.types) for b in batches) == 374


@pytest.mark.parametrize("how", ["truncate", "flip"])
def test_damaged_log_one_line_error_naming_the_record(gt3x_dir: Path, tmp_path: Path, how: str):
    src = gt3x_dir / "example.gt3x"
    with zipfile.ZipFile(src) as z:
        log = z.read("log.bin")
    recs = _records(log)
    k = 200
    offset, _, _, size = recs[k]
    if how == "truncate":
        damaged = log[: offset + 9 + size // 2]
    else:
        b = bytearray(log)
        b[offset + 8 + size // 2] ^= 0x10
        damaged = bytes(b)
    bad = _rezip(src, tmp_path / f"{how}.gt3x", damaged)
    with pytest.raises(ConversionError) as e:
        read_gt3x(bad)
    msg = str(e.value)
    assert "\n" not in msg and bad.name in msg and f"record {k} " in msg
    assert ("truncated" in msg) if how == "truncate" else ("checksum" in msg)
    out = tmp_path / "out.mcap"
    r = CliRunner().invoke(cli, ["convert", str(bad), "-o", str(out)])
    assert r.exit_code != 0 and f"record {k} " in r.output
    assert not list(tmp_path.glob("*.mcap*"))


def test_damaged_zip_bytes(gt3x_dir: Path, tmp_path: Path):
    """A bit flipped in the .gt3x file itself (log.bin is stored uncompressed) is caught by the record checksum;
    a cut .gt3x has lost its ZIP directory."""
    data = bytearray((gt3x_dir / "example.gt3x").read_bytes())
    data[5000] ^= 0x01
    flipped = tmp_path / "flipped.gt3x"
    flipped.write_bytes(bytes(data))
    with pytest.raises(ConversionError, match=r"flipped\.gt3x: log\.bin record \d+ .*checksum"):
        read_gt3x(flipped)
    cut = tmp_path / "cut.gt3x"
    cut.write_bytes(bytes(data[:200_000]))
    with pytest.raises(ConversionError, match=r"cut\.gt3x: not a readable \.gt3x"):
        read_gt3x(cut)


def test_cli_converts_every_file_and_doctor_passes(gt3x_dir: Path, tmp_path: Path):
    expected = {"example.gt3x": "actigraph", "example-IMU.csv": "actilife-csv", "exampleRAW.csv": "actilife-csv"}
    for name, fmt in expected.items():
        src = gt3x_dir / name
        assert detect(src).name == fmt
        out = tmp_path / f"{src.stem}.mcap"
        r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
        assert r.exit_code == 0, r.output
        r = CliRunner().invoke(cli, ["doctor", str(out)])
        assert r.exit_code == 0, r.output
        with TrialReader(out) as trial:
            assert "start_time" in trial.metadata["imulog.trial"]
            assert any(t.startswith("/imu/tas1e31150129") for t in trial.topics())


def test_actilife_csv_errors(gt3x_dir: Path, tmp_path: Path):
    lines = (gt3x_dir / "exampleRAW.csv").read_text().splitlines()
    lines[4] = "Epoch Period (hh:mm:ss) 00:01:00,,"
    epoch = tmp_path / "epoch.csv"
    epoch.write_text("\n".join(lines[:20]) + "\n")
    with pytest.raises(ConversionError, match=r"epoch\.csv: line 5: epoch export"):
        read_actilife_csv(epoch)
    lines = (gt3x_dir / "exampleRAW.csv").read_text().splitlines()
    lines[15] = "0.027,oops,0.965"
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConversionError, match=r"bad\.csv: line 16, column 'Accelerometer Y': 'oops' is not a number"):
        read_actilife_csv(bad)
    data = (gt3x_dir / "exampleRAW.csv").read_bytes()
    cut = tmp_path / "cut.csv"
    cut.write_bytes(data[: len(data) // 2])
    n_lines = data[: len(data) // 2].count(b"\n") + 1
    with pytest.raises(ConversionError, match=rf"cut\.csv: line {n_lines}: the file ends inside a row"):
        read_actilife_csv(cut)
    out = tmp_path / "cut.mcap"
    r = CliRunner().invoke(cli, ["convert", str(cut), "-o", str(out)])
    assert r.exit_code != 0 and f"line {n_lines}" in r.output and not out.exists()
    frame = pd.read_csv(io.StringIO("\n".join(lines[10:12])))
    assert list(frame.columns) == ["Accelerometer X", "Accelerometer Y", "Accelerometer Z"]


def test_ggir_testfile_sum_differs_only_by_read_gt3xs_rounding(tmp_path: Path):
    """Held out: GGIR's actigraph_testfile.gt3x (wGT3X-BT, 30 Hz, with idle sleep; Apache-2.0, tests/data). GGIR's
    test_greadaccfile.R reads its 17,640 recorded samples with read.gt3x and sums x, y, z to 2732.35 g (tolerance
    0.01); imulog's values sum to 2731.566 g. The whole difference is read.gt3x rounding every value to 3 decimals
    (``scaleAndRoundActivity``, C ``round``: half away from zero): imulog's values are whole counts / 256, the
    same 17,640 samples are recorded (the idle-sleep seconds are NaN), and rounded that way they give GGIR's sum."""
    import lzma

    src = Path(__file__).parent / "data" / "actigraph_testfile.gt3x.xz"
    path = tmp_path / "actigraph_testfile.gt3x"
    path.write_bytes(lzma.decompress(src.read_bytes()))
    rec = read_gt3x(path)
    imu = rec.imus[0]
    recorded = np.isfinite(imu.acc).all(axis=1)
    assert recorded.sum() == 17640 and (~recorded).sum() == 53160 - 17640
    meta = rec.metadata[f"imulog.device.{imu.name}"]
    assert meta["rate_hz"] == 30.0 and meta["idle_sleep_gaps"] == 24 and meta["idle_sleep_s"] * 30 == (~recorded).sum()
    g = imu.acc[recorded] / G0
    np.testing.assert_allclose(g * 256, np.round(g * 256), rtol=0, atol=1e-9)  # whole counts at 256 per g
    milli = g * 1000
    read_gt3x_values = np.sign(milli) * np.floor(np.abs(milli) + 0.5) / 1000
    assert abs(read_gt3x_values.sum() - 2732.35) < 0.01
    assert abs(g.sum() - 2731.566) < 0.001  # exact: 699281 counts / 256
