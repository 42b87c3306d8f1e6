"""The columnar primitives of the Rerun logging: what was logged (:class:`Entity`, :class:`LoggedTrial`), time
and component columns as arrow views, and :class:`ColumnLogger`, which sends scalars, states, points and strips
(used by :mod:`imulog.view.streams`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr

from imulog.archive.clocks import ClockMap
from imulog.view import layout as L
from imulog.view import rates
from imulog.view.phase_colors import known_phase_colors


@dataclass
class Entity:
    """One logged entity: ``role`` tells the blueprint where it belongs; ``rows`` temporal rows sent."""

    path: str
    role: str
    topic: str
    rows: int
    t_min_ns: int | None = None
    t_max_ns: int | None = None
    scale: float | None = None  # typical magnitude (95th percentile) of an error series, its unit
    color: tuple[int, int, int] | None = None


@dataclass
class LoggedTrial:
    """What :func:`log_streams` sent for one trial."""

    label: str
    prefix: str = ""
    entities: list[Entity] = field(default_factory=list)
    unaligned_imus: list[str] = field(default_factory=list)
    has_evaluation: bool = False

    def by_role(self, *roles: str) -> list[Entity]:
        """Entities having one of ``roles``, in logging order."""
        return [e for e in self.entities if e.role in roles]

    def paths(self) -> list[str]:
        """All entity paths logged."""
        return [e.path for e in self.entities]


class _TimeIndex:
    """The ``reference_time`` column of a batch (rerun's ``TimeColumnLike``): an arrow view of int64 ns, no copy."""

    def __init__(self, t_ref_ns: np.ndarray) -> None:
        t = np.ascontiguousarray(t_ref_ns, dtype=np.int64)
        self._times = pa.Array.from_buffers(pa.duration("ns"), len(t), [None, pa.py_buffer(t)])
        self._keep = t  # the buffer the arrow array points into

    def timeline_name(self) -> str:
        return L.TIMELINE

    def as_arrow_array(self) -> pa.Array:
        return self._times


class _ArrowBatch:
    """A component batch (rerun's ``ComponentBatchLike``) over an arrow array built here."""

    def __init__(self, array: pa.Array) -> None:
        self._array = array

    def as_arrow_array(self) -> pa.Array:
        return self._array


def scalar_column(values: np.ndarray) -> rr.ComponentColumn:
    """``Scalars:scalars`` of ``values`` (N, C), one row of C per sample: arrow views of the float64 array.

    ``rr.Scalars.columns`` flattens (copies) the array first; this sends the array's own buffer.
    """
    v = np.ascontiguousarray(values, dtype=np.float64)
    width = v.shape[1] if v.ndim == 2 else 1
    flat = pa.Array.from_buffers(pa.float64(), v.size, [None, pa.py_buffer(v)])
    offsets = np.arange(0, v.size + 1, width, dtype=np.int32)
    return rr.ComponentColumn(rr.Scalars.descriptor_scalars(), _ArrowBatch(flat), offsets=offsets)


def _norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norm of each row of ``v`` (N, 3), same unit (NaN rows stay NaN)."""
    v = np.asarray(v, dtype=np.float64)
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _rgb(c: tuple[int, int, int]) -> list[int]:
    return [int(c[0]), int(c[1]), int(c[2])]


class ColumnLogger:
    """Sends columns of one trial to a Rerun recording on the reference timeline (the primitives of ``_Logger``)."""

    def __init__(
        self,
        rec: rr.RecordingStream,
        trial: LoggedTrial,
        clocks: ClockMap,
        color_offset: int,
        reference: tuple[np.ndarray, np.ndarray] | None = None,
        trajectory_record: Mapping[str, Any] | None = None,
        timing_record: Mapping[str, Any] | None = None,
        metadata: Mapping[str, Any] | None = None,
    ):
        self.rec = rec
        self.trial = trial
        self.clocks = clocks
        self.prefix = trial.prefix
        self.n_paths = color_offset  # next palette index for a trajectory / marker set
        self.reference = reference  # Vicon cluster origin (t_ref ns, position m); set when the cluster pose is logged
        self.trajectory_record = dict(trajectory_record or {})
        self.metadata = metadata or {}  # the per-IMU trajectory records (imulog.trajectory.IMU)
        self.references: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # IMU -> its cluster origin (a setup)
        self.timing_record = dict(timing_record or {})  # imulog.timing: forced phases, repetition confidence
        self._index: tuple[np.ndarray, _TimeIndex] | None = None  # last time column, reused for the same array

    def _time(self, t_ref: np.ndarray) -> _TimeIndex:
        """Time column of ``t_ref``; the same array sent again (IMU quantities, cursor, error) reuses it."""
        if self._index is None or self._index[0] is not t_ref:
            self._index = (t_ref, _TimeIndex(t_ref))
        return self._index[1]

    # -- primitives -------------------------------------------------------------------------------
    def _record(self, path: str, role: str, topic: str, t_ref: np.ndarray) -> None:
        rows = len(t_ref)
        self.trial.entities.append(
            Entity(path, role, topic, rows, int(t_ref.min()) if rows else None, int(t_ref.max()) if rows else None)
        )

    def scalars(
        self,
        path: str,
        role: str,
        topic: str,
        t_ref: np.ndarray,
        values: np.ndarray,
        names: list[str],
        colors: list[tuple[int, int, int]] | None = None,
    ) -> None:
        values = np.asarray(values, dtype=np.float64)
        if values.ndim == 1:
            values = values[:, None]
        if len(t_ref) == 0 or values.shape[1] == 0:
            return
        self.rec.send_columns(path, indexes=[self._time(t_ref)], columns=[scalar_column(values)])
        style: dict[str, Any] = {"names": names}
        if colors is None and values.shape[1] <= len(L.AXIS_COLORS):
            colors = L.AXIS_COLORS[: values.shape[1]]
        if colors is not None:
            style["colors"] = [_rgb(c) for c in colors]
        self.rec.log(path, rr.SeriesLines(**style), static=True)
        self._record(path, role, topic, t_ref)

    def states(
        self,
        path: str,
        role: str,
        topic: str,
        t_ref: np.ndarray,
        states: np.ndarray,
        lanes: int,
        colors: Mapping[str, int] | None = None,
    ) -> None:
        """StateChange rows: ``states`` is (rows * lanes,) strings; empty string = reset (gap).

        ``colors`` maps state values to RGBA; by default the R2G phase colours (:data:`layout.PHASE_COLORS`) and
        grey for forced phases.
        """
        if len(t_ref) == 0:
            return
        text = [str(v) for v in states]
        columns = rr.StateChange.columns(state=text).partition(np.full(len(t_ref), lanes))
        self.rec.send_columns(path, indexes=[self._time(t_ref)], columns=columns)
        if colors is None:
            colors = known_phase_colors(text)
        if colors:
            values = sorted(colors)
            self.rec.log(
                path,
                rr.StateConfiguration(values=values, colors=np.array([colors[v] for v in values], dtype=np.uint32)),
                static=True,
            )
        self._record(path, role, topic, t_ref)

    def points(
        self,
        path: str,
        role: str,
        topic: str,
        t_ref: np.ndarray,
        pos: np.ndarray,
        valid: np.ndarray,
        radius_m: float,
        colour: tuple[int, int, int] | None,
        labels: list[str] | None = None,
    ) -> None:
        """Points3D, one row per sample; ``pos`` (N, M, 3), only valid points sent (rows may be empty).

        Without gaps every row holds the same M points in order, so the marker class ids (labels, colours) are
        sent once as a static column; with gaps they are sent only at the rows where the set of visible markers
        changes (:func:`rates.pattern_changes`), which latest-at carries forward to the rows in between.
        """
        n, m = valid.shape
        if n == 0:
            return
        complete = bool(valid.all())
        if complete:  # fast path: no gaps, M points per row
            flat = np.ascontiguousarray(pos, dtype=np.float32).reshape(-1, 3)
        else:
            flat = np.compress(valid.reshape(-1), pos.reshape(-1, 3), axis=0).astype(np.float32, copy=False)
        if labels is not None:
            self.rec.log(
                path,
                rr.AnnotationContext([(i, label, _rgb(L.color(i + 3))) for i, label in enumerate(labels)]),
                static=True,
            )
            static_ids = np.arange(m, dtype=np.uint16) if complete else None
            self.rec.log(
                path, rr.Points3D.from_fields(radii=[radius_m], show_labels=False, class_ids=static_ids), static=True
            )
        else:
            self.rec.log(
                path, rr.Points3D.from_fields(radii=[radius_m], colors=[_rgb(colour or (0, 0, 0))]), static=True
            )
        cols = rr.Points3D.columns(positions=flat)
        if not (complete and m == 1):  # one point per row is the default partition
            cols = cols.partition(np.full(n, m, dtype=np.int64) if complete else valid.sum(axis=1))
        self.rec.send_columns(path, indexes=[self._time(t_ref)], columns=cols)
        if labels is not None and not complete:
            self.class_id_changes(path, t_ref, valid)
        self._record(path, role, topic, t_ref)

    def class_id_changes(self, path: str, t_ref: np.ndarray, valid: np.ndarray) -> None:
        """The class ids of the visible markers, at the rows where the set of visible markers changes."""
        rows = rates.pattern_changes(valid)
        shown = valid[rows]
        ids = np.nonzero(shown)[1].astype(np.uint16)
        cols = rr.Points3D.columns(class_ids=ids).partition(shown.sum(axis=1))
        self.rec.send_columns(path, indexes=[_TimeIndex(t_ref[rows])], columns=cols)

    def path_strip(
        self,
        topic: str,
        t_ref: np.ndarray,
        pos: np.ndarray,
        colour: tuple[int, int, int],
        label: str,
        finite: np.ndarray | None = None,
    ) -> None:
        """The whole trajectory as static line strips, split at NaN samples and at time gaps (> 3 sample periods).

        ``finite`` (N,) is the mask of finite rows of ``pos`` when the caller has it already.
        """
        if finite is None:
            finite = np.all(np.isfinite(pos), axis=1)
        idx = np.flatnonzero(finite)
        if len(idx) < 2:
            return
        dt = np.diff(t_ref[idx])
        typical = float(np.median(dt))
        breaks = np.flatnonzero((np.diff(idx) > 1) | (dt > 3 * typical)) + 1
        points = np.ascontiguousarray(pos[idx] if len(idx) < len(pos) else pos, dtype=np.float32)
        bounds = np.concatenate([[0], breaks, [len(idx)]])
        strips = [points[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b - a >= 2]
        if not strips:
            return
        path = L.path_entity(topic, self.prefix)
        self.trial.entities.append(Entity(path, "path", topic, 0, color=colour))
        self.rec.log(
            path,
            rr.LineStrips3D(strips, colors=[_rgb(colour)], radii=[0.002], labels=[label] if len(strips) == 1 else None),
            static=True,
        )
