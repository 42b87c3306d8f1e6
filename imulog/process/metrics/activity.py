"""Activity counts from a 3-axis accelerometer: both methods of Doshi 2011, thesis section 4.2.4.

Method 1 (sign changes about the mean, Appendix A.1)::

    s_j[i] = +1 if a_j[i] > mean(a_j) else -1
    count_j = #{i >= 1 : s_j[i] != s_j[i-1]}          count = #{i : any axis changes sign at i}

Each sign change starts a new activity, which lasts until the next change (so the method returns ``count``
intervals). Doshi shows that it overestimates the count because noise about the mean flips the sign.

Method 2 (moving average subtracted, noise floor, dead periods; Appendix A.2)::

    ma_j[i] = (sum_{k=-m..m} a_j[i+k] + (wt-1) a_j[i]) / (2m + wt)   for m <= i < N-m;  ma_j[i] = a_j[i] elsewhere
    h_j[i]  = a_j[i] - ma_j[i];  h_j[i] = 0 where |h_j[i]| <= noise_floor      (noise removal)
    h_n[i]  = sqrt(h_x^2 + h_y^2 + h_z^2)                                      (the "4th" channel)

On each channel an activity starts at a non-zero sample and a *dead period* of at least ``dead`` consecutive
zero samples ends it (Doshi: "consecutive samples with value 0 exceed or equal to ``dead``"). The overall count
and the activity intervals are those of ``h_n``. Published values: ``m = 5``, ``dead = 9..10`` samples at 10 Hz
(section 4.2.4; ``dead = 10`` gave 7 of 8 ball throws, 9 gave 8, 8 gave 9), noise floor 0.09 g ("observed
static sensor noise" in Appendix A.2; the text asks for the peak amplitude of the measurement noise). Appendix
A.3 scales ``m`` with the sample rate (``m = m_in * f_sample``), so :meth:`ActivityCountParams.for_rate`
converts the published 0.5 s / 1.0 s to samples at any rate.

Deviation from Appendix A.2: its zero counter is not reset by non-zero samples (so zeros inside an activity
accumulate towards a dead period) and its interval end is hard-coded as ``i - 9``; imulog implements the rule as
written in the text (consecutive zeros) and ends an interval after its last non-zero sample. A final activity
that runs to the end of the recording is counted (as in A.2) and also reported as an interval.

Reference: R. Doshi, M.S. thesis, Colorado State University, 2011, section 4.2.4, Appendices A.1-A.2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DOSHI_RATE_HZ = 10.0  # sample rate of the WiTilt recordings in Doshi 2011 (Appendix A.1 prints N / 10 seconds)


@dataclass(frozen=True)
class ActivityCountParams:
    """Parameters of activity-count method 2 (Doshi 2011 section 4.2.4).

    m_samples: half width of the centred moving average (window 2m+1 samples); published 5 at 10 Hz.
    dead_samples: consecutive zero samples that end an activity; published 10 (9 for the ball-throw trial) at 10 Hz.
    noise_floor_g: |high-passed acceleration| at or below this is noise and forced to 0, in g; published 0.09 g.
    centre_weight: ``wt`` of Appendix A.2 (extra weight of the centre sample); published 1 (a plain average).
    min_activity_samples: activities shorter than this are dropped (imulog addition, default 1 = keep all, as
        published). Doshi (section 5.3) notes that involuntary jerks and noise are short while activities last
        longer; a noise floor measured on a short static recording lets rare single-sample noise peaks through.
    """

    m_samples: int = 5
    dead_samples: int = 10
    noise_floor_g: float = 0.09
    centre_weight: float = 1.0
    min_activity_samples: int = 1

    def __post_init__(self) -> None:
        if self.m_samples < 1:
            raise ValueError(f"m_samples must be >= 1, got {self.m_samples}")
        if self.dead_samples < 1:
            raise ValueError(f"dead_samples must be >= 1, got {self.dead_samples}")
        if not np.isfinite(self.noise_floor_g) or self.noise_floor_g < 0:
            raise ValueError(f"noise_floor_g must be finite and >= 0, got {self.noise_floor_g}")
        if self.centre_weight <= 0:
            raise ValueError(f"centre_weight must be > 0, got {self.centre_weight}")
        if self.min_activity_samples < 1:
            raise ValueError(f"min_activity_samples must be >= 1, got {self.min_activity_samples}")

    @classmethod
    def for_rate(
        cls,
        rate_hz: float,
        *,
        m_s: float = 0.5,
        dead_s: float = 1.0,
        noise_floor_g: float = 0.09,
        min_activity_s: float = 0.0,
    ) -> ActivityCountParams:
        """Parameters for a sample rate, from durations: published 0.5 s (m = 5) and 1.0 s (dead = 10) at 10 Hz."""
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        return cls(
            m_samples=max(1, round(m_s * rate_hz)),
            dead_samples=max(1, round(dead_s * rate_hz)),
            noise_floor_g=noise_floor_g,
            min_activity_samples=max(1, round(min_activity_s * rate_hz)),
        )


@dataclass(frozen=True)
class ActivityCount:
    """Counts and intervals of one method.

    per_axis: (3,) int activity count of x, y, z.
    count: overall count (method 1: samples where any axis changes sign; method 2: the norm channel).
    intervals: (K, 2) int sample indices ``[start, end)`` of the overall activities (K == count).
    per_axis_intervals: three (K_j, 2) arrays, one per axis.
    """

    per_axis: np.ndarray
    count: int
    intervals: np.ndarray
    per_axis_intervals: tuple[np.ndarray, ...]

    def durations_s(self, rate_hz: float) -> np.ndarray:
        """Duration of each overall activity in seconds (``(end - start) / rate_hz``)."""
        return (self.intervals[:, 1] - self.intervals[:, 0]) / float(rate_hz)


def _as_acc(acc_g: np.ndarray) -> np.ndarray:
    a = np.asarray(acc_g, dtype=np.float64)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] < 2:
        raise ValueError(f"acceleration must be (N, C) with N >= 2, got shape {np.shape(acc_g)}")
    return a


def _change_intervals(change: np.ndarray, n: int) -> np.ndarray:
    starts = np.flatnonzero(change)
    ends = np.append(starts[1:], n)
    return np.stack([starts, ends], axis=1).astype(np.int64) if len(starts) else np.zeros((0, 2), np.int64)


def activity_count_sign(acc_g: np.ndarray) -> ActivityCount:
    """Method 1: count sign changes of each axis about its mean (see the module docstring)."""
    a = _as_acc(acc_g)
    n = a.shape[0]
    sign = np.where(a > np.nanmean(a, axis=0), 1, -1)
    change = np.zeros(a.shape, dtype=bool)
    change[1:] = sign[1:] != sign[:-1]
    per_axis_intervals = tuple(_change_intervals(change[:, j], n) for j in range(a.shape[1]))
    any_change = change.any(axis=1)
    return ActivityCount(
        per_axis=change.sum(axis=0).astype(np.int64),
        count=int(any_change.sum()),
        intervals=_change_intervals(any_change, n),
        per_axis_intervals=per_axis_intervals,
    )


def centred_moving_average(x: np.ndarray, m: int, centre_weight: float = 1.0) -> np.ndarray:
    """Centred moving average over 2m+1 samples along axis 0; the first and last m samples are copied.

    ``(sum_{k=-m..m} x[i+k] + (centre_weight - 1) x[i]) / (2m + centre_weight)`` (Doshi 2011 Appendix A.2).
    """
    x = np.asarray(x, dtype=np.float64)
    out = x.copy()
    n = x.shape[0]
    if n <= 2 * m:
        return out
    c = np.cumsum(np.concatenate([np.zeros((1, *x.shape[1:])), x], axis=0), axis=0)
    window_sum = c[2 * m + 1 :] - c[: n - 2 * m]  # sum of x[i-m .. i+m] for i = m .. n-m-1
    centre = x[m : n - m]
    out[m : n - m] = (window_sum + (centre_weight - 1.0) * centre) / (2 * m + centre_weight)
    return out


def high_passed_noise_removed(acc_g: np.ndarray, params: ActivityCountParams | None = None) -> np.ndarray:
    """(N, C+1) signal of method 2: per-axis ``a - moving average`` with the noise floor zeroed, then their norm."""
    p = params or ActivityCountParams()
    a = _as_acc(acc_g)
    h = a - centred_moving_average(a, p.m_samples, p.centre_weight)
    h[~np.isfinite(h) | (np.abs(h) <= p.noise_floor_g)] = 0.0
    return np.column_stack([h, np.sqrt((h * h).sum(axis=1))])


def estimate_noise_floor(static_acc_g: np.ndarray, params: ActivityCountParams | None = None) -> float:
    """Peak |a - moving average| (g) of a recording at rest: the noise floor of method 2.

    Doshi 2011 section 4.2.4 removes noise "by threshold filtering high frequency contents using the peak
    amplitude of noise"; this measures that peak on a static recording with the same ``m`` (largest over axes;
    ``noise_floor_g`` of ``params`` is ignored). Longer static recordings give larger, safer peaks.
    """
    p = params or ActivityCountParams()
    a = _as_acc(static_acc_g)
    a = a[np.isfinite(a).all(axis=1)]
    if a.shape[0] <= 2 * p.m_samples:
        raise ValueError(f"static recording needs more than 2*m = {2 * p.m_samples} finite samples")
    h = a - centred_moving_average(a, p.m_samples, p.centre_weight)
    return float(np.abs(h).max())


def dead_period_intervals(signal: np.ndarray, dead_samples: int, min_samples: int = 1) -> np.ndarray:
    """``[start, end)`` sample intervals of non-zero activity separated by >= ``dead_samples`` zeros.

    An interval starts at a non-zero sample and ends after the last non-zero sample before a run of at least
    ``dead_samples`` zeros (or the end of the signal). Intervals shorter than ``min_samples`` are dropped.
    """
    idx = np.flatnonzero(np.asarray(signal) != 0)
    if len(idx) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    zeros_between = np.diff(idx) - 1
    split = np.flatnonzero(zeros_between >= dead_samples)
    starts = np.concatenate([[idx[0]], idx[split + 1]])
    ends = np.concatenate([idx[split], [idx[-1]]]) + 1
    keep = (ends - starts) >= min_samples
    return np.stack([starts[keep], ends[keep]], axis=1).astype(np.int64)


def activity_count_dead_period(acc_g: np.ndarray, params: ActivityCountParams | None = None) -> ActivityCount:
    """Method 2: moving average subtracted, noise floor, dead periods (see the module docstring)."""
    p = params or ActivityCountParams()
    h = high_passed_noise_removed(acc_g, p)
    k, n_min = p.dead_samples, p.min_activity_samples
    per_axis_intervals = tuple(dead_period_intervals(h[:, j], k, n_min) for j in range(h.shape[1] - 1))
    overall = dead_period_intervals(h[:, -1], k, n_min)
    return ActivityCount(
        per_axis=np.array([len(iv) for iv in per_axis_intervals], dtype=np.int64),
        count=len(overall),
        intervals=overall,
        per_axis_intervals=per_axis_intervals,
    )
