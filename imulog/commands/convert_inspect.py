"""``imulog convert --inspect``: what a conversion would make, printed without writing anything.

For each input (or each recording of a folder): the detected format, the header's columns and the channel each
goes to (delimited text and formats read through it: Shimmer), every stream with its samples, rate, units and
time span, the start time and where it came from, and every warning. Nothing is written, so a user can see what
a mapping file must say before writing one.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from imulog.converters import ConversionError, ConvertOptions
from imulog.model import Recording


def _rate(t_ns: np.ndarray) -> float | None:
    if len(t_ns) < 2:
        return None
    dt = float(np.median(np.diff(t_ns)))
    return 1e9 / dt if dt > 0 else None


def _fields(stream: Any) -> list[tuple[str, str]]:
    """(field, unit) pairs of one stream, as the archive will store them."""
    if hasattr(stream, "acc"):  # ImuStream
        out = []
        for q, unit in (("acc", "m/s^2"), ("gyr", "rad/s"), ("mag", "uT"), ("temperature", "degC")):
            if getattr(stream, q) is not None:
                out.append((q, unit))
        return out
    if hasattr(stream, "columns"):
        return list(zip(stream.columns, stream.units, strict=False))
    if hasattr(stream, "labels") and hasattr(stream, "pos"):
        return [(f"{len(stream.labels)} markers", "m")]
    if hasattr(stream, "channel_names"):
        return list(zip(stream.channel_names, stream.units, strict=False))
    if hasattr(stream, "position"):
        return [("position", "m"), ("orientation", "w,x,y,z")]
    return [("intervals", "")]


def column_roles(path: Path, fmt: str, options: ConvertOptions) -> list[str]:
    """``column -> channel field (unit)`` lines for delimited text; empty for other formats."""
    if fmt not in ("delimited", "shimmer-csv"):
        return []
    from imulog.converters._common import read_head, unit_overrides
    from imulog.converters.delimited import analyse_header
    from imulog.converters.mapping import load_mapping, sibling_mapping

    head = read_head(path)
    from imulog.converters._common import head_lines

    lines = head_lines(path, head)
    raw: set[int] | None = None
    if fmt == "shimmer-csv":
        from imulog.converters.shimmer import header, normalised_lines

        found = header(lines)
        if found is None:
            return []
        lines, raw = normalised_lines(lines, found)
    mapping_path = options.mapping or sibling_mapping(path)
    mapping = load_mapping(mapping_path) if mapping_path else None
    device = str(mapping.device.get("name", "imu")) if mapping else "imu"
    layout = analyse_header(
        path, lines, mapping=mapping, device_name=device, units=unit_overrides(options.extra), raw=raw
    )
    out = []
    for c in layout.columns:
        if c.quantity == "ignore":
            target = "(not read)"
        elif c.quantity == "time":
            target = "time"
        elif c.quantity == "index":
            target = "sample index"
        elif c.quantity == "marker":
            target = f"{c.device}: marker {c.variant!r} {c.axis} (/poses/{c.device} with an orientation group, else /markers)"
        elif c.quantity == "quat":
            target = f"/orientation/{c.device} q{c.axis}"
        elif c.quantity == "extra":
            target = f"/signals/{c.device}"
        elif c.quantity == "auto":
            target = f"/imu/{c.device} {c.axis} (quantity from the values)"
        else:
            target = f"/imu/{c.device} {c.quantity}{' ' + c.axis if c.axis else ''}"
        unit = "unit from the values" if c.unit == "?" else (c.unit or "no unit")
        out.append(f"  column {c.index + 1} {c.name!r} -> {target} [{unit}]")
    return out


def describe(
    files: list[Path], formats: list[str], rec: Recording, warnings: list[str], options: ConvertOptions
) -> dict:
    """What :func:`imulog.commands.convert` would write for ``files``, as a JSON-able dict."""
    streams = []
    for s in rec.streams():
        t = getattr(s, "t_ns", None)
        if t is None:
            t = getattr(s, "start_ns", np.zeros(0, dtype=np.int64))
        rate = _rate(np.asarray(t))
        streams.append(
            {
                "topic": s.topic if hasattr(s, "topic") else str(s),
                "samples": len(t),
                "rate_hz": round(rate, 4) if rate else None,
                "duration_s": round(float(t[-1] - t[0]) / 1e9, 3) if len(t) > 1 else 0.0,
                "fields": [f"{f} [{u}]" if u else f for f, u in _fields(s)],
            }
        )
    columns: dict[str, list[str]] = {}
    for p, f in zip(files, formats, strict=True):
        try:
            roles = column_roles(p, f, options)
        except ConversionError:
            roles = []
        if roles:
            columns[p.name] = roles
    inputs = {p.name: f for p, f in zip(files, formats, strict=True)}
    for meta in rec.metadata.values():
        inner = meta.get("compression") if isinstance(meta, dict) else None
        if inner and inputs.get(inner.get("container")) == "compressed":
            inputs[inner["container"]] = f"compressed ({inner['inner_format']} inside: {inner['inner']})"
    trial = rec.metadata.get("imulog.trial", {})
    return {
        "inputs": inputs,
        "columns": columns,
        "streams": streams,
        "start_time": trial.get("start_time"),
        "time_zone": trial.get("time_zone"),
        "start_time_source": trial.get("start_time_source"),
        "devices": {
            k.removeprefix("imulog.device."): v for k, v in rec.metadata.items() if k.startswith("imulog.device.")
        },
        "warnings": warnings,
    }


def render(report: dict) -> list[str]:
    """The report of :func:`describe` as text lines."""
    out = []
    for name, fmt in report["inputs"].items():
        out.append(f"{name}: format {fmt}")
        out.extend(report["columns"].get(name, []))
    out.append("would write:")
    for s in report["streams"]:
        rate = f"{s['rate_hz']:g} Hz" if s["rate_hz"] else "irregular/one sample"
        out.append(f"  {s['topic']}: {s['samples']} samples, {rate}, {s['duration_s']:g} s; {', '.join(s['fields'])}")
    if report["start_time"]:
        src = f" from {report['start_time_source']}" if report["start_time_source"] else ""
        out.append(f"start time: {report['start_time']} ({report['time_zone']}){src}")
    else:
        out.append("start time: none in the file (give --meta start_time=...)")
    for w in report["warnings"]:
        out.append(f"warning: {w}")
    if not report["warnings"]:
        out.append("no warnings")
    return out
