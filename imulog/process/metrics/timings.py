"""Movement timings from labelled intervals: per-phase durations (R2G) and peg times (NHPT).

Inputs are :class:`imulog.model.Intervals` (or any object with ``start_ns``, ``end_ns``, ``labels``,
``task_index`` arrays), e.g. ``/derived/phases/{imu}`` written by the segmentation step or the simulator's
ground-truth phases. Times are int64 ns on one clock; durations are returned in seconds.

* R2G (reach-to-grasp drinking task): each repetition ``task_index = 1..25`` has the phases ``reach``, ``lift``,
  ``return_bottle``, ``return_hand``. ``duration = (end_ns - start_ns) / 1e9``; a repetition's duration runs from
  its first phase's start to its last phase's end. Phase durations are what a therapist compares between
  visits (slower, more variable reaches early after stroke).
* NHPT (nine-hole peg test, Bai et al. 2023): the hand pauses (zero velocity) when it picks up a peg and when it
  inserts it; the double-threshold detector of Bai et al. times the movements between these pauses. With the
  movements labelled as the simulator's ``nhpt`` protocol does (``to_container`` ends at a pick-up, ``place``
  carries the peg and ends at its insertion, then ``to_hole`` / ``remove`` take the pegs out, ``return_hand``),
  imulog reports for peg ``k`` the pick-up time (end of ``to_container``) and the placement time (end of
  ``place``), in s from the test start, the transport time ``placement_k - pickup_k`` and the return time
  ``pickup_{k+1} - placement_k``; the test time runs from the first movement's start to the end of the last
  movement of the test (``return_hand`` excluded).

Reference: Bai L. et al., "Upper limb position tracking with a single inertial sensor using dead reckoning
method with drift correction techniques", Sensors 23(1):360, 2023 (sections 3.1 and 4.1: automatic timing of
individual peg pick-up and placement).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

NS_PER_S = 1e9
R2G_PHASES = ("reach", "lift", "return_bottle", "return_hand")


class IntervalsLike(Protocol):
    start_ns: np.ndarray
    end_ns: np.ndarray
    labels: list[str]
    task_index: np.ndarray | None


@dataclass(frozen=True)
class PhaseTable:
    """One row per interval, sorted by start: task_index, label, start_ns, duration_s."""

    task_index: np.ndarray
    labels: np.ndarray
    start_ns: np.ndarray
    duration_s: np.ndarray

    def durations(self, label: str) -> np.ndarray:
        """Durations (s) of every interval with ``label``, in time order."""
        return self.duration_s[self.labels == label]

    def by_key(self) -> dict[tuple[int, str], float]:
        """``{(task_index, label): duration_s}``; a repeated key keeps the sum of its durations."""
        out: dict[tuple[int, str], float] = {}
        for ti, lab, d in zip(self.task_index.tolist(), self.labels.tolist(), self.duration_s.tolist(), strict=True):
            out[(ti, lab)] = out.get((ti, lab), 0.0) + d
        return out


def phase_table(intervals: IntervalsLike) -> PhaseTable:
    """Durations (s) of labelled intervals, sorted by start time."""
    start = np.asarray(intervals.start_ns, dtype=np.int64)
    end = np.asarray(intervals.end_ns, dtype=np.int64)
    labels = np.asarray(list(intervals.labels), dtype=object)
    ti = intervals.task_index
    task = np.full(len(start), -1, np.int64) if ti is None else np.asarray(ti, dtype=np.int64)
    if not (len(start) == len(end) == len(labels) == len(task)):
        raise ValueError("intervals: start, end, labels and task_index differ in length")
    if np.any(end < start):
        raise ValueError("intervals: an interval ends before it starts")
    order = np.argsort(start, kind="stable")
    return PhaseTable(
        task_index=task[order],
        labels=labels[order],
        start_ns=start[order],
        duration_s=(end[order] - start[order]) / NS_PER_S,
    )


def phase_summary(intervals: IntervalsLike, labels: tuple[str, ...] | None = None) -> dict[str, dict[str, float]]:
    """Per label: n, mean_s, std_s (population), median_s, min_s, max_s, cv (std / mean)."""
    table = phase_table(intervals)
    wanted = labels if labels is not None else tuple(dict.fromkeys(table.labels.tolist()))
    out: dict[str, dict[str, float]] = {}
    for label in wanted:
        d = table.durations(label)
        if len(d) == 0:
            continue
        mean = float(d.mean())
        out[label] = {
            "n": int(len(d)),
            "mean_s": mean,
            "std_s": float(d.std()),
            "median_s": float(np.median(d)),
            "min_s": float(d.min()),
            "max_s": float(d.max()),
            "cv": float(d.std() / mean) if mean > 0 else float("nan"),
        }
    return out


def repetition_durations(intervals: IntervalsLike) -> dict[int, float]:
    """``{task_index: s}`` from the first start to the last end of each repetition (task_index >= 0)."""
    start = np.asarray(intervals.start_ns, dtype=np.int64)
    end = np.asarray(intervals.end_ns, dtype=np.int64)
    task = np.asarray(intervals.task_index, dtype=np.int64)
    out: dict[int, float] = {}
    for ti in np.unique(task[task >= 0]).tolist():
        sel = task == ti
        out[int(ti)] = float((end[sel].max() - start[sel].min()) / NS_PER_S)
    return out


@dataclass(frozen=True)
class DurationComparison:
    """Estimated vs reference durations paired by (task_index, label)."""

    keys: list[tuple[int, str]]
    estimated_s: np.ndarray
    reference_s: np.ndarray
    missing: list[tuple[int, str]]  # in the reference, not estimated
    extra: list[tuple[int, str]]  # estimated, not in the reference

    @property
    def error_s(self) -> np.ndarray:
        return self.estimated_s - self.reference_s

    @property
    def max_abs_error_s(self) -> float:
        return float(np.max(np.abs(self.error_s))) if len(self.keys) else float("nan")


def compare_durations(estimated: IntervalsLike, reference: IntervalsLike) -> DurationComparison:
    """Pair the phases of two segmentations by (task_index, label) and return both durations (s)."""
    est = phase_table(estimated).by_key()
    ref = phase_table(reference).by_key()
    keys = [k for k in ref if k in est]
    return DurationComparison(
        keys=keys,
        estimated_s=np.array([est[k] for k in keys]),
        reference_s=np.array([ref[k] for k in keys]),
        missing=[k for k in ref if k not in est],
        extra=[k for k in est if k not in ref],
    )


@dataclass(frozen=True)
class NhptParams:
    """Movement labels of the NHPT intervals (those of ``imulog.simulate`` protocol ``nhpt``).

    pickup_movement: the movement that ends at a peg pick-up (hand reaches the container): ``to_container``.
    place_movement: the movement that carries a peg and ends at its insertion into a hole: ``place``.
    outside_test: labels not counted in the test time (the hand's return to rest after the last peg).
    """

    pickup_movement: str = "to_container"
    place_movement: str = "place"
    outside_test: tuple[str, ...] = ("return_hand",)


@dataclass(frozen=True)
class NhptTimings:
    """Per peg k (in time order): pick-up and placement times (s from test start), transport and return (s).

    pickup_s: end of the k-th pick-up movement (start of the zero-velocity pause at the container).
    place_s: end of the following placement movement (the peg is in its hole).
    transport_s: place_s - pickup_s (grasp pause plus transport); place_movement_s: the transport alone.
    return_s: pickup_s[k+1] - place_s[k] (insertion pause plus the way back to the container).
    test_time_s: first movement start to the end of the last movement of the test.
    """

    pickup_s: np.ndarray
    place_s: np.ndarray
    transport_s: np.ndarray
    place_movement_s: np.ndarray
    return_s: np.ndarray
    test_time_s: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "n_pegs": int(len(self.place_s)),
            "test_time_s": self.test_time_s,
            "pickup_s": self.pickup_s.tolist(),
            "place_s": self.place_s.tolist(),
            "transport_s": self.transport_s.tolist(),
            "place_movement_s": self.place_movement_s.tolist(),
            "return_s": self.return_s.tolist(),
            "transport_mean_s": float(np.mean(self.transport_s)) if len(self.transport_s) else float("nan"),
        }


def nhpt_timings(intervals: IntervalsLike, params: NhptParams | None = None) -> NhptTimings:
    """Peg pick-up and placement times from NHPT movement intervals (Bai et al. 2023); see the module docstring.

    Each pick-up is paired with the first placement movement that starts after it ends (and before the next
    pick-up ends).
    """
    p = params or NhptParams()
    start = np.asarray(intervals.start_ns, dtype=np.int64)
    end = np.asarray(intervals.end_ns, dtype=np.int64)
    labels = np.asarray(list(intervals.labels), dtype=object)
    if len(start) == 0:
        raise ValueError("no intervals")
    in_test = ~np.isin(labels, list(p.outside_test))
    if not in_test.any():
        raise ValueError("no intervals inside the test")
    t0 = int(start[in_test].min())
    t_end = int(end[in_test].max())
    is_pick = labels == p.pickup_movement
    is_place = labels == p.place_movement
    if not is_pick.any() or not is_place.any():
        raise ValueError(f"need intervals labelled {p.pickup_movement!r} and {p.place_movement!r}")
    pick_end = np.sort(end[is_pick])
    order = np.argsort(start[is_place])
    place_start, place_end = start[is_place][order], end[is_place][order]
    picks, places, moves = [], [], []
    for k, tp in enumerate(pick_end):
        nxt = pick_end[k + 1] if k + 1 < len(pick_end) else np.iinfo(np.int64).max
        j = np.flatnonzero((place_start >= tp) & (place_start < nxt))
        if len(j):
            picks.append(tp)
            places.append(place_end[j[0]])
            moves.append(place_end[j[0]] - place_start[j[0]])
    pick_a = (np.array(picks, dtype=np.int64) - t0) / NS_PER_S
    place_a = (np.array(places, dtype=np.int64) - t0) / NS_PER_S
    return NhptTimings(
        pickup_s=pick_a,
        place_s=place_a,
        transport_s=place_a - pick_a,
        place_movement_s=np.array(moves, dtype=np.int64) / NS_PER_S,
        return_s=pick_a[1:] - place_a[:-1],
        test_time_s=(t_end - t0) / NS_PER_S,
    )
