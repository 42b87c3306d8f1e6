"""C3D in pieces (issue 24, point 4): every shared C3D converts through ``imulog convert`` whole and in tiny pieces to
the same archive, sample by sample; the pieces' values are ezc3d's and the `c3d` package's reads; DEC and MIPS files
in pieces equal their Intel file; a trial longer than the 65535 frames a 16-bit count holds (written by
``benchmarks/long_c3d.py``) is read to its last frame, equal to what was written and to the `c3d` package."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from imulog.converters._binary import concat_chunks
from imulog.converters.c3d import iter_c3d, read_c3d
from imulog.converters.c3d_format import DEC, MIPS, from_intel
from test_convert_pieces import assert_same_recording
from test_convert_pieces_archive import SHARED_DATA, assert_same_trial, convert_twice

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from long_c3d import frames_at, write_long_c3d  # noqa: E402  (the documented layout, shared with the benchmark)

SHARED_C3D = sorted(p.relative_to(SHARED_DATA).as_posix() for p in SHARED_DATA.rglob("*.c3d"))
PIECE = "imulog.converters.c3d.PIECE_BYTES"


def test_the_shared_c3d_files_are_the_four_known():
    assert SHARED_C3D == [
        "c3d/ktk_sample_propulsion_upperlimb.c3d",
        "devices/c3d_samples/MACsample.c3d",
        "devices/c3d_samples/pc_int.c3d",
        "vicon_nexus/markers_analogs.c3d",
    ]


@pytest.mark.parametrize("rel", SHARED_C3D, ids=[Path(r).name for r in SHARED_C3D])
def test_pieces_write_the_whole_files_archive(rel, shared_data, tmp_path, monkeypatch):
    """A piece of about 2 KB of data (a few frames; the Nexus file's 38 analog channels at 20 samples a frame make
    one frame 3 KB: one frame a piece), through the streaming writer, against the whole file."""
    whole, pieces = convert_twice(shared_data / rel, tmp_path, (PIECE, 2048), monkeypatch)
    assert_same_trial(whole, pieces)


@pytest.mark.parametrize("rel", SHARED_C3D, ids=[Path(r).name for r in SHARED_C3D])
def test_one_frame_pieces_join_to_the_whole_recording(rel, shared_data):
    path = shared_data / rel
    pieces = list(iter_c3d(path, piece_bytes=1))
    whole = read_c3d(path)
    assert len(pieces) == len(whole.markers[0])  # one frame a piece
    assert_same_recording(concat_chunks(pieces), whole)
    assert all(p.warnings == [] for p in pieces[1:-1])  # the markers' warnings come with the last piece only


def _ezc3d(path: Path):
    import ezc3d

    return ezc3d.c3d(str(path))


def _c3d_package(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(points (N, M, 5), analogs (N x ratio, C)) as the `c3d` package reads them."""
    import c3d

    with warnings.catch_warnings(), open(path, "rb") as f:
        warnings.simplefilter("ignore")
        frames = list(c3d.Reader(f).read_frames())
    return np.array([p for _, p, _ in frames]), np.concatenate([a.T for _, _, a in frames])


@pytest.mark.parametrize("rel", SHARED_C3D, ids=[Path(r).name for r in SHARED_C3D])
def test_pieces_values_are_ezc3d_and_c3d_package_reads(rel, shared_data, tmp_path):
    """Positions (m), validity and analogs of the pieces joined, against ezc3d (which crashes on MACsample.c3d) and
    the `c3d` package (which refuses the kineticstoolkit file's SCALE; MIPS given to it as its Intel rewrite)."""
    from imulog.converters.c3d_format import parameters, to_intel

    path = shared_data / rel
    rec = concat_chunks(iter_c3d(path, piece_bytes=4096))
    m = rec.markers[0]
    unit = {"mm": 1e-3, "m": 1.0}[m.meta["units"]]
    checked = 0
    if "MACsample" not in rel:
        ez = _ezc3d(path)
        pts, res = ez["data"]["points"], ez["data"]["meta_points"]["residuals"][0]
        np.testing.assert_array_equal(m.valid, (np.isfinite(pts[:3]).all(axis=0) & (res >= 0)).T)
        np.testing.assert_allclose(m.pos[m.valid], np.transpose(pts[:3], (2, 1, 0))[m.valid] * unit, rtol=1e-12)
        if rec.analogs:
            np.testing.assert_allclose(rec.analogs[0].values, ez["data"]["analogs"][0].T, rtol=1e-9, atol=1e-12)
        checked += 1
    if "ktk_sample" not in rel:
        intel = path
        if "MACsample" in rel:  # MIPS: its Intel rewrite, the header's scale set to POINT:SCALE (else refused)
            data = bytearray(to_intel(path.read_bytes()))
            data[12:16] = np.float32(parameters(bytes(data))["POINT:SCALE"][0]).tobytes()
            intel = tmp_path / "mac_intel.c3d"
            intel.write_bytes(bytes(data))
        pk, an = _c3d_package(intel)
        np.testing.assert_array_equal(m.valid, pk[:, :, 3] >= 0)
        np.testing.assert_allclose(m.pos[m.valid], pk[:, :, :3][m.valid] * unit, rtol=1e-6)
        if rec.analogs:
            np.testing.assert_allclose(rec.analogs[0].values, an, rtol=1e-6, atol=1e-9)
        checked += 1
    assert checked >= 1


@pytest.mark.parametrize("proc", [DEC, MIPS], ids=["dec", "mips"])
@pytest.mark.parametrize("integer", [True, False], ids=["int16", "float32"])
def test_dec_and_mips_in_pieces_equal_their_intel_file(tmp_path, proc, integer):
    """The frame ranges are rewritten from the file's processor type: VAX-F and big-endian floats, big-endian
    integers; pieces of 40 frames against the Intel file in one piece."""
    intel = tmp_path / "intel.c3d"
    write_long_c3d(intel, 500, markers=3, ratio=4, integer=integer)
    variant = tmp_path / "variant.c3d"
    variant.write_bytes(from_intel(intel.read_bytes(), proc))
    frame_bytes = (3 * 4 + 4) * (2 if integer else 4)
    pieces = list(iter_c3d(variant, piece_bytes=40 * frame_bytes))
    assert len(pieces) == 13
    ref = read_c3d(intel)
    joined = concat_chunks(pieces)
    for a, b in ((joined.markers[0], ref.markers[0]), (joined.analogs[0], ref.analogs[0])):
        assert a.t_ns.tobytes() == b.t_ns.tobytes() and a.meta == {**b.meta, "source": "variant.c3d"}
    assert joined.markers[0].pos.tobytes() == ref.markers[0].pos.tobytes()
    assert joined.analogs[0].values.tobytes() == ref.analogs[0].values.tobytes()


@pytest.mark.parametrize("integer", [False, True], ids=["float32", "int16"])
def test_a_trial_longer_than_65535_frames(tmp_path, integer):
    """70 000 frames at 100 Hz: counted by TRIAL:ACTUAL_END_FIELD (the header and POINT:FRAMES hold 65535), read to
    the last frame; positions, gaps and the analog channel equal what was written and the `c3d` package's reading;
    pieces of 1 MiB join to the whole."""
    path = tmp_path / "long.c3d"
    n = 70_000
    write_long_c3d(path, n, integer=integer)
    rec = read_c3d(path)
    m, a = rec.markers[0], rec.analogs[0]
    pos, res, emg = frames_at(0, n, markers=4, ratio=10, rate_hz=100.0)
    assert len(m) == n and len(a) == 10 * n and not rec.warnings
    assert m.t_ns[-1] == (n - 1) * 10_000_000 and a.t_ns[-1] == (10 * n - 1) * 1_000_000
    np.testing.assert_array_equal(m.valid, res >= 0)
    np.testing.assert_allclose(m.pos[m.valid], pos[m.valid] * 1e-3, rtol=1e-6)
    np.testing.assert_allclose(a.values[:, 0], emg, atol=1e-6)
    assert ("resolution" in m.meta) == integer and ("resolution" in a.meta) == integer
    pk, an = _c3d_package(path)
    assert len(pk) == n
    np.testing.assert_array_equal(m.valid, pk[:, :, 3] >= 0)
    np.testing.assert_allclose(m.pos[m.valid], pk[:, :, :3][m.valid] * 1e-3, rtol=1e-6)
    np.testing.assert_allclose(a.values, an, rtol=1e-6, atol=1e-9)
    pieces = list(iter_c3d(path, piece_bytes=1 << 20))
    assert len(pieces) > 2
    assert_same_recording(concat_chunks(pieces), rec)


_PEAK = """
import sys
from imulog.converters.c3d import iter_c3d
n = 0
for piece in iter_c3d(sys.argv[1], piece_bytes=1 << 20):
    n += len(piece.markers[0])
hwm = [int(x.split()[1]) for x in open("/proc/self/status") if x.startswith("VmHWM:")]
print(n, hwm[0])
"""


def _peak_kib(path: Path) -> tuple[int, int]:
    """(frames read, the reading child's own peak RSS in KiB: VmHWM, which the parent's peak does not carry)."""
    import subprocess

    out = subprocess.run([sys.executable, "-c", _PEAK, str(path)], capture_output=True, text=True, check=True)
    n, kib = out.stdout.split()
    return int(n), int(kib)


def test_a_long_c3d_reads_in_bounded_memory(tmp_path):
    """Peak memory of reading a C3D in 1 MiB pieces does not grow with the file: 400 000 frames (42 MB) peak
    within 15 MB of 100 000 frames (10 MB); measured 56.5 -> 57.4 MB, where one piece (``piece_bytes=None``) peaks
    at 135 -> 423 MB."""
    short, long = tmp_path / "short.c3d", tmp_path / "long.c3d"
    write_long_c3d(short, 100_000)
    write_long_c3d(long, 400_000)
    n_short, peak_short = _peak_kib(short)
    n_long, peak_long = _peak_kib(long)
    assert (n_short, n_long) == (100_000, 400_000)
    grow_mb = (peak_long - peak_short) / 1024
    assert grow_mb < 15, (
        f"peak grew {grow_mb:.0f} MB from {short.stat().st_size >> 20} to {long.stat().st_size >> 20} MB"
    )
