"""C3D files (via ezc3d): points as markers, analog channels, events; units m or mm; non-integer rates.

Every processor type is read: Intel and DEC (VAX floats) files go to ezc3d as they are, MIPS (SGI, big-endian)
files are rewritten as Intel first (:mod:`imulog.converters.c3d_format`; ezc3d refuses MIPS). ezc3d runs in a child
process under a time and memory limit (``extra["reader_timeout_s"]``, default 60 s; ``reader_memory_bytes``,
1 GiB, :mod:`imulog.converters._guard`); when it fails, crashes or hangs, imulog's own reader
(:mod:`imulog.converters.c3d_data`) reads the points and analogs, with a warning naming what ezc3d did. The frame count is
``POINT:FRAMES`` (warned when the header's count disagrees; the header's 16-bit count wraps on long trials), the
point scale ``POINT:SCALE`` (warned when the header's copy disagrees). A marker set without one valid sample, or
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
"""

from __future__ import annotations

from pathlib import Path
from struct import error as struct_error
from typing import Any

import numpy as np
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import AnalogStream, Intervals, MarkerStream, Recording, SignalStream
from imulog.numeric import finite_rows

LENGTH_TO_M = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}
MODEL_OUTPUT_GROUPS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS")


def _param(params: dict, group: str, name: str, default: Any = None) -> Any:
    try:
        return params[group][name]["value"]
    except KeyError:
        return default


def _positions_m(xyz: np.ndarray, params: dict, unit: str) -> tuple[np.ndarray, dict[str, Any]]:
    """Marker positions in m and, for an integer C3D (``POINT:SCALE`` > 0), the ``resolution`` hint that lets the
    archive store the file's int16 words: positions are then ``counts * (POINT:SCALE * unit to m)``, so they read
    back bit for bit (:mod:`imulog.archive.numbers`); a float C3D (scale < 0) keeps ``xyz * unit to m``."""
    to_m = LENGTH_TO_M[unit]
    scale = _param(params, "POINT", "SCALE")
    step = float(scale[0]) if scale is not None and len(scale) else 0.0
    fin = np.isfinite(xyz)
    if step > 0 and np.isfinite(step) and fin.any():
        with np.errstate(invalid="ignore"):
            counts = np.rint(xyz / step)
        whole = np.abs(counts[fin]).max() <= 32768 and np.allclose(counts[fin] * step, xyz[fin], rtol=1e-6, atol=0)
        if whole:  # the words of an integer file (ezc3d gives word x scale, possibly rounded in float32)
            m_step = step * to_m
            return counts * m_step, {"resolution": {"pos": {"scale": m_step}}}
    return xyz * to_m, {}


def _analog_values(values: np.ndarray, params: dict) -> tuple[np.ndarray, dict[str, Any]]:
    """(N, C) analog values and, when they are the file's words, the ``resolution`` hint that stores those words:
    C3D analogs are ``(word - ANALOG:OFFSET) * ANALOG:GEN_SCALE * ANALOG:SCALE`` per channel, so with the words as
    counts the values are ``(counts + shift) * scale`` (shift = -offset, scale = GEN_SCALE * SCALE), given back
    exactly by the archive (:mod:`imulog.archive.numbers`). Values that are not whole words (a float C3D's
    analogs) keep float64."""
    n_ch = values.shape[1]

    def per_channel(key: str, default: float) -> np.ndarray:
        out = np.full(n_ch, default)
        given = _param(params, "ANALOG", key)
        given = np.asarray([] if given is None else given, dtype=np.float64).reshape(-1)[:n_ch]
        out[: len(given)] = given
        return out

    off = per_channel("OFFSET", 0.0)
    step = per_channel("GEN_SCALE", 1.0)[0] * per_channel("SCALE", 1.0)
    if not (np.isfinite(step).all() and (step != 0).all() and np.isfinite(off).all() and np.isfinite(values).all()):
        return values, {}
    with np.errstate(invalid="ignore", over="ignore"):
        words = values / step + off
    counts = np.rint(words)
    # ezc3d computes in float32 or float64: the words within a thousandth of a count, and within 16 bits
    if not (np.abs(words - counts).max(initial=0.0) <= 1e-3 and np.abs(counts).max(initial=0.0) <= 65536):
        return values, {}
    return (counts - off) * step, {"resolution": {"values": {"shift": (-off).tolist(), "scale": step.tolist()}}}


def _labels(params: dict, group: str, n: int) -> list[str]:
    labels = list(_param(params, group, "LABELS", []) or [])
    if len(labels) < n:
        labels += list(_param(params, group, "LABELS2", []) or [])
    labels = [str(x).strip() for x in labels[:n]]
    labels += [f"{group.lower()}_{i + 1}" for i in range(len(labels), n)]
    seen: dict[str, int] = {}
    out = []
    for lab in labels:  # C3D allows repeated or blank labels: make them unique, keep the original order
        lab = lab or "unnamed"
        if lab in seen:
            seen[lab] += 1
            lab = f"{lab}#{seen[lab]}"
        else:
            seen[lab] = 1
        out.append(lab)
    return out


def _frames_needed(path: Path, intel: bytes, params: dict) -> tuple[int, list[str]]:
    """Frames to read (``POINT:FRAMES``, else the header's count) and a warning when the two disagree; raises
    ConversionError when the file is shorter than those frames need (ezc3d would silently return fewer)."""
    import struct

    n_points, n_analog, first, last = struct.unpack_from("<4H", intel, 2)
    (scale,) = struct.unpack_from("<f", intel, 12)
    (data_block,) = struct.unpack_from("<H", intel, 16)
    hdr = last - first + 1
    warnings = []
    pf = params.get("POINT:FRAMES")
    frames = hdr
    if isinstance(pf, list) and pf:
        frames = int(pf[0]) + (65536 if int(pf[0]) < 0 else 0)
        if frames != hdr:
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
    if len(intel) < need:
        raise ConversionError(path, f"truncated C3D: {len(intel)} bytes, its {frames} frames need {need}")
    return frames, warnings


def _ezc3d_read(path: str) -> dict[str, Any]:
    """ezc3d's reading of ``path`` as plain dicts and arrays (runs in a guarded child process)."""
    import ezc3d

    c = ezc3d.c3d(path, extract_forceplat_data=False)
    params = {
        g: {n: {"value": v["value"]} for n, v in grp.items() if isinstance(v, dict) and "value" in v}
        for g, grp in c["parameters"].items()
        if isinstance(grp, dict)
    }
    data = c["data"]
    meta = {}
    if "meta_points" in data:
        meta = {k: np.asarray(data["meta_points"][k]) for k in ("residuals", "camera_masks") if k in data["meta_points"]}
    return {
        "header": {"points": dict(c["header"]["points"])},
        "parameters": params,
        "data": {"points": np.asarray(data["points"]), "analogs": np.asarray(data["analogs"]), "meta_points": meta},
    }


def load(path: Path, options: ConvertOptions | None = None) -> tuple[dict[str, Any], list[str]]:
    """The file's content (ezc3d under a time and memory guard; imulog's own reader when ezc3d cannot) and
    warnings. DEC files go to ezc3d as they are, MIPS files rewritten as Intel (ezc3d refuses them)."""
    import tempfile

    from imulog.converters import c3d_data
    from imulog.converters._guard import DEFAULT_MEMORY_BYTES, DEFAULT_TIMEOUT_S, GuardError, guarded
    from imulog.converters.c3d_format import (
        DEC,
        INTEL,
        PROCESSORS,
        C3dLayoutError,
        parameters,
        processor_type,
        to_intel,
    )

    extra = options.extra if options else {}
    data = path.read_bytes()
    try:
        proc = processor_type(data)
        intel = to_intel(data)
        params = parameters(intel)
    except (C3dLayoutError, struct_error, ValueError, IndexError) as e:
        raise ConversionError(path, f"corrupt C3D: {e}") from None
    _, warnings = _frames_needed(path, intel, params)
    try:
        import ezc3d  # noqa: F401
    except ImportError:  # pragma: no cover - optional extra
        raise ConversionError(path, "reading C3D needs ezc3d: pip install 'imulog[c3d]'") from None
    timeout = float(extra.get("reader_timeout_s", DEFAULT_TIMEOUT_S))
    memory = int(extra.get("reader_memory_bytes", DEFAULT_MEMORY_BYTES))
    tmp = None
    try:
        source = str(path)
        if proc not in (INTEL, DEC):
            fd, tmp = tempfile.mkstemp(suffix=".c3d")
            with open(fd, "wb") as f:
                f.write(intel)
            source = tmp
        try:
            return guarded(_ezc3d_read, source, timeout_s=timeout, memory_bytes=memory), warnings
        except GuardError as e:
            if e.kind == "error" and e.exc_type == "RuntimeError" and proc == INTEL and "support" not in str(e):
                why = f"ezc3d: {e}"
            else:
                why = f"ezc3d {e}"
            try:
                content = c3d_data.read(intel)
            except (C3dLayoutError, ValueError, IndexError, struct_error) as e2:
                raise ConversionError(path, f"corrupt C3D ({PROCESSORS[proc]}): {why}; imulog's reader: {e2}") from None
            warnings.append(f"{path.name}: {why}; read with imulog's own C3D reader (points, analogs, events)")
            return content, warnings
    finally:
        if tmp:
            Path(tmp).unlink(missing_ok=True)


def invalid_marker_warnings(path: Path, name: str, labels: list[str], valid: np.ndarray) -> list[str]:
    """One warning for a marker set without a single valid sample, else one listing its never-valid markers."""
    never = [lab for j, lab in enumerate(labels) if not valid[:, j].any()]
    if not never:
        return []
    if len(never) == len(labels):
        return [f"{path.name}: marker set {name!r}: all {len(labels)} markers are invalid in every frame"]
    shown = ", ".join(never[:5]) + (" ..." if len(never) > 5 else "")
    return [f"{path.name}: marker set {name!r}: {len(never)} of {len(labels)} markers never valid ({shown})"]


def read_c3d(path: Path, name: str = "vicon", options: ConvertOptions | None = None) -> Recording:
    path = Path(path)
    if path.stat().st_size < 512:
        raise ConversionError(path, "too short to be a C3D file")
    with open(path, "rb") as f:
        head = f.read(2)
    if len(head) < 2 or head[1] != 0x50:
        raise ConversionError(path, "not a C3D file (byte 2 of the header is not 0x50)")
    c, warnings = load(path, options)
    params = c["parameters"]
    header = c["header"]
    rate = float(header["points"]["frame_rate"])
    rate_param = _param(params, "POINT", "RATE")
    if rate_param is not None and len(rate_param):
        rate = float(rate_param[0])
    if not (rate > 0 and np.isfinite(rate)):
        raise ConversionError(path, f"point rate {rate!r} is not positive")
    first = int(header["points"]["first_frame"])
    points = c["data"]["points"]  # (4, M, N)
    n_frames = points.shape[2]
    rec = Recording(sources=[str(path)], warnings=list(warnings))
    t_ns = np.round((first + np.arange(n_frames)) * (1e9 / rate)).astype(np.int64)
    meta: dict[str, Any] = {"format": "c3d", "source": path.name, "rate_hz": rate, "first_frame": first}
    units_list = _param(params, "POINT", "UNITS", ["mm"]) or ["mm"]
    unit = str(units_list[0]).strip(" \x00") or "mm"
    n_points = points.shape[1]
    if n_points and n_frames:
        if unit not in LENGTH_TO_M:
            raise ConversionError(path, f"unknown POINT:UNITS {unit!r}")
        labels = _labels(params, "POINT", n_points)
        outputs = set()
        for grp in MODEL_OUTPUT_GROUPS:
            outputs.update(str(x).strip() for x in (_param(params, "POINT", grp, []) or []))
        meta_points = c["data"].get("meta_points", {})
        residuals = meta_points["residuals"][0] if "residuals" in meta_points else None
        cameras = meta_points.get("camera_masks")  # (7, M, N) bool
        no_camera = ~np.asarray(cameras).any(axis=0).T if cameras is not None else True
        xyz = np.transpose(points[:3], (2, 1, 0)).astype(np.float64)  # (N, M, 3)
        valid = finite_rows(xyz)
        unmeasured_origin = np.zeros_like(valid)
        if residuals is not None and residuals.shape == (n_points, n_frames):
            valid &= residuals.T >= 0
            unmeasured_origin = valid & (residuals.T == 0) & no_camera & (xyz == 0).all(axis=2)
        marker_idx = [i for i, lab in enumerate(labels) if lab not in outputs]
        out_idx = [i for i, lab in enumerate(labels) if lab in outputs]
        if marker_idx:
            zeros = unmeasured_origin[:, marker_idx]
            if zeros.any():  # the C3D guide's invalid point: X = Y = Z = 0, written without the -1 residual word
                valid[:, marker_idx] &= ~zeros
                rec.warnings.append(
                    f"{path.name}: marker set {name!r}: {int(zeros.sum())} sample(s) of "
                    f"{int(zeros.any(axis=0).sum())} marker(s) at exactly (0, 0, 0) with no residual (not measured: "
                    "the C3D convention for an invalid point) stored as gaps"
                )
            pos, res = _positions_m(xyz[:, marker_idx, :], params, unit)
            rec.markers.append(
                MarkerStream(
                    name=name,
                    t_ns=t_ns,
                    labels=[labels[i] for i in marker_idx],
                    pos=pos,
                    valid=valid[:, marker_idx],
                    meta={"rate_hz": rate, "units": unit, "source": path.name, **res},
                )
            )
            meta.update(marker_units=unit, markers=len(marker_idx))
            rec.warnings.extend(invalid_marker_warnings(path, name, rec.markers[-1].labels, rec.markers[-1].valid))
        if out_idx:
            cols, units, vals = [], [], []
            for i in out_idx:
                for k, ax in enumerate("XYZ"):
                    cols.append(f"{labels[i]}.{ax}")
                    units.append("")
                    vals.append(np.where(valid[:, i], xyz[:, i, k], np.nan))
            rec.signals.append(
                SignalStream(
                    topic="/vicon/model_outputs", t_ns=t_ns, columns=cols, units=units, values=np.column_stack(vals)
                )
            )
    analogs = c["data"]["analogs"]  # (1, C, N*ratio)
    if analogs.size:
        a_rate = float((_param(params, "ANALOG", "RATE", [0.0]) or [0.0])[0]) or rate
        n_ch = analogs.shape[1]
        ratio = a_rate / rate
        labels = _labels(params, "ANALOG", n_ch)
        a_units = list(_param(params, "ANALOG", "UNITS", []) or [])
        a_units = [str(u).strip() for u in a_units[:n_ch]] + [""] * max(0, n_ch - len(a_units))
        n = analogs.shape[2]
        t_a = np.round((first + np.arange(n) / ratio) * (1e9 / rate)).astype(np.int64)
        a_values, a_hint = _analog_values(analogs[0].T.astype(np.float64), params)
        rec.analogs.append(
            AnalogStream(
                name=name,
                t_ns=t_a,
                channel_names=labels,
                units=a_units,
                values=a_values,
                meta={"rate_hz": a_rate, "source": path.name, **a_hint},
            )
        )
        meta.update(analog_rate_hz=a_rate, analog_channels=n_ch)
    used = int((_param(params, "EVENT", "USED", [0]) or [0])[0])
    if used > 0:
        times = np.asarray(_param(params, "EVENT", "TIMES"), dtype=np.float64).reshape(2, -1)[:, :used]
        seconds = times[0] * 60.0 + times[1]
        ev_labels = [str(x).strip() for x in (_param(params, "EVENT", "LABELS", []) or [])][:used]
        contexts = [str(x).strip() for x in (_param(params, "EVENT", "CONTEXTS", []) or [])][:used]
        ev_labels += [""] * (used - len(ev_labels))
        contexts += [""] * (used - len(contexts))
        full = [f"{ctx} {lab}".strip() for ctx, lab in zip(contexts, ev_labels, strict=True)]
        order = np.argsort(seconds, kind="stable")
        t_ev = np.round(seconds[order] * 1e9).astype(np.int64)
        rec.events.append(
            Intervals(topic=f"/events/{name}", start_ns=t_ev, end_ns=t_ev, labels=[full[i] for i in order])
        )
        meta["events"] = used
    if not rec.streams():
        raise ConversionError(path, "C3D file holds no points and no analog data")
    rec.metadata[f"imulog.device.{name}"] = meta
    return rec


class C3dConverter(Converter):
    name = "c3d"
    description = "C3D motion capture (points, analogs, events; Intel, DEC, MIPS; m or mm) via ezc3d, guarded"
    extensions = (".c3d",)
    example = "imulog convert markers_analogs.c3d -o trial.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        if len(head) >= 512 and head[1] == 0x50:
            return 0.95 if path.suffix.lower() == ".c3d" else 0.4
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        name = options.extra.get("vicon_name", "vicon") if options else "vicon"
        return read_c3d(Path(path), name=name, options=options)


CONVERTER = C3dConverter()
