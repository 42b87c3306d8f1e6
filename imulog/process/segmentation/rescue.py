"""Phases the movement detector missed: a slow rotation below DynAMoS's threshold (an imulog addition, issue 31).

DynAMoS's threshold is 11 % of the trial's largest filtered angular-velocity norm, which the calibration wave
or one fast return sets (3-4 rad/s); a slow, stroke-like lift that turns the wrist at 0.4 rad/s then stays
below it although it is four times the lowest phase the detector did find. A missing phase leaves a rest of two
pauses and a movement (13-16 s against 8 s between repetitions), which the repetition grouping takes for a
border, so every later phase of the trial can slip by one repetition.

:func:`rescue_missed` looks into every rest between two movements for a run of the norm above
``fraction`` x the lowest height among the movements at least half the median height (the subject's slowest
real phase, not a fidget), not touching either neighbour (that is a neighbour's flank or tail) and lasting at
least ``alpha`` x the median movement duration (DynAMoS's own short-movement bound): such a run is a movement.
Event correction then keeps or drops it like any other. Intervals are half-open sample ranges.
"""

from __future__ import annotations

import numpy as np


def rescue_missed(
    start: np.ndarray,
    end: np.ndarray,
    norm,
    fraction: float = 0.5,
    alpha: float = 0.8,
    task: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Movements ``[start, end)`` (time order) with the runs found in the rests between them added.

    ``norm``: the filtered angular-velocity norm (rad/s), an array or a store that supports slicing
    (``norm[a:b]``); ``task`` (boolean per movement, default all): the movements whose heights and durations
    define the level and the length (not a calibration wave's); ``fraction`` 0 returns the movements
    unchanged."""
    start, end = np.asarray(start, dtype=np.int64), np.asarray(end, dtype=np.int64)
    task = np.ones(len(start), dtype=bool) if task is None else np.asarray(task, dtype=bool)
    if fraction <= 0 or task.sum() < 3:
        return start, end
    ts, te = start[task], end[task]
    heights = np.array([float(np.max(norm[a:b])) if b > a else 0.0 for a, b in zip(ts, te, strict=True)])
    real = heights[heights >= 0.5 * np.median(heights)]
    level = fraction * float(real.min())
    # as long as the real movements are above the same level (DynAMoS's own short-movement bound, alpha x the
    # median, measured where the rescue measures: a slow phase's run above half the lowest height is shorter
    # than its movement at DynAMoS's threshold)
    above_level = [int(np.count_nonzero(np.asarray(norm[a:b]) > level)) for a, b in zip(ts, te, strict=True)]
    min_len = alpha * float(np.median(above_level))
    new_s, new_e = [], []
    for k in range(len(start) - 1):
        lo, hi = int(end[k]), int(start[k + 1])
        if hi - lo < min_len + 2:
            continue
        above = np.asarray(norm[lo:hi]) > level
        d = np.diff(np.r_[0, above.astype(np.int8), 0])
        for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
            if a > 0 and b < hi - lo and b - a >= min_len:  # inside the rest, long enough to be a phase
                new_s.append(lo + int(a))
                new_e.append(lo + int(b))
    if not new_s:
        return start, end
    s = np.concatenate([start, new_s])
    e = np.concatenate([end, new_e])
    order = np.argsort(s, kind="stable")
    return s[order], e[order]
