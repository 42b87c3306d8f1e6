"""Daily-life summaries: arm use, activity counts and the distance histogram per hour and per day.

Home recordings (Doshi 2011 ch. 5: arm use during daily life; wrist sensors sent home record for a week) are read
as trends, not as one number for the whole file. :func:`period_summaries` cuts the per-sample results of the
whole-recording metrics into periods aligned to the wall clock (whole hours, local midnights when the trial's
start time is known) and summarises each period with the same definitions:

* ``arm_use_percent``: % of the period's valid samples counted as arm use (:func:`imulog.process.metrics.arm_usage`);
* ``activity_count``: activities (Doshi method 2) that *start* in the period;
* ``distance_weighted_area``: the weighted area (Doshi 2011 section 5.3) of the histogram of the period's
  per-sample windowed distance, with the whole recording's bins;
* ``valid_s``: seconds of valid (finite) samples, so a period the sensor was off or not worn is visible as such.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta

import numpy as np

from imulog.process.metrics.distance import weighted_area

HOUR_S = 3600.0
DAY_S = 86400.0


@dataclass(frozen=True)
class PeriodSummary:
    """One period: its start (ns on the device clock and, when known, ISO wall-clock time) and its metrics."""

    start_ns: int
    start: str
    valid_s: float
    arm_use_percent: float
    activity_count: int
    distance_weighted_area: float

    def to_dict(self) -> dict[str, float | int | str]:
        return {
            "start": self.start,
            "start_ns": int(self.start_ns),
            "valid_s": round(float(self.valid_s), 3),
            "arm_use_percent": round(float(self.arm_use_percent), 3) if np.isfinite(self.arm_use_percent) else None,
            "activity_count": int(self.activity_count),
            "distance_weighted_area": round(float(self.distance_weighted_area), 3),
        }


def wall_clock_origin_ns(t0_ns: int, start_time: str | None, period_s: float) -> tuple[int, datetime | None]:
    """Device-clock time of the wall-clock period boundary at or before the first sample ``t0_ns``.

    ``start_time`` (ISO 8601, the trial's ``imulog.trial.start_time``; local time when it carries an offset) is
    the wall-clock time of ``t0_ns``. Without it, periods start at the first sample.
    """
    if not start_time:
        return int(t0_ns), None
    try:
        start = datetime.fromisoformat(str(start_time))
    except ValueError:
        return int(t0_ns), None
    midnight = start.replace(hour=0, minute=0, second=0, microsecond=0)
    since = (start - midnight).total_seconds()
    back_s = since % period_s
    return int(t0_ns - round(back_s * 1e9)), start - timedelta(seconds=back_s)


class PeriodAccumulator:
    """Per-period sums (valid and arm-use samples, activity starts, distance-bin counts), added piece by piece.

    Periods of ``period_s`` start at ``origin_ns`` (device clock; :func:`wall_clock_origin_ns`), labelled from
    ``origin_time`` when known. ``bin_centres_cm``: the distance histogram's (uniform) bins.
    """

    def __init__(
        self, origin_ns: int, origin_time: datetime | None, period_s: float, bin_centres_cm: np.ndarray
    ) -> None:
        self.origin_ns, self.origin_time, self.period_s = int(origin_ns), origin_time, period_s
        self.period_ns = int(round(period_s * 1e9))
        self.centres = np.asarray(bin_centres_cm, np.float64)
        self.bin_width = float(self.centres[1] - self.centres[0]) if len(self.centres) > 1 else 1.0
        self.valid: dict[int, int] = {}
        self.active: dict[int, int] = {}
        self.starts: dict[int, int] = {}
        self.hist: dict[int, np.ndarray] = {}
        self.dt_s: float | None = None

    def _period(self, t_ns: np.ndarray) -> np.ndarray:
        return (np.asarray(t_ns, np.int64) - self.origin_ns) // self.period_ns

    def add(self, t_ns: np.ndarray, valid: np.ndarray, active: np.ndarray, distance_cm: np.ndarray) -> None:
        """Samples ``t_ns`` (sorted), their validity, arm use and windowed distance (cm, NaN = unknown)."""
        t = np.asarray(t_ns, np.int64)
        if self.dt_s is None and len(t) > 1:
            self.dt_s = float(np.median(np.diff(t))) / 1e9
        which = self._period(t)
        valid = np.asarray(valid, bool)
        d = np.asarray(distance_cm, np.float64)
        bins = len(self.centres)
        for k in np.unique(which).tolist():
            v = (which == k) & valid
            self.valid[k] = self.valid.get(k, 0) + int(v.sum())
            self.active[k] = self.active.get(k, 0) + int((v & np.asarray(active, bool)).sum())
            counts = self.hist.setdefault(k, np.zeros(bins))
            dk = d[v & np.isfinite(d)]
            if len(dk) and bins:
                idx = np.clip(np.floor((dk - self.centres[0]) / self.bin_width + 0.5).astype(np.int64), 0, bins - 1)
                counts += np.bincount(idx, minlength=bins)

    def add_activity_starts(self, starts_ns: np.ndarray) -> None:
        """Times at which activities start (each counted in its period)."""
        for k in self._period(starts_ns).tolist():
            self.starts[k] = self.starts.get(k, 0) + 1

    def rows(self, weight_start_cm: float = 60.0) -> list[PeriodSummary]:
        """One summary per period from the first to the last with samples (empty ones between included)."""
        out = []
        for k in range(max(self.valid, default=-1) + 1):
            n = self.valid.get(k, 0)
            counts = self.hist.get(k)
            area = 0.0
            if counts is not None and counts.sum():
                area = weighted_area(100.0 * counts / counts.sum(), self.centres, weight_start_cm)
            label = (
                ""
                if self.origin_time is None
                else (self.origin_time + timedelta(seconds=k * self.period_s)).isoformat()
            )
            out.append(
                PeriodSummary(
                    start_ns=self.origin_ns + k * self.period_ns,
                    start=label,
                    valid_s=n * (self.dt_s or 0.0),
                    arm_use_percent=100.0 * self.active.get(k, 0) / n if n else float("nan"),
                    activity_count=self.starts.get(k, 0),
                    distance_weighted_area=float(area),
                )
            )
        return out


def period_summaries(
    t_ns: np.ndarray,
    valid: np.ndarray,
    active: np.ndarray,
    activity_starts: np.ndarray,
    distance_cm: np.ndarray,
    bin_centres_cm: np.ndarray,
    *,
    period_s: float,
    origin_ns: int,
    origin_time: datetime | None = None,
    weight_start_cm: float = 60.0,
) -> list[PeriodSummary]:
    """Summaries of consecutive periods of ``period_s`` starting at ``origin_ns`` (device clock).

    ``t_ns`` (N,) sample times; ``valid`` (N,) bool; ``active`` (N,) bool arm use; ``activity_starts`` (K,) sample
    indices where activities start; ``distance_cm`` (N,) windowed distance; ``bin_centres_cm`` (B,) the histogram
    bins of the whole recording (uniform). The long-recording path adds the same sums piece by piece
    (:class:`PeriodAccumulator`).
    """
    t = np.asarray(t_ns, np.int64)
    if len(t) == 0:
        return []
    periods = PeriodAccumulator(origin_ns, origin_time, period_s, bin_centres_cm)
    periods.add(t, valid, active, distance_cm)
    periods.add_activity_starts(t[np.asarray(activity_starts, np.int64)])
    return periods.rows(weight_start_cm)
