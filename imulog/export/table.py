"""One channel as a typed table (Parquet or CSV): wall-clock time, seconds from start, units in names.

Columns: ``time`` (timestamp[ns] with the trial's time zone; only when ``imulog.trial`` records a
``start_time``), ``t[s]`` (float seconds from the trial's first raw sample on the chosen clock),
``t_ns`` (int64 ns on the chosen clock), then the values named ``acc_x[m/s^2]``, ``O_x[m]``... (no
suffix for dimensionless or boolean columns). Every field's metadata holds ``unit`` and ``name`` (the
bare column name); the schema metadata holds the channel's topic, frame, provenance and the clock.
Intervals give ``start_time``/``end_time``, ``start[s]``, ``end[s]``, ``duration[s]``,
``start_ns``/``end_ns``, ``label`` and ``task_index``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from imulog.archive.errors import ArchiveError
from imulog.export._atomic import ExportError, atomic_file
from imulog.export.clock import ClockError, TrialClock, seconds_from, trial_clock, wall_clock_ns
from imulog.model import ImuStream, Intervals, MarkerStream, PoseStream, Stream

FORMATS = ("parquet", "csv")
_KEEP = ("kind", "frame_id", "units", "algorithm", "params", "inputs", "source", "step", "run")


def _json_list(text: str | None) -> list[Any] | None:
    try:
        value = json.loads(text) if text else None
    except ValueError:
        return None
    return value if isinstance(value, list) else None


def column_units(stream: Stream, meta: dict[str, str], columns: list[str]) -> dict[str, str]:
    """Unit of each flat column (``stream_columns`` names) from the channel's ``units`` metadata."""
    units = _json_list(meta.get("units"))
    single = meta.get("units", "") if units is None else ""
    out: dict[str, str] = {}
    if isinstance(stream, ImuStream):
        groups = _json_list(meta.get("columns")) or ["acc", "gyr", "mag"]
        by_group = dict(zip(groups, units or [], strict=False))
        defaults = {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT", "temperature": "degC"}
        for c in columns:
            group = c.split("_", 1)[0] if c != "temperature" else "temperature"
            out[c] = str(by_group.get(group, defaults.get(group, "")))
    elif isinstance(stream, MarkerStream):
        for c in columns:
            out[c] = "" if c.endswith("_valid") else (single or "m")
    elif isinstance(stream, PoseStream):
        for c in columns:
            out[c] = (single or "m") if c in ("x", "y", "z") else "1"
    else:
        names = list(getattr(stream, "columns", None) or getattr(stream, "channel_names", None) or [])
        by_name = dict(zip(names, units or [], strict=False))
        for c in columns:
            out[c] = str(by_name.get(c, single))
    return out


def labelled(name: str, unit: str) -> str:
    """``acc_x`` + ``m/s^2`` -> ``acc_x[m/s^2]``; no suffix for dimensionless (``1``) or unknown units."""
    return f"{name}[{unit}]" if unit and unit != "1" else name


@dataclass
class ExportResult:
    """What an export wrote (``to_dict`` is what ``--json`` prints)."""

    path: str
    format: str
    clock: str
    rows: int = 0
    columns: list[str] = field(default_factory=list)
    topics: list[str] = field(default_factory=list)
    files: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in ("path", "format", "clock", "rows", "columns", "topics", "files", "notes")}


def stream_table(stream: Stream, meta: dict[str, str], topic: str, tc: TrialClock):
    """A ``pyarrow.Table`` of one stream (or one block of it) on ``tc``'s clock."""
    import pyarrow as pa

    from imulog.archive.reader import stream_columns

    fields: list[tuple[str, Any, dict[str, str]]] = []  # (name, array, field metadata)

    def time_fields(prefix: str, t_ns: np.ndarray) -> None:
        t = tc.times(topic, t_ns)
        stem = prefix or "t"
        if tc.start_time is not None:
            wall = wall_clock_ns(t, tc.origin_ns, tc.start_time)
            fields.append(
                (
                    f"{prefix}_time" if prefix else "time",
                    pa.array(wall, pa.timestamp("ns", tz=tc.time_zone)),
                    {"unit": "ns"},
                )
            )
        fields.append((f"{stem}[s]", pa.array(seconds_from(t, tc.origin_ns)), {"unit": "s", "name": stem}))
        fields.append((f"{stem}_ns", pa.array(t), {"unit": "ns", "name": f"{stem}_ns"}))

    if isinstance(stream, Intervals):
        time_fields("start", stream.start_ns)
        time_fields("end", stream.end_ns)
        dur = (np.asarray(stream.end_ns, np.int64) - np.asarray(stream.start_ns, np.int64)) / 1e9
        fields.append(("duration[s]", pa.array(dur.astype(np.float64)), {"unit": "s", "name": "duration"}))
        fields.append(("label", pa.array(list(stream.labels), pa.string()), {"unit": ""}))
        fields.append(("task_index", pa.array(np.asarray(stream.task_index, np.int64)), {"unit": ""}))
    else:
        cols = stream_columns(stream)
        t_ns = cols.pop("t_ns")
        time_fields("", t_ns)
        units = column_units(stream, meta, list(cols))
        for name, values in cols.items():
            fields.append((labelled(name, units[name]), pa.array(values), {"unit": units[name], "name": name}))
    schema_meta = {"topic": topic, **{k: meta[k] for k in _KEEP if k in meta}, **tc.record()}
    schema = pa.schema([pa.field(n, a.type, metadata=m) for n, a, m in fields], metadata=schema_meta)
    return pa.Table.from_arrays([a for _, a, _ in fields], schema=schema)


def channel_table(
    trial,
    topic: str,
    *,
    clock: str = "device",
    imu: str | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
):
    """The whole channel (optionally ``start_ns <= t < end_ns`` on its stored clock) as one table."""
    tc = trial_clock(trial, clock, imu)
    stream = trial.read(topic, start_ns, end_ns)
    return stream_table(stream, trial.channel(topic).metadata, topic, tc)


def format_of(path: str | Path, fmt: str | None = None) -> str:
    """``parquet`` or ``csv`` from ``fmt`` or the file's suffix."""
    fmt = (fmt or Path(path).suffix.lstrip(".")).lower()
    if fmt not in FORMATS:
        raise ExportError(f"{path}: a table export ends in .parquet or .csv (or give --to parquet|csv)")
    return fmt


def export_table(
    trial,
    topic: str,
    out: str | Path,
    *,
    fmt: str | None = None,
    clock: str = "device",
    imu: str | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> ExportResult:
    """Write one channel to Parquet or CSV, block by block (memory bounded by one chunk), atomically."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    fmt = format_of(out, fmt)
    tc = trial_clock(trial, clock, imu)
    meta = trial.channel(topic).metadata
    result = ExportResult(path=str(out), format=fmt, clock=clock, topics=[topic], files=[str(out)])
    if meta.get("kind") == "intervals":
        pieces = iter([trial.read(topic, start_ns, end_ns)])
    else:
        pieces = trial.iter_blocks(topic, start_ns, end_ns)
    with atomic_file(out) as tmp:
        writer = None
        try:
            for stream in pieces:
                table = stream_table(stream, meta, topic, tc)
                if writer is None:
                    writer = (
                        pq.ParquetWriter(tmp, table.schema) if fmt == "parquet" else pacsv.CSVWriter(tmp, table.schema)
                    )
                    result.columns = table.column_names
                writer.write_table(table)
                result.rows += table.num_rows
            if writer is None:  # nothing in range: an empty table with the right columns
                table = stream_table(trial.read(topic, start_ns, end_ns), meta, topic, tc)
                result.columns = table.column_names
                if fmt == "parquet":
                    pq.write_table(table, tmp)
                else:
                    pacsv.write_csv(table, tmp)
        finally:
            if writer is not None:
                writer.close()
    result.notes = list(tc.notes)
    return result


__all__ = [
    "ArchiveError",
    "ClockError",
    "ExportResult",
    "channel_table",
    "column_units",
    "export_table",
    "format_of",
    "labelled",
    "stream_table",
]
