"""Every reader that yields its recording in pieces (``Converter.iter_chunks``) gives, with a tiny piece size, what
it gives in one piece: values, times, counts, warnings, metadata and sources (issue 24, point 4). Real files from
``../shared/data`` and the repository's simulated recording; host-clock text generated in the documented layout."""

from __future__ import annotations

import dataclasses
import functools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError
from imulog.converters._binary import concat_chunks
from imulog.converters.base import ConvertOptions
from imulog.converters.registry import get

from imulog.model import Recording

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from bench_convert_pieces import host_clock_csv  # noqa: E402  (the documented layout, shared with the benchmark)


def assert_same_recording(a: Recording, b: Recording) -> None:
    """``a`` and ``b`` hold the same streams bit for bit, the same warnings, metadata and sources."""
    assert [s.topic for s in a.streams()] == [s.topic for s in b.streams()]
    for sa, sb in zip(a.streams(), b.streams(), strict=True):
        for f in dataclasses.fields(sa):
            va, vb = getattr(sa, f.name), getattr(sb, f.name)
            if isinstance(va, np.ndarray):
                assert va.dtype == vb.dtype and va.shape == vb.shape, (sa.topic, f.name)
                assert va.tobytes() == vb.tobytes(), (sa.topic, f.name)
            else:
                assert va == vb, (sa.topic, f.name)
    assert a.warnings == b.warnings
    assert a.metadata == b.metadata
    assert a.sources == b.sources


def _pieces_equal_whole(pieces: list[Recording], whole: Recording) -> None:
    assert len(pieces) > 1, "the tiny piece size must cut the file"
    assert_same_recording(concat_chunks(pieces), whole)


# (converter name, path under ../shared/data or the repository, how to set a tiny piece size)
TEXT = "imulog.converters._pieces.PIECE_BYTES"
CASES = [
    ("delimited", "imu_text/fusion_sensor_data.csv", (TEXT, 4096)),
    ("delimited", "imu_text/shimmer_consensys_export.csv", (TEXT, 700)),  # host clock: stamps repeat
    ("delimited", "repo:recordings/sim/r2g_s00_t00_imu.csv", (TEXT, 65536)),  # no time column: mapping and rate
    ("gaitmap", "gaitmap_foot/imu_sample.csv", (TEXT, 16384)),
    ("actilife-csv", "devices/actigraph_gt3x/exampleRAW.csv", (TEXT, 8192)),  # no time column: banner rate
    ("actilife-csv", "devices/actigraph_gt3x/example-IMU.csv", (TEXT, 8192)),  # formatted local time stamps
    ("axivity-csv", "devices/axivity_csv/ax3_testfile_unix_timestamps.csv", (TEXT, 2048)),
    ("movella-dot", "devices/movella_dot_csv/bei_D4CA6EF17860_20210830_170505.csv", (TEXT, 4096)),
    ("nilspod", "devices/nilspod/NilsPodX-6F13_20210109_162824.bin", ("imulog.converters.nilspod.PIECE_SAMPLES", 500)),
    ("nilspod", "devices/nilspod/NilsPodX-6F13_20210109_162824_data.csv", (TEXT, 4096)),  # NilsPodLib's export
    ("xsens", "devices/xsens_mtmanager/MT_012005D6_031-000_00B421AF.txt", (TEXT, 16384)),  # old header, Mat
    ("xsens", "devices/xsens_mtmanager/MT_01200454_000-000_00B40DE4.txt", (TEXT, 64)),  # no SampleTimeFine
    ("xsens", "devices/xsens_mtmanager/MT2022_ACC_GYRO_ROT_MAT_SPACE_00B42D4B.txt", (TEXT, 64)),  # space-delimited
    ("actigraph", "devices/actigraph_gt3x/example.gt3x", None),
    ("axivity", "devices/axivity_cwa/ax3_sample.cwa", None),
    ("axivity", "devices/axivity_cwa/ax6_sample.cwa", None),
    ("edf", "devices/edf/trigno_emg.edf", None),
    ("geneactiv", "devices/geneactiv_bin/GENEActiv_testfile.bin", ("imulog.converters.geneactiv.PAGES_PER_CHUNK", 3)),
    ("xdf", "devices/xdf/clock_resets.xdf", None),
    ("xdf", "devices/xdf/minimal.xdf", None),
    ("xdf", "devices/xdf/empty_streams.xdf", None),
]


def _path(rel: str, shared_data: Path) -> Path:
    return REPO / rel[5:] if rel.startswith("repo:") else shared_data / rel


def _tiny_pieces(name: str, path: Path, setting, monkeypatch) -> list[Recording]:
    conv = get(name)
    if setting is not None:
        monkeypatch.setattr(*setting)
        return list(conv.iter_chunks(path))
    if name == "actigraph":
        import imulog.converters.actigraph as ag
        from imulog.converters.actigraph_records import iter_record_batches

        monkeypatch.setattr(ag, "iter_record_batches", functools.partial(iter_record_batches, batch_bytes=4096))
        return list(conv.iter_chunks(path))
    if name == "axivity":
        from imulog.converters.axivity import iter_chunks

        return list(iter_chunks(path, blocks_per_chunk=2))
    if name == "edf":
        from imulog.converters.edf import iter_chunks

        return list(iter_chunks(path, max_samples=2000))
    if name == "xdf":
        from imulog.converters.xdf import iter_chunks

        return list(iter_chunks(path, piece_bytes=64))
    raise AssertionError(name)


@pytest.mark.parametrize(("name", "rel", "setting"), CASES, ids=[f"{c[0]}:{Path(c[1]).name}" for c in CASES])
def test_tiny_pieces_equal_one_piece_on_real_files(name, rel, setting, shared_data, monkeypatch):
    path = _path(rel, shared_data)
    whole = get(name).convert(path)
    pieces = _tiny_pieces(name, path, setting, monkeypatch)
    _pieces_equal_whole(pieces, whole)


# ----------------------------------------------------------------------------------- host clock in pieces
def test_host_clock_fit_is_the_same_in_any_pieces(tmp_path):
    from imulog.converters.delimited import iter_delimited, read_delimited

    path = tmp_path / "shimmer.csv"
    stamps = host_clock_csv(path, 20_000)
    whole = read_delimited(path)
    (imu,) = whole.imus
    assert np.any(np.diff(stamps) == 0) and np.all(np.diff(imu.t_ns) > 0)
    assert "least-squares" in whole.metadata["imulog.device.shimmer_40ac"]["time"]["clock"]
    assert np.abs(imu.t_ns - stamps * 1e6).max() < 80e6  # within the packets' delay and jitter
    assert abs(1e9 / np.median(np.diff(imu.t_ns)) - 51.2) < 0.01
    for piece_bytes in (3000, 50_000, 400_000):
        _pieces_equal_whole(list(iter_delimited(path, piece_bytes=piece_bytes)), whole)


@pytest.mark.parametrize("row", [150, 9_000, 19_990])
def test_a_host_stamp_far_off_the_line_names_the_same_line_in_pieces(row, tmp_path):
    from imulog.converters.delimited import iter_delimited, read_delimited

    path = tmp_path / "late.csv"
    host_clock_csv(path, 20_000, late={row: 5.0, row + 3: 9.0})  # two late stamps: the first is named
    with pytest.raises(ConversionError) as whole:
        read_delimited(path)
    assert "more than 1 s off the sample clock" in str(whole.value) and f"line {row + 4}" in str(whole.value)
    for piece_bytes in (3000, 50_000):
        with pytest.raises(ConversionError) as pieces:
            list(iter_delimited(path, piece_bytes=piece_bytes))
        assert str(pieces.value) == str(whole.value)


def test_shimmer_four_row_export_in_pieces(tmp_path):
    from imulog.converters.shimmer import iter_shimmer, read_shimmer

    path = tmp_path / "capture.csv"
    n = 5000
    rng = np.random.default_rng(1)
    rows = np.column_stack([np.arange(n) * 1000 / 51.2, rng.normal(0, 1, (n, 3)), rng.normal(0, 9, (n, 3))])
    sig = ["Timestamp"] + [f"Accel_LN_{a}" for a in "XYZ"] + [f"Gyro_{a}" for a in "XYZ"]
    with open(path, "w") as f:
        f.write("\t".join(["Shimmer_8E5E"] * 7) + "\n" + "\t".join(sig) + "\n" + "\t".join(["CAL"] * 7) + "\n")
        f.write("\t".join(["mSecs"] + ["m/(sec^2)"] * 3 + ["deg/sec"] * 3) + "\n")
        np.savetxt(f, rows, delimiter="\t", fmt="%.4f")
    whole = read_shimmer(path)
    assert len(whole.imus[0]) == n
    _pieces_equal_whole(list(iter_shimmer(path, ConvertOptions(), piece_bytes=20_000)), whole)


# ----------------------------------------------------------------------------------- bounded memory
_PEAK = """
import resource, sys
from imulog.converters.delimited import iter_delimited
n = 0
for piece in iter_delimited(sys.argv[1], piece_bytes=1 << 20):
    n += len(piece.imus[0])
print(n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def _peak_kib(path: Path) -> tuple[int, int]:
    out = subprocess.run([sys.executable, "-c", _PEAK, str(path)], capture_output=True, text=True, check=True)
    n, kib = out.stdout.split()
    return int(n), int(kib)


def test_host_clock_text_converts_in_bounded_memory(tmp_path):
    """Peak memory of converting a host-clock file in 1 MiB pieces does not grow with the file: a file 4x as long
    (about 60 MB more text, 45 MB more values) peaks within 15 MB of the short one (the whole file in memory would
    add at least its text and values: 100 MB)."""
    short, long = tmp_path / "short.csv", tmp_path / "long.csv"
    host_clock_csv(short, 250_000)
    host_clock_csv(long, 1_000_000)
    n_short, peak_short = _peak_kib(short)
    n_long, peak_long = _peak_kib(long)
    assert (n_short, n_long) == (250_000, 1_000_000)
    grow_mb = (peak_long - peak_short) / 1024
    assert grow_mb < 15, (
        f"peak grew {grow_mb:.0f} MB from {short.stat().st_size >> 20} to {long.stat().st_size >> 20} MB of text"
    )


def test_compressed_text_comes_in_the_inner_readers_pieces(shared_data, tmp_path, monkeypatch):
    import gzip

    src = shared_data / "imu_text/fusion_sensor_data.csv"
    path = tmp_path / "fusion.csv.gz"
    path.write_bytes(gzip.compress(src.read_bytes()))
    conv = get("compressed")
    whole = conv.convert(path)
    assert whole.sources == [str(path)] and len(whole.imus[0]) > 0
    monkeypatch.setattr(TEXT, 4096)
    _pieces_equal_whole(list(conv.iter_chunks(path)), whole)


def test_movella_dot_wrap_of_sample_time_fine_across_pieces(tmp_path):
    from imulog.converters.movella_dot import WRAP, iter_movella_dot, read_movella_dot

    n = 6000
    us = (WRAP - 30 * 16_667 + np.arange(n) * 16_667) % WRAP  # 60 Hz; the 32-bit counter wraps at row 30
    rng = np.random.default_rng(2)
    rows = np.column_stack([np.arange(n), us, rng.normal(0, 1, (n, 6))])
    path = tmp_path / "dot_D4CA6EF17860_20210830_170505.csv"
    header = "PacketCounter,SampleTimeFine," + ",".join(f"{q}_{a}" for q in ("Acc", "Gyr") for a in "XYZ")
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt=["%d", "%d"] + ["%.5f"] * 6)
    whole = read_movella_dot(path)
    assert np.all(np.diff(whole.imus[0].t_ns) == 16_667_000)
    _pieces_equal_whole(list(iter_movella_dot(path, piece_bytes=5000)), whole)


def test_adc_text_in_pieces(tmp_path):
    from imulog.converters.adc import iter_adc, read_adc

    rng = np.random.default_rng(4)
    counts = rng.integers(300, 700, (20_000, 3))
    lines = [f"X={x} Y={y} Z={z}" for x, y, z in counts]
    path = tmp_path / "witilt.txt"
    path.write_text("\n".join(lines) + "\nX=51")  # a logger that lost power mid-line
    whole = read_adc(path, rate_hz=50.0)
    assert len(whole.imus[0]) == 20_000 and "cut short" in whole.warnings[0]
    _pieces_equal_whole(list(iter_adc(path, rate_hz=50.0, piece_bytes=20_000)), whole)
    for row, bad in ((150, "X=12 Y=3"), (15_000, ""), (19_990, "X=2000 Y=1 Z=1")):  # damage in later pieces
        damaged = tmp_path / f"bad_{row}.txt"
        damaged.write_text("\n".join(lines[:row] + [bad] + lines[row + 1 :]) + "\n")
        with pytest.raises(ConversionError) as one:
            read_adc(damaged, rate_hz=50.0)
        assert f"line {row + 1}" in str(one.value)
        with pytest.raises(ConversionError) as pieces:
            list(iter_adc(damaged, rate_hz=50.0, piece_bytes=20_000))
        assert str(pieces.value) == str(one.value)


def test_nilspod_counter_gap_and_error_across_pieces(shared_data, tmp_path):
    from imulog.converters.nilspod import iter_bin, read_bin

    data = (shared_data / "devices/nilspod/NilsPodX-6F13_20210109_162824.bin").read_bytes()
    size, hsz = 32, 52  # this session's sample and header sizes
    gap = tmp_path / "NilsPodX-gap.bin"  # samples 100..109 dropped, 200..204 too: two gaps, in two pieces
    gap.write_bytes(data[: hsz + 100 * size] + data[hsz + 110 * size : hsz + 200 * size] + data[hsz + 205 * size :])
    whole = read_bin(gap)
    assert any("skips 15 samples in 2 places" in w for w in whole.warnings)
    assert whole.imus[0].meta["missing_samples"] == 15
    _pieces_equal_whole(list(iter_bin(gap, samples_per_piece=150)), whole)
    swap = tmp_path / "NilsPodX-swap.bin"  # samples 300 and 301 swapped, 300 the first of a piece
    s = [data[hsz + k * size : hsz + (k + 1) * size] for k in range((len(data) - hsz) // size)]
    s[300], s[301] = s[301], s[300]
    swap.write_bytes(data[:hsz] + b"".join(s))
    with pytest.raises(ConversionError) as one:
        read_bin(swap)
    for per in (100, 150, 301):
        with pytest.raises(ConversionError) as pieces:
            list(iter_bin(swap, samples_per_piece=per))
        assert str(pieces.value) == str(one.value) and "sample 301:" in str(one.value)
