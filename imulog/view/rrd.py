"""Read a saved ``.rrd`` back with rerun-sdk's chunk reader (for checks, tests and ``imulog view --check``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

from imulog.view.layout import TIMELINE


@dataclass
class EntitySummary:
    """Temporal rows of one entity on ``reference_time``, its time range (ns) and component columns.

    ``component_rows`` counts, per component, the rows that carry it; ``rows`` is the largest of them (a
    component sent only where it changes, such as the class ids of markers with gaps, adds no rows).
    """

    t_min_ns: int | None = None
    t_max_ns: int | None = None
    timelines: set[str] = field(default_factory=set)
    components: set[str] = field(default_factory=set)
    static_components: set[str] = field(default_factory=set)
    component_rows: dict[str, int] = field(default_factory=dict)

    @property
    def rows(self) -> int:
        return max(self.component_rows.values(), default=0)


def _times_ns(column: pa.Array) -> np.ndarray:
    return np.asarray(column.cast(pa.int64()).to_numpy(zero_copy_only=False), dtype=np.int64)


def summarize(path: str | Path) -> dict[str, EntitySummary]:
    """Entity path -> :class:`EntitySummary` over the first recording in ``path``."""
    out: dict[str, EntitySummary] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        entry = out.setdefault(chunk.entity_path, EntitySummary())
        batch = chunk.to_record_batch()
        components = {n for n in batch.schema.names if ":" in n}
        if chunk.is_static:
            entry.static_components |= components
            continue
        entry.components |= components
        entry.timelines |= set(chunk.timeline_names)
        if TIMELINE in batch.schema.names:
            t = _times_ns(batch.column(TIMELINE))
            for name in components:
                column = batch.column(name)
                entry.component_rows[name] = entry.component_rows.get(name, 0) + len(column) - column.null_count
            if len(t):
                lo, hi = int(t.min()), int(t.max())
                entry.t_min_ns = lo if entry.t_min_ns is None else min(entry.t_min_ns, lo)
                entry.t_max_ns = hi if entry.t_max_ns is None else max(entry.t_max_ns, hi)
    return out


def read_column(path: str | Path, entity: str, component: str) -> tuple[np.ndarray, list]:
    """(reference time ns, per-row values as Python lists) of ``component`` of ``entity``, sorted by time."""
    times: list[np.ndarray] = []
    values: list = []
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if component not in batch.schema.names:
            continue
        times.append(_times_ns(batch.column(TIMELINE)))
        values.extend(batch.column(component).to_pylist())
    if not times:
        return np.zeros(0, np.int64), []
    t = np.concatenate(times)
    order = np.argsort(t, kind="stable")
    return t[order], [values[i] for i in order]


def read_scalars(path: str | Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(reference time ns (N,), values (N, C)) of a ``Scalars`` entity."""
    t, rows = read_column(path, entity, "Scalars:scalars")
    if not rows:
        return t, np.zeros((0, 0))
    return t, np.asarray(rows, dtype=np.float64)
