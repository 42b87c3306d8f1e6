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
    bins of the whole recording (uniform).
    """
    t = np.asarray(t_ns, np.int64)
    if len(t) == 0:
        return []
    period_ns = int(round(period_s * 1e9))
    which = (t - origin_ns) // period_ns
    n_periods = int(which[-1]) + 1
    valid = np.asarray(valid, bool)
    dt_s = float(np.median(np.diff(t))) / 1e9 if len(t) > 1 else 0.0
    n_valid = np.bincount(which[valid], minlength=n_periods)
    n_active = np.bincount(which[valid & np.asarray(active, bool)], minlength=n_periods)
    starts = np.asarray(activity_starts, np.int64)
    n_activity = np.bincount(which[starts], minlength=n_periods) if len(starts) else np.zeros(n_periods, np.int64)

    centres = np.asarray(bin_centres_cm, np.float64)
    width = float(centres[1] - centres[0]) if len(centres) > 1 else 1.0
    edges = np.concatenate([centres - width / 2, [centres[-1] + width / 2]]) if len(centres) else np.zeros(0)
    d = np.asarray(distance_cm, np.float64)
    ok = valid & np.isfinite(d)
    out: list[PeriodSummary] = []
    for k in range(n_periods):
        inside = (which == k) & ok
        area = 0.0
        if len(edges) and inside.any():
            hist, _ = np.histogram(np.clip(d[inside], edges[0], edges[-1]), bins=edges)
            area = weighted_area(100.0 * hist / inside.sum(), centres, weight_start_cm)
        label = "" if origin_time is None else (origin_time + timedelta(seconds=k * period_s)).isoformat()
        out.append(
            PeriodSummary(
                start_ns=int(origin_ns + k * period_ns),
                start=label,
                valid_s=float(n_valid[k]) * dt_s,
                arm_use_percent=100.0 * n_active[k] / n_valid[k] if n_valid[k] else float("nan"),
                activity_count=int(n_activity[k]),
                distance_weighted_area=float(area),
            )
        )
    return out
