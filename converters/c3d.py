"""C3D files (via ezc3d): points as markers, analog channels, events; units m or mm; non-integer rates.

Every processor type is read: Intel and DEC (VAX floats) files go to ezc3d as they are, MIPS (SGI, big-endian)
files are rewritten as Intel first (:mod:`imulog.converters.c3d_format`; ezc3d refuses MIPS). ezc3d runs in a child
process under a time and memory limit (``extra["reader_timeout_s"]``, default 60 s; ``reader_memory_bytes``,
1 GiB, :mod:`imulog.converters._guard`) on the header and parameters; when it fails, crashes or hangs, imulog's own
parser reads them, with a warning naming what ezc3d did. The points and analogs are always imulog's reading
(:mod:`imulog.converters.c3d_data`, equal to ezc3d's and the `c3d` package's on the shared files). The frame count is
``POINT:FRAMES`` (warned when the header's count disagrees; the header's 16-bit count wraps on long trials; beyond
65535 frames ``TRIAL:ACTUAL_START_FIELD``/``ACTUAL_END_FIELD``, else ``POINT:LONG_FRAMES``), the point scale ``POINT:SCALE`` (warned when the header's copy disagrees). A marker set without one valid sample, or
markers that are never valid, are warned about per marker set.

Valid samples (the C3D guide, "3D data"): a point whose fourth word (camera mask and residual) is negative is
invalid, whatever its coordinates say, and so is a non-finite one. A marker at exactly (0, 0, 0) whose fourth word
is 0 (no residual, no camera: not measured) is the guide's other spelling of an invalid point (coordinates zeroed,
the -1 word not written): a gap too, counted in one warning per marker set. A point at the origin with a residual
or a camera stays valid. Only the word's sign and whether it is 0 are used, because readers split it differently:
ezc3d takes the residual from its high byte and the cameras from the low byte, the `c3d` package and imulog's own
reader the other way round (the guide puts the cameras in the high byte, below the sign bit).

Time on the capture clock: point frame ``k`` (0-based, counting from the header's first frame) is at
``round((first_frame + k) / point_rate * 1e9)`` ns, so a Vicon C3D and its Nexus CSV export share one clock.
Analog sample ``j`` is at ``(first_frame + j / ratio) / point_rate``. Event times (``EVENT:TIMES``, minutes and
seconds) are seconds on the same clock. Points listed under ``POINT:ANGLES/FORCES/MOMENTS/POWERS/SCALARS`` are
model outputs, kept in ``/vicon/model_outputs`` with their units rather than as markers.

Memory: in pieces (``iter_chunks``). ezc3d reads only the header and parameter section (a copy of the file's bytes
before the data and its first frame, in the guarded child); the data section, frames of one fixed size, is read a range of frames at a
time by imulog's own reader (:mod:`imulog.converters.c3d_data`, about :data:`PIECE_BYTES` of data a piece), so a
piece holds one range whatever the file's length. The whole-file ``convert`` is the one-piece case. What the whole
file decides (each stream's span and ``meta``) comes from the header and parameters and is declared by the first
piece (:data:`imulog.model.PIECES_RECORD`); the warnings about markers never valid or at the origin come with the
last piece.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from struct import error as struct_error
from typing import Any

from imulog.converters import c3d_data
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.c3d_streams import (
    LENGTH_TO_M,
    MODEL_OUTPUT_GROUPS,
    C3dPlan,
    Tally,
    device_records,
    first_piece_metadata,
    imu_spans,
    piece,
    plan,
)
from imulog.converters.errors import ConversionError

from imulog.model import Recording

__all__ = ["LENGTH_TO_M", "MODEL_OUTPUT_GROUPS", "PIECE_BYTES", "C3dConverter", "iter_c3d", "load", "read_c3d"]

#: bytes of the data section per piece when a large file is converted piece by piece (whole frames, at least one):
#: decoded to float64 positions, times and analogs, 4 MiB of float32 data is about 11 MB of arrays, of int16 about 22 MB
#: (16 MiB pieces peaked at 460-520 MB for 1-4 h, as the command holds the first and the previous piece: 271-280 MB)
PIECE_BYTES = 4 * 1024 * 1024


def _frames_needed(path: Path, intel: bytes, params: dict, size: int) -> tuple[int, list[str]]:
    """Frames to read (:func:`imulog.converters.c3d_data.frame_count`) and a warning when ``POINT:FRAMES`` and the
    header's count disagree, or the header's scale and ``POINT:SCALE``; raises ConversionError when the file
    (``size`` bytes) is shorter than those frames need (ezc3d would silently return fewer)."""
    import struct

    import numpy as np

    n_points, n_analog, first, last = struct.unpack_from("<4H", intel, 2)
    (scale,) = struct.unpack_from("<f", intel, 12)
    (data_block,) = struct.unpack_from("<H", intel, 16)
    hdr = last - first + 1
    warnings = []
    _, frames, counted = c3d_data.frame_count(params, first, last)
    if counted == "POINT:FRAMES" and frames != hdr:
        warnings.append(
            f"{path.name}: the header's frame count {hdr} disagrees with POINT:FRAMES {frames}; read POINT:FRAMES"
        )
    pscale = params.get("POINT:SCALE")
    if isinstance(pscale, list) and pscale:
        if not np.isclose(float(pscale[0]), scale, rtol=1e-6) and n_points:
            warnings.append(
                f"{path.name}: the header's scale {scale:g} disagrees with POINT:SCALE {float(pscale[0]):g}; "
                "used POINT:SCALE (the C3D standard's rule)"
            )
        scale = float(pscale[0])
    if frames <= 0 or data_block < 2:
        return frames, warnings
    word = 4 if scale < 0 else 2
    need = (data_block - 1) * 512 + frames * (n_points * 4 + n_analog) * word
    if size < need:
        raise ConversionError(path, f"truncated C3D: {size} bytes, its {frames} frames need {need}")
    return frames, warnings


def _ezc3d_read(path: str) -> dict[str, Any]:
    """ezc3d's reading of the header and parameters in ``path`` (a copy of a file's bytes before its data) as
    plain dicts (runs in a guarded child process)."""
    import ezc3d

    c = ezc3d.c3d(path, extract_forceplat_data=False)
    params = {
        g: {n: {"value": v["value"]} for n, v in grp.items() if isinstance(v, dict) and "value" in v}
        for g, grp in c["parameters"].items()
        if isinstance(grp, dict)
    }
    return {"header": {"points": dict(c["header"]["points"])}, "parameters": params}


def load(path: Path, options: ConvertOptions | None = None) -> tuple[dict[str, Any], c3d_data.Layout, int, list[str]]:
    """The file's header and parameters (ezc3d under a time and memory guard; imulog's own parser when ezc3d
    cannot), its data layout, processor type and warnings, from the bytes before its data. DEC files go to ezc3d as
    they are, MIPS files rewritten as Intel (ezc3d refuses them)."""
    import tempfile

    from imulog.converters._guard import DEFAULT_MEMORY_BYTES, DEFAULT_TIMEOUT_S, GuardError, guarded
    from imulog.converters.c3d_format import (
        DEC,
        INTEL,
        PROCESSORS,
        C3dLayoutError,
        parameters,
        processor_type,
        read_prefix,
        to_intel,
    )

    extra = options.extra if options else {}
    size = path.stat().st_size
    try:
        with open(path, "rb") as f:
            prefix = read_prefix(f)
        proc = processor_type(prefix)
        intel = to_intel(prefix)
        params = parameters(intel)
    except (C3dLayoutError, struct_error, ValueError, IndexError) as e:
        raise ConversionError(path, f"corrupt C3D: {e}") from None
    _, warnings = _frames_needed(path, intel, params, size)
    try:
        lay = c3d_data.layout(intel, params, size)
    except (C3dLayoutError, struct_error, ValueError, IndexError) as e:
        raise ConversionError(path, f"corrupt C3D ({PROCESSORS[proc]}): {e}") from None
    try:
        import ezc3d  # noqa: F401
    except ImportError:  # pragma: no cover - optional extra
        raise ConversionError(path, "reading C3D needs ezc3d: pip install 'imulog[c3d]'") from None
    timeout = float(extra.get("reader_timeout_s", DEFAULT_TIMEOUT_S))
    memory = int(extra.get("reader_memory_bytes", DEFAULT_MEMORY_BYTES))
    fd, tmp = tempfile.mkstemp(suffix=".c3d")
    try:
        with open(fd, "wb") as out, open(path, "rb") as f:
            # the bytes before the data and the first frame (ezc3d refuses a file without a frame it declares)
            head = prefix[: lay.data_start] if len(prefix) > lay.data_start else prefix
            f.seek(len(head))
            head += f.read(lay.data_start - len(head) + (lay.frame_bytes if lay.frames else 0))
            out.write(head if proc in (INTEL, DEC) else to_intel(head))
        try:
            return guarded(_ezc3d_read, tmp, timeout_s=timeout, memory_bytes=memory), lay, proc, warnings
        except GuardError as e:
            if e.kind == "error" and e.exc_type == "RuntimeError" and proc == INTEL and "support" not in str(e):
                why = f"ezc3d: {e}"
            else:
                why = f"ezc3d {e}"
            try:
                content = c3d_data.ezc3d_parameters(intel)
            except (C3dLayoutError, ValueError, IndexError, struct_error) as e2:
                raise ConversionError(path, f"corrupt C3D ({PROCESSORS[proc]}): {why}; imulog's reader: {e2}") from None
            warnings.append(f"{path.name}: {why}; read with imulog's own C3D reader (points, analogs, events)")
            return content, lay, proc, warnings
    finally:
        Path(tmp).unlink(missing_ok=True)


def _check_header(path: Path) -> None:
    if path.stat().st_size < 512:
        raise ConversionError(path, "too short to be a C3D file")
    with open(path, "rb") as f:
        head = f.read(2)
    if len(head) < 2 or head[1] != 0x50:
        raise ConversionError(path, "not a C3D file (byte 2 of the header is not 0x50)")


def iter_c3d(
    path: Path, name: str = "vicon", options: ConvertOptions | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """The file's recording in pieces of whole frames, about ``piece_bytes`` of data each (None: one piece). The
    first of several pieces declares every stream's span and final meta; events come with the first piece, the
    markers' whole-file warnings with the last."""
    from imulog.converters.c3d_format import PROCESSORS, C3dLayoutError

    path = Path(path)
    _check_header(path)
    c, lay, proc, warnings = load(path, options)
    p: C3dPlan = plan(path, name, c["header"], c["parameters"], lay)
    step = lay.frames if piece_bytes is None else max(1, piece_bytes // max(lay.frame_bytes, 1))
    bounds = list(range(0, lay.frames, max(step, 1))) or [0]
    tally = Tally()

    def decoded(f):
        for lo in bounds:
            hi = min(lo + step, lay.frames)
            try:
                yield lo, c3d_data.decode(c3d_data.read_frames(f, lay, proc, lo, hi), lay)
            except (C3dLayoutError, ValueError) as e:
                raise ConversionError(path, f"corrupt C3D ({PROCESSORS[proc]}): {e}") from None

    with open(path, "rb") as f:
        if p.imus and len(bounds) > 1:  # IMUs among the analogs: their spans for the first piece's declaration
            p.imu_spans = imu_spans(p, decoded(f))
        for k, (lo, data) in enumerate(decoded(f)):
            rec = piece(p, data, lo, tally)
            if k == 0:
                rec.warnings.extend(warnings + p.warnings)
                first_piece_metadata(p, rec, pieces=len(bounds) > 1)
            else:
                rec.metadata.update(device_records(p))
            if k == len(bounds) - 1:
                rec.warnings.extend(tally.warnings(p))
            yield rec


def read_c3d(path: Path, name: str = "vicon", options: ConvertOptions | None = None) -> Recording:
    """The whole file as one Recording: :func:`iter_c3d` in one piece."""
    (rec,) = iter_c3d(path, name, options, piece_bytes=None)
    return rec


class C3dConverter(Converter):
    name = "c3d"
    description = "C3D motion capture (points, analogs, events; Intel, DEC, MIPS; m or mm) via ezc3d, guarded"
    extensions = (".c3d",)
    example = "imulog convert markers_analogs.c3d -o trial.mcap"
    fixed_pieces = True  # whole frames of one size: freed piece temporaries are reused (imulog.heap.reuse_heap)

    def sniff(self, path: Path, head: bytes) -> float:
        if len(head) >= 512 and head[1] == 0x50:
            return 0.95 if path.suffix.lower() == ".c3d" else 0.4
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        name = options.extra.get("vicon_name", "vicon") if options else "vicon"
        return read_c3d(Path(path), name=name, options=options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        name = options.extra.get("vicon_name", "vicon") if options else "vicon"
        return iter_c3d(Path(path), name=name, options=options, piece_bytes=PIECE_BYTES)


CONVERTER = C3dConverter()
