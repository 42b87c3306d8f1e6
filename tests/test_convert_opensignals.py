"""OpenSignals/BITalino text files, written in the documented layout (no redistributable sample is shared)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError, ConvertOptions, convert_file, detect


def _write(
    tmp: Path, *, device: str = "bitalino_rev", seq_gap: bool = False, header: dict | None = None
) -> tuple[Path, np.ndarray]:
    n = 500
    rng = np.random.default_rng(4)
    seq = np.arange(n) % 16
    if seq_gap:
        seq[300:] = (seq[300:] + 3) % 16
    a = rng.integers(0, 1024, (n, 3))
    rows = np.column_stack([seq, np.zeros((n, 4), int), a])
    hdr = header or {
        "00:07:80:3B:46:61": {
            "sensor": ["EMG", "EDA", "ACC"],
            "device name": "00:07:80:3B:46:61",
            "column": ["nSeq", "I1", "I2", "O1", "O2", "A1", "A2", "A3"],
            "sync interval": 2,
            "time": "14:40:49.587",
            "date": "2017-1-20",
            "device": device,
            "sampling rate": 1000,
            "label": ["A1", "A2", "A3"],
            "resolution": [4, 1, 1, 1, 1, 10, 10, 10],
            "firmware version": 1281,
        }
    }
    path = tmp / "opensignals_000780.txt"
    text = "# OpenSignals Text File Format\n# " + json.dumps(hdr) + "\n# EndOfHeader\n"
    text += "".join("\t".join(str(v) for v in r) + "\t\n" for r in rows)  # OpenSignals ends rows with a tab
    path.write_text(text)
    return path, a


def test_bitalino_counts_and_transfer_functions(tmp_path):
    path, a = _write(tmp_path)
    assert detect(path).name == "opensignals"
    rec = convert_file(path)
    (sig,) = rec.signals
    np.testing.assert_array_equal(sig.values[:, 5:8], a)
    np.testing.assert_array_equal(sig.t_ns[:3], [0, 1_000_000, 2_000_000])
    (ana,) = rec.analogs
    assert ana.channel_names == ["a1_emg", "a2_eda"] and ana.units == ["V", "uS"]
    np.testing.assert_allclose(ana.values[:, 0], (a[:, 0] / 1024 - 0.5) * 3.3 / 1009, rtol=1e-12)  # PLUX EMG
    np.testing.assert_allclose(ana.values[:, 1], a[:, 1] / 1024 * 3.3 / 0.132, rtol=1e-12)  # PLUX EDA
    assert any("A3 kept as ADC counts" in w for w in rec.warnings)
    assert rec.metadata["imulog.trial"]["start_time"] == "2017-01-20T14:40:49.587"


def test_other_plux_devices_stay_counts_and_lost_samples_are_said(tmp_path):
    path, _ = _write(tmp_path, device="biosignalsplux", seq_gap=True)
    rec = convert_file(path)
    assert not rec.analogs
    assert any("nSeq jumps at 1 row(s) (first line 304)" in w for w in rec.warnings)


def test_header_errors(tmp_path):
    path, _ = _write(tmp_path, header={"dev": {"column": ["nSeq", "A1"], "sampling rate": -5}})
    with pytest.raises(ConversionError, match=r"line 2: device dev: 'sampling rate' -5 is not a rate"):
        convert_file(path)
    path.write_text("# OpenSignals Text File Format\n# {broken\n# EndOfHeader\n1\t2\n")
    with pytest.raises(ConversionError, match=r"OpenSignals"):  # no JSON: named as a recognised variant
        convert_file(path)
    good, _ = _write(tmp_path)
    lines = good.read_text().splitlines()
    lines[100] = lines[100].replace("\t0\t", "\tx\t", 1)
    good.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConversionError, match=r"line 101, column '00:07:80:3B:46:61:I1': 'x' is not a number"):
        convert_file(good)
    good.write_text("\n".join(lines[:100] + [lines[101][:5]]) + "\n")
    rec = convert_file(good)
    assert len(rec.signals[0]) == 97 and any("last row cut short" in w for w in rec.warnings)


def test_opensignals_h5_matches_the_text_file(tmp_path):
    h5py = pytest.importorskip("h5py")
    txt, a = _write(tmp_path)
    h5 = tmp_path / "opensignals_000780.h5"
    with h5py.File(h5, "w") as f:  # the layout biosignalsnotebooks reads: <MAC>/raw/{nSeq, channel_N}
        g = f.create_group("00:07:80:3B:46:61")
        g.attrs["sampling rate"] = 1000
        g.attrs["nsamples"] = len(a)
        g.attrs["resolution"] = [4, 1, 1, 1, 1, 10, 10, 10]
        g.attrs["device"] = "bitalino_rev"
        g.attrs["date"] = "2017-1-20"
        g.attrs["time"] = "14:40:49.587"
        raw = g.create_group("raw")
        raw["nSeq"] = (np.arange(len(a)) % 16).reshape(-1, 1)
        for k, sensor in enumerate(["EMG", "EDA", "ACC"]):
            raw[f"channel_{k + 1}"] = a[:, k : k + 1]
            raw[f"channel_{k + 1}"].attrs["sensor"] = sensor
    assert detect(h5).name == "opensignals-h5"
    from_h5, from_txt = convert_file(h5), convert_file(txt)
    np.testing.assert_allclose(from_h5.analogs[0].values, from_txt.analogs[0].values, rtol=1e-15)
    np.testing.assert_array_equal(from_h5.signals[0].values[:, 1:], a)
    assert from_h5.metadata["imulog.trial"]["start_time"] == from_txt.metadata["imulog.trial"]["start_time"]


def _hangs(*args, **kwargs):
    import time

    time.sleep(3600)


def test_opensignals_h5_reader_runs_guarded(tmp_path, monkeypatch):
    """h5py reads the .h5 in a guarded child: a layout problem keeps its one-line message; a reader that never
    returns is stopped after the limit, in one line."""
    import time

    h5py = pytest.importorskip("h5py")
    from imulog.converters import ConversionError
    from imulog.converters.opensignals_h5 import read_opensignals_h5

    empty = tmp_path / "empty.h5"
    with h5py.File(empty, "w") as f:
        f.create_group("00:07:80:3B:46:61").create_group("raw")
    with pytest.raises(ConversionError, match=r"empty\.h5: device 00:07:80:3B:46:61: no raw/channel_N datasets$"):
        read_opensignals_h5(empty)
    monkeypatch.setattr(h5py, "File", _hangs)
    t0 = time.monotonic()
    with pytest.raises(ConversionError, match=r"h5py did not finish within 1 s") as e:
        read_opensignals_h5(empty, ConvertOptions(extra={"reader_timeout_s": 1.0}))
    assert time.monotonic() - t0 < 15 and "\n" not in str(e.value)


def test_opensignals_h5_saturated_counter_and_whole_second_time(tmp_path):
    """As in the real biosignalsnotebooks .h5 recordings (51 files checked by hand, MIT): a biosignalsplux file's
    uint16 nSeq counts up and then stays at 65535, which is no loss of samples (a real skip still is), and the
    header time may have no milliseconds (`12:02:03`)."""
    h5py = pytest.importorskip("h5py")
    n = 40000
    seq = np.minimum(np.arange(n) + 30000, 65535)
    seq[1000:] += 1  # one real lost sample at row 1000 (before the counter saturates)
    seq = np.minimum(seq, 65535).astype(np.uint16)
    h5 = tmp_path / "plux.h5"
    with h5py.File(h5, "w") as f:
        g = f.create_group("00:07:80:79:6F:DB")
        g.attrs["sampling rate"] = 1000
        g.attrs["resolution"] = [16]
        g.attrs["device"] = "channeller"
        g.attrs["date"] = "2019-03-18"
        g.attrs["time"] = "12:02:03"
        raw = g.create_group("raw")
        raw["nSeq"] = seq.reshape(-1, 1)
        raw["channel_1"] = np.arange(n, dtype=np.uint16).reshape(-1, 1)
        raw["channel_1"].attrs["sensor"] = "BVP"
    rec = convert_file(h5)
    (w,) = [w for w in rec.warnings if "nSeq" in w]
    assert "nSeq jumps at 1 row(s) (first sample 1000)" in w  # not the ~4500 rows at 65535
    assert rec.metadata["imulog.trial"]["start_time"] == "2019-03-18T12:02:03.000"
    assert not any("not understood" in w for w in rec.warnings)


@pytest.mark.parametrize("seq_gap", [False, True])
def test_text_in_pieces_equals_one_piece(tmp_path, seq_gap):
    """Tiny pieces give the one-piece conversion: values, times, the nSeq warning (its first line across a piece
    border), the counts warning and a cut final row."""
    import dataclasses

    from imulog.converters._binary import concat_chunks
    from imulog.converters.opensignals import iter_opensignals, read_opensignals

    path, _ = _write(tmp_path, seq_gap=seq_gap)
    path.write_bytes(path.read_bytes() + b"7\t0\t0")  # a copy cut inside its last row
    whole = read_opensignals(path)
    assert any("last row cut short" in w for w in whole.warnings)
    for piece_bytes in (700, 4000):
        pieces = list(iter_opensignals(path, piece_bytes=piece_bytes))
        joined = concat_chunks(pieces)
        assert len(pieces) > 1 and joined.warnings == whole.warnings and joined.metadata == whole.metadata
        for a, b in zip(joined.streams(), whole.streams(), strict=True):
            for f in dataclasses.fields(a):
                if isinstance(getattr(a, f.name), np.ndarray):
                    assert getattr(a, f.name).tobytes() == getattr(b, f.name).tobytes(), (a.topic, f.name)
