"""XDF streams to imulog streams: channel labels, types and units decide IMU, markers, signals or events; the
``imulog.device.<stream>`` record; the file header's start time (shared by the converter and the live capture)."""

from __future__ import annotations

import re
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._binary import format_offset
from imulog.converters._common import sanitize_name, unit_factor
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Intervals, MarkerStream, Recording, SignalStream

_AXIS = r"[ _\-.:]?([xyz])"
IMU_LABELS = {
    "acc": re.compile(r"^(?:acc|accel|accelerometer|acceleration)" + _AXIS + "$", re.I),
    "gyr": re.compile(r"^(?:gyr|gyro|gyroscope|angularvelocity|angular_velocity)" + _AXIS + "$", re.I),
    "mag": re.compile(r"^(?:mag|magn|magnetometer|magneticfield)" + _AXIS + "$", re.I),
}
IMU_TYPES = {"accelerometer": "acc", "acc": "acc", "gyroscope": "gyr", "gyro": "gyr", "magnetometer": "mag"}
LENGTH_UNITS = {"m": 1.0, "meters": 1.0, "cm": 0.01, "mm": 0.001, "millimeters": 0.001}


def _first(d: Any, key: str, default: Any = None) -> Any:
    if not isinstance(d, dict):
        return default
    v = d.get(key)
    if isinstance(v, list):
        return v[0] if v else default
    return v if v is not None else default


def channel_info(info: dict, n: int) -> tuple[list[str], list[str], list[str]]:
    """(labels, units, types) of a stream's channels from ``desc/channels/channel`` (``ch<i>`` / "" when absent)."""
    labels, units, types = [f"ch{i}" for i in range(n)], [""] * n, [""] * n
    desc = _first(info, "desc")
    channels = _first(desc, "channels")
    entries = channels.get("channel", []) if isinstance(channels, dict) else []
    for i, ch in enumerate(entries[:n]):
        labels[i] = str(_first(ch, "label", labels[i]) or labels[i]).strip()
        units[i] = str(_first(ch, "unit", "") or "").strip()
        types[i] = str(_first(ch, "type", "") or "").strip()
    return labels, units, types


def _imu_groups(labels: list[str], units: list[str], types: list[str]) -> dict[str, tuple[list[int], float, str]]:
    """quantity -> (x, y, z channel indices, factor to SI, unit as declared) for complete groups with known units."""
    found: dict[str, dict[str, int]] = {}
    for i, (label, ctype) in enumerate(zip(labels, types, strict=True)):
        for q, rx in IMU_LABELS.items():
            m = rx.match(label.replace(" ", ""))
            if m:
                found.setdefault(q, {})[m.group(1).lower()] = i
                break
        else:
            q = IMU_TYPES.get(ctype.lower())
            m = re.search(r"([xyz])$", label, re.I)
            if q and m:
                found.setdefault(q, {})[m.group(1).lower()] = i
    out = {}
    for q, axes in found.items():
        if set(axes) != {"x", "y", "z"}:
            continue
        idx = [axes["x"], axes["y"], axes["z"]]
        declared = {units[i] for i in idx}
        if len(declared) != 1:
            continue
        unit = declared.pop()
        factor = unit_factor(q, unit) if unit else None
        if factor is not None:
            out[q] = (idx, factor, unit)
    return out


def _marker_groups(labels: list[str], units: list[str]) -> tuple[list[str], list[list[int]], float] | None:
    if len(labels) % 3 or not labels:
        return None
    names, groups = [], []
    for j in range(0, len(labels), 3):
        trio = labels[j : j + 3]
        m = [re.match(r"^(.*?)[ _\-.:]?([xyz])$", lab, re.I) for lab in trio]
        if not all(m) or [x.group(2).lower() for x in m] != ["x", "y", "z"] or len({x.group(1) for x in m}) != 1:
            return None
        names.append(m[0].group(1) or f"marker{j // 3}")
        groups.append(list(range(j, j + 3)))
    declared = {u.lower() for u in units}
    if len(declared) != 1 or declared.pop() not in LENGTH_UNITS or len(set(names)) != len(names):
        return None
    return names, groups, LENGTH_UNITS[units[0].lower()]


def stream_meta(path: Path, info: dict, name: str, n_samples: int, footer: dict | None, segments: int) -> dict:
    """The ``imulog.device.<name>`` record of a stream: its header, sample count, footer count, clock segments."""
    meta: dict[str, Any] = {
        "format": "xdf",
        "stream_name": str(_first(info, "name", name)),
        "stream_type": str(_first(info, "type", "") or ""),
        "stream_id": int(_first(info, "stream_id", 0) or 0),
        "channel_format": str(_first(info, "channel_format", "float32")),
        "channel_count": int(float(_first(info, "channel_count", 1) or 1)),
        "nominal_srate_hz": float(_first(info, "nominal_srate", 0) or 0),
        "samples": int(n_samples),
        "time_base": "ns of the recording host's LSL clock, stream clock offsets applied",
        "source": path.name,
    }
    for key in ("source_id", "hostname", "created_at", "uid"):
        v = _first(info, key)
        if v:
            meta[key] = str(v)
    manufacturer = _first(_first(info, "desc"), "manufacturer")
    if manufacturer:
        meta["manufacturer"] = str(manufacturer)
    footer_info = (footer or {}).get("info") or {}
    if footer_info:
        meta["footer_sample_count"] = int(float(_first(footer_info, "sample_count", 0) or 0))
    meta["clock_segments"] = segments  # > 1: the host clock was reset during the recording
    return meta


def stream_layout(info: dict) -> tuple[str, Any]:
    """How a stream's channels map to imulog streams: ("events", None), ("markers", (names, groups, scale)) or
    ("numeric", (IMU groups, the remaining channel indices, their column names, units))."""
    fmt = str(_first(info, "channel_format", "float32"))
    if fmt == "string":
        return "events", None
    n_ch = int(float(_first(info, "channel_count", 1) or 1))
    labels, units, types = channel_info(info, n_ch)
    if str(_first(info, "type", "") or "").lower() in ("mocap", "motion capture"):
        markers = _marker_groups(labels, units)
        if markers is not None:
            return "markers", markers
    groups = _imu_groups(labels, units, types)
    if "acc" not in groups and "gyr" not in groups:
        groups = {}
    used = {i for idx, _, _ in groups.values() for i in idx}
    rest = [i for i in range(n_ch) if i not in used]
    cols = [labels[i] for i in rest]
    if len(set(cols)) != len(cols):
        cols = [f"{c}_{i}" for c, i in zip(cols, rest, strict=True)]
    return "numeric", (groups, rest, cols, [units[i] for i in rest])


def stream_piece(name: str, layout: tuple[str, Any], t_ns: np.ndarray, series: Any, meta: dict) -> list[Any]:
    """The imulog streams of some samples of one stream (``series``: (n, channels) numbers or string rows);
    ``meta`` is the device record (the IMU stream carries it with the declared IMU units, markers without)."""
    kind, how = layout
    if kind == "events":
        labels = ["|".join(str(v) for v in row) if isinstance(row, list | tuple) else str(row) for row in series]
        return [Intervals(topic=f"/events/{name}", start_ns=t_ns, end_ns=t_ns.copy(), labels=labels)]
    n_ch = int(meta["channel_count"])
    values = np.asarray(series, dtype=np.float64).reshape(len(t_ns), n_ch)
    if kind == "markers":
        marker_names, groups, scale = how
        pos = np.stack([values[:, g] for g in groups], axis=1) * scale
        shown = {k: v for k, v in meta.items() if k != "marker_units"}
        return [MarkerStream(name=name, t_ns=t_ns, labels=marker_names, pos=pos, meta=shown)]
    groups, rest, cols, units = how
    out: list[Any] = []
    if groups:
        parts = {q: values[:, idx] * factor for q, (idx, factor, _) in groups.items()}
        out.append(
            ImuStream(
                name=name, t_ns=t_ns, acc=parts.get("acc"), gyr=parts.get("gyr"), mag=parts.get("mag"), meta=dict(meta)
            )
        )
    if rest or not groups:
        out.append(SignalStream(topic=f"/signals/{name}", t_ns=t_ns, columns=cols, units=units, values=values[:, rest]))
    return out


def device_meta(path: Path, info: dict, name: str, n: int, footer: dict | None, segments: int) -> dict:
    """:func:`stream_meta` plus what the layout adds: the declared IMU units or the markers' unit."""
    meta = stream_meta(path, info, name, n, footer, segments)
    kind, how = stream_layout(info)
    if kind == "markers":
        meta["marker_units"] = channel_info(info, int(meta["channel_count"]))[1][0]
    elif kind == "numeric" and how[0]:
        meta["imu_units_declared"] = {q: u for q, (_, _, u) in how[0].items()}
    return meta


def _check_increasing(path: Path, t_ns: np.ndarray, meta: dict, before: int | None, offset: int) -> None:
    """Stamps must increase (also from the previous piece's last, ``before``); the sample is named by its index."""
    full = t_ns if before is None else np.concatenate([[before], t_ns])
    bad = np.flatnonzero(np.diff(full) <= 0)
    if len(bad):
        i = int(bad[0]) + 1 + offset - (0 if before is None else 1)
        raise ConversionError(
            path, f"stream {meta['stream_id']} ({meta['stream_name']!r}): sample {i} time stamp does not increase"
        )


def stream_to_recording(path: Path, stream: dict, name: str) -> Recording:
    """One stream in pyxdf's layout (``info``, ``time_stamps`` s, ``time_series``, optional ``footer``) -> a
    Recording with its channel(s) and an ``imulog.device.<name>`` record (the live capture's mapping)."""
    info = stream["info"]
    t_ns = np.round(np.asarray(stream["time_stamps"], dtype=np.float64) * 1e9).astype(np.int64)
    segments = len(info.get("clock_segments") or [])
    meta = device_meta(path, info, name, len(t_ns), stream.get("footer"), segments)
    rec = Recording(sources=[str(path)])
    rec.metadata[f"imulog.device.{name}"] = meta
    _check_increasing(path, t_ns, meta, None, 0)
    for s in stream_piece(name, stream_layout(info), t_ns, stream["time_series"], meta):
        {ImuStream: rec.imus, MarkerStream: rec.markers, SignalStream: rec.signals, Intervals: rec.events}[
            type(s)
        ].append(s)
    return rec


def header_start_time(header: dict) -> dict[str, str]:
    """``imulog.trial`` start fields from the FileHeader ``datetime`` (``2025-01-31T00:21:17+0000``), else {}."""
    text = _first(header.get("info", {}), "datetime")
    if not text:
        return {}
    try:
        when = datetime.fromisoformat(str(text).strip())
    except ValueError:
        return {}
    if when.tzinfo is None:
        return {"start_time": when.isoformat(timespec="milliseconds"), "time_zone": "unknown (device local time)"}
    offset = int(when.utcoffset().total_seconds())  # type: ignore[union-attr]
    zone = "UTC" if offset == 0 else format_offset(offset)
    return {"start_time": when.isoformat(timespec="milliseconds"), "time_zone": zone}


def _stream_names(infos: list[dict]) -> dict[int, str]:
    names = {int(i["stream_id"]): sanitize_name(str(i.get("name") or "stream")) for i in infos}
    taken = list(names.values())
    return {sid: (n if taken.count(n) == 1 else f"{n}_{sid}") for sid, n in names.items()}
