"""One stream (or one block of it) as a typed Arrow table on a trial clock: the columns every table export writes
and ``TrialReader.read_pandas(clock=...)`` returns.

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
from typing import TYPE_CHECKING, Any

from imulog._lazy import LazyModule
from imulog.model import AnalogStream, ImuStream, Intervals, MarkerStream, PoseStream, SignalStream, Stream

if TYPE_CHECKING:
    from imulog.archive.trial_clock import TrialClock

np = LazyModule("numpy", __name__)  # the reader imports this module: imulog info never needs numpy

_KEEP = ("kind", "frame_id", "units", "algorithm", "params", "inputs", "source", "step", "run")


def stream_columns(stream: Stream) -> dict[str, Any]:
    """Flatten a stream into named 1-D columns (``acc_x``, ``O_x``, ``qw``...)."""
    cols: dict[str, Any] = {}
    if isinstance(stream, Intervals):
        return {
            "start_ns": stream.start_ns,
            "end_ns": stream.end_ns,
            "label": list(stream.labels),
            "task_index": stream.task_index,
        }
    cols["t_ns"] = stream.t_ns
    if isinstance(stream, ImuStream):
        for name in ("acc", "gyr", "mag"):
            a = getattr(stream, name)
            if a is not None:
                for k, axis in enumerate("xyz"):
                    cols[f"{name}_{axis}"] = a[:, k]
        if stream.temperature is not None:
            cols["temperature"] = stream.temperature
    elif isinstance(stream, MarkerStream):
        for j, label in enumerate(stream.labels):
            for k, axis in enumerate("xyz"):
                cols[f"{label}_{axis}"] = stream.pos[:, j, k]
            cols[f"{label}_valid"] = stream.valid[:, j]
    elif isinstance(stream, AnalogStream):
        for j, name in enumerate(stream.channel_names):
            cols[name] = stream.values[:, j]
    elif isinstance(stream, SignalStream):
        for j, name in enumerate(stream.columns):
            cols[name] = stream.values[:, j]
    elif isinstance(stream, PoseStream):
        for k, axis in enumerate("xyz"):
            cols[axis] = stream.position[:, k]
        for k, axis in enumerate(("qw", "qx", "qy", "qz")):
            cols[axis] = stream.orientation[:, k]
    return {k: (np.ascontiguousarray(v) if isinstance(v, np.ndarray) else v) for k, v in cols.items()}


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


def stream_table(stream: Stream, meta: dict[str, str], topic: str, tc: TrialClock):
    """A ``pyarrow.Table`` of one stream (or one block of it) on ``tc``'s clock."""
    import pyarrow as pa

    from imulog.archive.trial_clock import seconds_from, wall_clock_ns

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
