"""XDF clock synchronisation as pyxdf 1.17 does it (BSD-2-Clause, xdf-modules/pyxdf), applied piece by piece.

pyxdf's ``load_xdf(synchronize_clocks=True, handle_clock_resets=True, dejitter_timestamps=False)`` maps a stream's
time stamps onto the recording host's clock: it drops a last clock offset that the pylsl#67 bug corrupted (with the
samples past the footer's count), cuts the ClockOffset measurements into segments at host clock resets, fits a
robust line (Huber loss, ADMM) to each segment and adds ``intercept + slope x t`` to the stamps of the samples
that segment covers. Everything here needs only the clock offsets (a few per minute), so the fit is done before the
first sample is read, and :class:`StreamClock` maps the stamps piece by piece with exactly pyxdf's arithmetic: a
stamp belongs to a segment until the first stamp closer to the next segment's first offset than to the current
segment's last one.
"""

from __future__ import annotations

import numpy as np

WINSOR_THRESHOLD = 0.0001
RESET_TIME_STDS, RESET_TIME_S, RESET_OFFSET_STDS, RESET_OFFSET_S = 5, 5, 10, 1


def _segment_clock_diff(diff: np.ndarray, thresh_stds: float, thresh_secs: float) -> np.ndarray:
    median = np.median(diff)
    diffs_shift = diff - median
    diffs_shift_abs = np.abs(diffs_shift)
    mad = np.median(diffs_shift_abs) + np.finfo(float).eps
    diffs_std = diffs_shift / mad
    return (np.abs(diffs_std) > thresh_stds) & (diffs_shift_abs > thresh_secs)


def reset_ranges(clock_times: list[float], clock_values: list[float]) -> list[tuple[int, int]]:
    """Inclusive index ranges of the clock offsets between host clock resets (pyxdf ``_detect_clock_resets``)."""
    if len(clock_times) <= 1:
        return [(0, len(clock_times) - 1)]
    time_diff = np.diff(clock_times)
    value_diff = np.diff(clock_values)
    decreasing = time_diff < 0
    time_glitch = _segment_clock_diff(time_diff, RESET_TIME_STDS, RESET_TIME_S)
    value_glitch = _segment_clock_diff(value_diff, RESET_OFFSET_STDS, RESET_OFFSET_S)
    breaks = np.where(decreasing | time_glitch & value_glitch)[0]
    starts = np.hstack(([0], breaks + 1))
    ends = np.hstack((breaks, len(time_diff)))
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def robust_fit(a: np.ndarray, y: np.ndarray, rho: float = 1, iters: int = 1000) -> np.ndarray:
    """Huber-loss linear regression by ADMM (pyxdf ``_robust_fit``, after Boyd's ADMM codes)."""
    a = np.copy(a)
    offset = np.min(a[:, 1])
    a[:, 1] -= offset
    aty = np.dot(a.T, y)
    lower = np.linalg.cholesky(np.dot(a.T, a))
    upper = lower.T
    z = np.zeros_like(y)
    u = z
    x = z
    for _ in range(iters):
        x = np.linalg.solve(upper, (np.linalg.solve(lower, aty + np.dot(a.T, z - u))))
        d = np.dot(a, x) - y + u
        d_inv = np.zeros_like(d)
        np.divide(1, d, out=d_inv, where=d != 0)
        tmp = np.maximum(0, (1 - (1 + 1 / rho) * np.abs(d_inv)))
        z = rho / (1 + rho) * d + 1 / (1 + rho) * tmp * d
        u = d - z
    x[0] -= x[1] * offset
    return x


def corrupted_last_offset(clock_times: list[float], clock_values: list[float]) -> bool:
    """pyxdf ``_detect_corrupted_clock_offset``: the last offset is anomalous in time or value (pylsl#67)."""
    times, values = np.asarray(clock_times), np.asarray(clock_values)
    if len(times) < 3:
        return False
    intervals = np.diff(times)
    median_interval = np.median(intervals[:-1])
    last_interval = np.abs(intervals[-1])
    growth = np.inf if last_interval > 0 else 1.0
    time_ratio = last_interval / median_interval if median_interval > 0 else growth
    median_val = np.median(values[:-1])
    mad = np.median(np.abs(values[:-1] - median_val))
    value_z = np.abs(values[-1] - median_val) / (1.4826 * mad) if mad > np.finfo(float).eps else 0.0
    return bool(time_ratio > 10.0 or value_z > 10.0)


class StreamClock:
    """One stream's clock segments and their lines; :meth:`map` turns raw stamps (s) into synchronised ones, piece
    by piece in sample order, and counts the segments that received samples (pyxdf's ``clock_segments``)."""

    def __init__(self, clock_times: list[float], clock_values: list[float]) -> None:
        self.times, self.values = list(clock_times), list(clock_values)
        self.ranges = reset_ranges(self.times, self.values) if self.times else []
        self.coef: list[tuple[float, float]] = []
        self.failed: list[tuple[int, int]] = []  # segments whose line cannot be fitted (pyxdf warns, uses 0, 0)
        for lo, hi in self.ranges:
            if lo == hi:
                self.coef.append((self.values[lo], 0))
                continue
            x = np.column_stack([np.ones(hi + 1 - lo), np.array(self.times[lo : hi + 1]) / WINSOR_THRESHOLD])
            y = np.array(self.values[lo : hi + 1]) / WINSOR_THRESHOLD
            try:
                c = robust_fit(x, y)
                c[0] *= WINSOR_THRESHOLD
            except np.linalg.LinAlgError:
                self.failed.append((lo, hi))
                c = [0, 0]
            self.coef.append((c[0], c[1]))
        self.segment = 0  # the segment the next stamp is tested against
        self.used: list[int] = []  # segments that received samples

    def map(self, stamps: np.ndarray) -> np.ndarray:
        """The synchronised stamps of the next samples (a new array; raw when the stream has no clock offsets)."""
        t = np.array(stamps, dtype=np.float64)
        if not self.ranges or not len(t):
            return t
        if len(self.ranges) == 1:
            c0, c1 = self.coef[0]
            t += c0 + (c1 * t)
            self._use(0)
            return t
        start = 0
        while start < len(t):
            r = self.segment
            lo, hi = self.ranges[r]
            if hi + 1 < len(self.times):
                end_t, next_t = self.times[hi], self.times[hi + 1]
                cond = np.less(np.abs(t[start:] - end_t), np.abs(t[start:] - next_t))
                stop = len(t) if cond.all() else start + int(np.argmin(cond))
            else:
                stop = len(t)
            if stop > start:
                c0, c1 = self.coef[r]
                t[start:stop] += c0 + c1 * t[start:stop]
                self._use(r)
            if stop < len(t):
                self.segment += 1
            start = stop
        return t

    def _use(self, r: int) -> None:
        if not self.used or self.used[-1] != r:
            self.used.append(r)
