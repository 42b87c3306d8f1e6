"""Markdown documents shown in the viewer: the trial/alignment description and the evaluation (error) report."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from imulog.archive.clocks import ClockMap
from imulog.view import layout as L


def _flatten(record: Mapping[str, Any], parent: str = "") -> list[tuple[str, Any]]:
    rows: list[tuple[str, Any]] = []
    for key, value in record.items():
        name = f"{parent}.{key}" if parent else str(key)
        if isinstance(value, Mapping):
            rows.extend(_flatten(value, name))
        else:
            rows.append((name, value))
    return rows


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list | tuple):
        return ", ".join(_fmt(v) for v in value)
    return str(value)


def markdown_table(record: Mapping[str, Any]) -> str:
    """A flat two-column Markdown table of a (nested) metadata record."""
    lines = ["| quantity | value |", "|---|---|"]
    lines += [f"| {k} | {_fmt(v)} |" for k, v in _flatten(record)]
    return "\n".join(lines)


def info_markdown(label: str, metadata: Mapping[str, Mapping[str, Any]], clocks: ClockMap) -> str:
    parts = [f"# {label}", ""]
    if "imulog.trial" in metadata:
        parts += ["## Trial", markdown_table(metadata["imulog.trial"]), ""]
    parts += ["## Timeline", f"`{L.TIMELINE}`: reference (Vicon) clock, ns."]
    if clocks.alignments:
        for imu, record in clocks.alignments.items():
            shown = ("offset_ns", "drift_ppm", "t0_ns", "method", "score", "drift_uncertainty_ppm", "quality")
            keep = {k: record[k] for k in shown if k in record}
            parts += [f"IMU `{imu}` mapped with `imulog.alignment`:", "", markdown_table(keep), ""]
    if clocks.unaligned:
        parts += [f"**No alignment for IMU(s) {', '.join(sorted(clocks.unaligned))}: shown on their device clock.**"]
    return "\n".join(parts)


def _mean_std(value: Any) -> str:
    if isinstance(value, Mapping) and "mean" in value:
        std = value.get("std")
        return f"{value['mean']:.3g} ± {std:.2g}" if isinstance(std, int | float) else f"{value['mean']:.3g}"
    return _fmt(value)


def evaluation_markdown(record: Mapping[str, Any]) -> str:
    """The ``imulog.evaluation`` record as Markdown: per axis, one row per method, mean ± std of each metric.

    Records without the ``methods -> {name: {summary: {axis: {metric: {mean, std}}}}}`` layout are shown as a
    flat key/value table (lists of per-repetition entries are summarised by their length).
    """
    title = "# Evaluation: errors vs the optical reference"
    methods = record.get("methods")
    if not isinstance(methods, Mapping) or not all(
        isinstance(m, Mapping) and isinstance(m.get("summary"), Mapping) for m in methods.values()
    ):
        flat = {
            k: (f"{len(v)} entries" if isinstance(v, list) and v and isinstance(v[0], Mapping) else v)
            for k, v in record.items()
        }
        return f"{title}\n\n{markdown_table(flat)}"
    units = record.get("units", {}) if isinstance(record.get("units"), Mapping) else {}
    metrics = list(record.get("metrics") or [])
    parts = [title, ""]
    if "reference" in record:
        parts += [f"Reference: `{record['reference']}`. Mean ± std over repetitions.", ""]
    axes: list[str] = []
    for m in methods.values():
        axes += [a for a in m["summary"] if a not in axes]
    for axis in axes:
        names = metrics or sorted({k for m in methods.values() for k in m["summary"].get(axis, {})})
        header = [f"{n} ({units[n]})" if n in units else n for n in names]
        parts += [f"## {axis}", "", "| method | " + " | ".join(header) + " |", "|---" * (len(names) + 1) + "|"]
        for method, m in methods.items():
            row = m["summary"].get(axis, {})
            parts.append(f"| {method} | " + " | ".join(_mean_std(row.get(n, "")) for n in names) + " |")
        parts.append("")
    return "\n".join(parts)


def metrics_markdown(record: Mapping[str, Any]) -> str:
    """The ``imulog.metrics`` record (flat dotted keys) as Markdown, one table per group.

    Groups are the first part of each key (``arm_usage``, ``activity``, ``distance``, ``timings``,
    ``smoothness``, ``nhpt``); long lists (e.g. the distance histogram) are summarised by their length.
    """
    groups: dict[str, dict[str, Any]] = {}
    periods = {k: record[k] for k in ("by_day", "by_hour") if isinstance(record.get(k), list)}
    for key, value in record.items():
        if key in periods:
            continue
        group, _, rest = key.partition(".")
        if not rest:
            group, rest = "recording", key
        if isinstance(value, list) and len(value) > 12:
            value = f"{len(value)} values"
        groups.setdefault(group, {})[rest] = value
    parts = ["# Clinical metrics", "", "Computed by `imulog process metrics` (see docs/metrics.md)."]
    for group, values in groups.items():
        parts += ["", f"## {group.replace('_', ' ')}", markdown_table(values)]
    for key, rows in periods.items():
        parts += ["", f"## {'per day' if key == 'by_day' else 'per hour'}", period_table(rows)]
    return "\n".join(parts)


def period_table(rows: list[Any]) -> str:
    """Per-hour or per-day summaries (``imulog.metrics`` ``by_hour``/``by_day``) as one Markdown table."""
    lines = ["| start | valid (h) | arm use (%) | activities | distance area (% cm) |", "|---|---|---|---|---|"]
    for r in rows:
        if not isinstance(r, Mapping):
            continue
        use = r.get("arm_use_percent")
        lines.append(
            f"| {r.get('start') or r.get('start_ns')} | {float(r.get('valid_s') or 0) / 3600:.2f} | "
            f"{'-' if use is None else f'{float(use):.1f}'} | {r.get('activity_count', '')} | "
            f"{float(r.get('distance_weighted_area') or 0):.1f} |"
        )
    return "\n".join(lines)
