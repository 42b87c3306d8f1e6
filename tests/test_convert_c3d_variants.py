"""C3D variants built from the c3d.org samples (../shared/data/devices/c3d_samples): DEC and MIPS processor types,
a header frame count that disagrees with POINT:FRAMES, all-invalid markers, and a reader that hangs or crashes."""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError, convert_file
from imulog.converters._guard import GuardError, guarded
from imulog.converters.c3d_format import DEC, MIPS, from_intel, ieee_to_vax, parameters, to_intel, vax_to_ieee

SAMPLES = "devices/c3d_samples"


@pytest.fixture(scope="module")
def pc_int(shared_data: Path) -> Path:
    return shared_data / SAMPLES / "pc_int.c3d"


def test_vax_floats_known_values():
    # VAX-F 1.0 is stored as 80 40 00 00; -2.5 as 20 C1 00 00 (sign in the first word)
    raw = np.array([[0x80, 0x40, 0, 0], [0x20, 0xC1, 0, 0]], dtype=np.uint8)
    np.testing.assert_array_equal(vax_to_ieee(raw), [1.0, -2.5])
    np.testing.assert_array_equal(ieee_to_vax(np.array([1.0, -2.5], np.float32)), raw)


@pytest.mark.parametrize("proc", [DEC, MIPS])
def test_dec_and_mips_variants_read_like_the_intel_file(pc_int: Path, tmp_path: Path, proc: int):
    data = pc_int.read_bytes()
    variant = from_intel(data, proc)
    assert variant[(data[0] - 1) * 512 + 3] == proc and variant != data
    assert to_intel(variant) == data  # the rewrite is exact both ways
    path = tmp_path / f"walk_{proc}.c3d"
    path.write_bytes(variant)
    ref = convert_file(pc_int)
    rec = convert_file(path)
    assert not any("imulog's own" in w for w in rec.warnings)  # DEC: ezc3d itself; MIPS: ezc3d on the rewrite
    np.testing.assert_array_equal(rec.markers[0].pos, ref.markers[0].pos)
    np.testing.assert_array_equal(rec.markers[0].t_ns, ref.markers[0].t_ns)
    np.testing.assert_array_equal(rec.analogs[0].values, ref.analogs[0].values)


def test_mips_sample_reads_with_own_reader(shared_data: Path):
    """MACsample.c3d (MIPS): ezc3d refuses MIPS and crashes on its Intel rewrite; imulog's reader reads it."""
    path = shared_data / SAMPLES / "MACsample.c3d"
    data = path.read_bytes()
    rec = convert_file(path)
    (m,) = rec.markers
    p = parameters(data)
    assert len(m) == p["POINT:FRAMES"][0] == 180 and len(m.labels) == 33
    assert rec.analogs[0].values.shape == (180 * 17, 16)
    assert any("POINT:SCALE" in w for w in rec.warnings)  # header 0.0551 vs parameter 0.0215
    assert any("never valid" in w for w in rec.warnings)
    # the raw integers of frame 1, marker 1 times POINT:SCALE (mm -> m), read by hand from the MIPS bytes
    start = (struct.unpack(">H", data[16:18])[0] - 1) * 512
    x, y, z, r = struct.unpack(">4h", data[start + 4 * 2 * 1 : start + 4 * 2 * 2])  # marker 2 (RHIP), frame 1
    if r >= 0:
        np.testing.assert_allclose(m.pos[0, 1], np.array([x, y, z]) * p["POINT:SCALE"][0] / 1000, rtol=1e-12)
    else:
        assert not m.valid[0, 1]


@pytest.mark.parametrize("extra", [500, -20])
def test_header_frame_count_disagrees_with_point_frames(pc_int: Path, tmp_path: Path, extra: int):
    """The header claims more (or fewer) frames than POINT:FRAMES: imulog reads what ezc3d reads."""
    import ezc3d

    data = bytearray(pc_int.read_bytes())
    first, last = struct.unpack_from("<HH", data, 6)
    struct.pack_into("<H", data, 8, last + extra)
    path = tmp_path / "header_frames.c3d"
    path.write_bytes(bytes(data))
    rec = convert_file(path)
    assert len(rec.markers[0]) == last - first + 1 == ezc3d.c3d(str(path))["data"]["points"].shape[2]
    np.testing.assert_array_equal(rec.markers[0].pos, convert_file(pc_int).markers[0].pos)
    assert any("disagrees with POINT:FRAMES" in w for w in rec.warnings)


def test_truncated_file_still_refused(pc_int: Path, tmp_path: Path):
    path = tmp_path / "cut.c3d"
    path.write_bytes(pc_int.read_bytes()[:-4000])
    with pytest.raises(ConversionError, match=r"cut\.c3d: truncated C3D"):
        convert_file(path)


def _edit_words(src: Path, out: Path, edit) -> int:
    """``src`` (an integer Intel C3D) written to ``out`` after ``edit(words, n_points)`` changed its data words,
    (frames, 4 x points + analogs) int16; returns the number of points."""
    data = bytearray(src.read_bytes())
    n_points, n_analog = struct.unpack_from("<2H", data, 2)
    start = (struct.unpack_from("<H", data, 16)[0] - 1) * 512
    frames = parameters(bytes(data))["POINT:FRAMES"][0]
    words = np.frombuffer(bytes(data), "<i2", count=frames * (4 * n_points + n_analog), offset=start).copy()
    words = words.reshape(frames, -1)
    edit(words, n_points)
    data[start : start + words.nbytes] = words.tobytes()
    out.write_bytes(bytes(data))
    return n_points


def test_all_invalid_marker_set_is_warned(pc_int: Path, tmp_path: Path):
    def every_residual_invalid(words: np.ndarray, n_points: int) -> None:
        words[:, 3 : 4 * n_points : 4] = -1

    path = tmp_path / "invalid.c3d"
    n_points = _edit_words(pc_int, path, every_residual_invalid)
    rec = convert_file(path)
    assert not rec.markers[0].valid.any()
    assert any(f"all {n_points} markers are invalid in every frame" in w for w in rec.warnings)


def _sleep(s: float) -> int:
    time.sleep(s)
    return 1


def _hog() -> int:
    return len(bytearray(3 << 30))


def _crash() -> None:
    os.abort()


def test_guard_time_memory_crash():
    assert guarded(_sleep, 0.0, timeout_s=10) == 1
    t0 = time.monotonic()
    with pytest.raises(GuardError, match=r"did not finish within 0.5 s") as e:
        guarded(_sleep, 30.0, timeout_s=0.5)
    assert e.value.kind == "timeout" and time.monotonic() - t0 < 5
    with pytest.raises(GuardError, match="GiB of memory") as e:
        guarded(_hog, memory_bytes=256 << 20)
    assert e.value.kind == "memory"
    with pytest.raises(GuardError, match=r"crashed \(SIGABRT\)"):
        guarded(_crash)


def test_hanging_reader_falls_back_with_one_line(pc_int: Path, monkeypatch):
    import imulog.converters.c3d as c3d

    ref = convert_file(pc_int).markers[0].pos
    monkeypatch.setattr(c3d, "_ezc3d_read", lambda path: _sleep(30.0))
    from imulog.converters import ConvertOptions

    t0 = time.monotonic()
    rec = c3d.read_c3d(pc_int, options=ConvertOptions(extra={"reader_timeout_s": 0.5}))
    assert time.monotonic() - t0 < 10
    (w,) = [w for w in rec.warnings if "imulog's own" in w]
    assert "did not finish within 0.5 s" in w and "\n" not in w
    np.testing.assert_array_equal(rec.markers[0].pos, ref)


def _with_words(pc_int: Path, tmp_path: Path, edits: dict[int, int], zero: tuple[int, ...] = ()) -> tuple[Path, int]:
    """pc_int.c3d with frame 0's fourth point word set per ``edits`` (point -> int16 word) and the coordinates of
    the points in ``zero`` set to 0; returns the path and the number of points."""

    def edit(words: np.ndarray, n_points: int) -> None:
        for j, w in edits.items():
            words[0, 4 * j + 3] = w
        for j in zero:
            words[0, 4 * j : 4 * j + 3] = 0

    path = tmp_path / "words.c3d"
    return path, _edit_words(pc_int, path, edit)


def _c3d_package_residuals(path: Path) -> np.ndarray:
    """Frame 0's residuals as the `c3d` package reads them (-1 = invalid)."""
    import warnings

    import c3d

    with warnings.catch_warnings(), open(path, "rb") as f:
        warnings.simplefilter("ignore")
        (_, points, _) = next(iter(c3d.Reader(f).read_frames()))
    return points[:, 3]


@pytest.mark.parametrize("own_reader", [False, True], ids=["ezc3d", "imulog-reader"])
def test_residual_and_camera_mask_semantics_make_gaps(pc_int: Path, tmp_path: Path, monkeypatch, own_reader: bool):
    """A negative fourth word is invalid whatever the coordinates and camera bits say (-1, -2, a camera mask with
    the sign bit set, 0x8000); so is the guide's other spelling, X = Y = Z = 0 with a zero word (no residual, no
    camera). A measured point (residual > 0) at the origin stays valid. ezc3d and the `c3d` package agree on the
    negative words; on the zero word both report a valid point at the origin, which imulog stores as a gap."""
    import ezc3d
    import imulog.converters.c3d as c3d_mod

    ref = convert_file(pc_int).markers[0]
    valid0 = np.flatnonzero(ref.valid[0])
    a, b, c, d, e, f = (int(j) for j in valid0[:6])
    negative = {a: -1, b: -2, c: -0x7EFB, d: -32768}  # -0x7EFB = 0x8105: cameras 1 and 8 (sign), residual 5
    path, n_points = _with_words(pc_int, tmp_path, {**negative, e: 0, f: 0x0105}, zero=(e, f))
    if own_reader:
        monkeypatch.setattr(c3d_mod, "_ezc3d_read", lambda p: _crash())
    rec = convert_file(path)
    m = rec.markers[0]
    assert any("imulog's own" in w for w in rec.warnings) == own_reader
    for j in negative:
        assert not m.valid[0, j], j
    assert not m.valid[0, e]  # (0, 0, 0), word 0: not measured -> the invalid convention
    assert m.valid[0, f] and np.all(m.pos[0, f] == 0)  # measured at the origin (residual 5 x scale)
    (w,) = [w for w in rec.warnings if "exactly (0, 0, 0)" in w]
    assert "1 sample(s) of 1 marker(s)" in w and "'vicon'" in w
    # every other sample is as in the unedited file
    keep = np.ones_like(m.valid)
    keep[0, [a, b, c, d, e, f]] = False
    np.testing.assert_array_equal(m.valid[keep], ref.valid[keep])
    np.testing.assert_array_equal(m.pos[keep & m.valid], ref.pos[keep & m.valid])
    # the two reference readers on the same bytes
    ez = ezc3d.c3d(str(path))["data"]["meta_points"]["residuals"][0][:, 0]
    pk = _c3d_package_residuals(path)
    for j in negative:
        assert ez[j] < 0 and pk[j] < 0, j
    assert ez[e] == 0 and pk[e] == 0 and ez[f] > 0 and pk[f] > 0
    # the two readers split the word differently: ezc3d's residual is its high byte, the c3d package's the low byte
    scale = parameters(path.read_bytes())["POINT:SCALE"][0]
    assert ez[f] == pytest.approx(0x01 * scale) and pk[f] == pytest.approx(0x05 * scale)


def test_shared_c3d_files_validity_equals_two_readers(shared_data: Path):
    """On the real files a sample is valid exactly where ezc3d gives finite coordinates and a residual >= 0, and
    (where the `c3d` package reads the file) where it gives a residual >= 0."""
    import warnings

    import c3d
    import ezc3d

    for rel in (
        "devices/c3d_samples/pc_int.c3d",
        "vicon_nexus/markers_analogs.c3d",
        "c3d/ktk_sample_propulsion_upperlimb.c3d",
    ):
        path = shared_data / rel
        ez = ezc3d.c3d(str(path))
        res = ez["data"]["meta_points"]["residuals"][0]
        ok = np.isfinite(ez["data"]["points"][:3]).all(axis=0) & (res >= 0)
        m = convert_file(path).markers[0]
        np.testing.assert_array_equal(m.valid, ok.T, err_msg=rel)
        try:
            with warnings.catch_warnings(), open(path, "rb") as f:
                warnings.simplefilter("ignore")
                pk = np.array([p[:, 3] for _, p, _ in c3d.Reader(f).read_frames()])
        except AssertionError:  # the c3d package refuses the ktk file's SCALE parameter
            continue
        np.testing.assert_array_equal(m.valid, pk >= 0, err_msg=rel)


@pytest.mark.parametrize("own_reader", [False, True], ids=["ezc3d", "imulog-reader"])
def test_float_c3d_residual_semantics(tmp_path: Path, monkeypatch, own_reader: bool):
    """The same rules in a floating-point C3D (POINT:SCALE < 0, the fourth word a float), written by ezc3d itself:
    residual -1 is a gap, (0, 0, 0) with residual 0 a gap, (0, 0, 0) with residual 2 a valid measured point."""
    import ezc3d
    import imulog.converters.c3d as c3d_mod

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("A", "B", "C", "D")
    pts = np.ones((4, 4, 5))
    pts[:3] = np.arange(60).reshape(3, 4, 5) + 100.0
    pts[:3, 1:3, 0] = 0.0  # B and C at the origin in frame 0
    res = np.full((1, 4, 5), 2.0)
    res[0, 0, 0] = -1.0  # A invalid
    res[0, 1, 0] = 0.0  # B not measured
    c["data"]["points"] = pts
    c["data"]["meta_points"]["residuals"] = res
    path = tmp_path / "float.c3d"
    c.write(str(path))
    data = path.read_bytes()
    assert struct.unpack_from("<f", data, 12)[0] < 0  # a float file
    np.testing.assert_array_equal(ezc3d.c3d(str(path))["data"]["meta_points"]["residuals"][0][:, 0], [-1, 0, 2, 2])
    if own_reader:
        monkeypatch.setattr(c3d_mod, "_ezc3d_read", lambda p: _crash())
    rec = convert_file(path)
    m = rec.markers[0]
    np.testing.assert_array_equal(m.valid[0], [False, False, True, True])
    assert m.valid[1:].all()
    np.testing.assert_allclose(m.pos[1:, 3], pts[:3, 3, 1:].T * 1e-3)  # mm -> m
    assert sum("exactly (0, 0, 0)" in w for w in rec.warnings) == 1
