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

from imulog.process.segmentation.dynamos import refine_boundaries


def half_width(norm, lo: int, hi: int, peak_at: int) -> int:
    """Samples of the contiguous run around ``peak_at`` where the norm in ``[lo, hi)`` stands above half its
    height over the stretch's floor (10th percentile): a bump's width at half its own height, whatever that
    height (a run above one fixed level is short for a bump that barely clears it)."""
    seg = np.asarray(norm[lo:hi], dtype=float)
    k = int(peak_at) - lo
    floor = float(np.percentile(seg, 10))
    above = seg > floor + 0.5 * (seg[k] - floor)
    a, b = k, k + 1
    while a > 0 and above[a - 1]:
        a -= 1
    while b < len(seg) and above[b]:
        b += 1
    return b - a


def _movement_half_width(norm, start: np.ndarray, end: np.ndarray, k: int) -> int:
    """:func:`half_width` of movement ``k``, over it and as much again on each side (up to its neighbours)."""
    a, b = int(start[k]), int(end[k])
    lo = max(a - (b - a), int(end[k - 1]) if k > 0 else 0)
    hi = min(b + (b - a), int(start[k + 1]) if k + 1 < len(start) else len(norm))
    return half_width(norm, lo, hi, a + int(np.argmax(np.asarray(norm[a:b]))))


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
    # as wide as the real movements, each measured at half its own height (DynAMoS's own short-movement bound,
    # alpha x the median): a slow phase that barely clears the level has a short run above it (issue 31:
    # 1.8 s above the level against 2.1 s for the real phases, 6 s wide at its base)
    widths = [_movement_half_width(norm, ts, te, k) for k in range(len(ts)) if te[k] > ts[k]]
    min_len = alpha * float(np.median(widths))
    new_s, new_e = [], []
    for k in range(len(start) - 1):
        lo, hi = int(end[k]), int(start[k + 1])
        if hi - lo < min_len + 2:
            continue
        above = np.asarray(norm[lo:hi]) > level
        d = np.diff(np.r_[0, above.astype(np.int8), 0])
        for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
            if a == 0 or b >= hi - lo:  # touches a neighbour: its flank or tail
                continue
            peak = lo + int(a) + int(np.argmax(np.asarray(norm[lo + a : lo + b])))
            if half_width(norm, lo, hi, peak) >= min_len:  # inside the rest, as wide as a phase
                # down its flanks as DynAMoS's movements are (refine_boundaries: while the norm keeps falling,
                # to 10 % of the way from the rest's floor to the level): a slow bump is seconds wider than
                # its run above the level, more than the later refinements may move a boundary
                seg = np.asarray(norm[lo:hi], dtype=float)
                floor = float(np.percentile(seg, 10))
                ra, rb = refine_boundaries(np.array([a]), np.array([b]), seg, level, 0.1, noise=floor)
                new_s.append(lo + int(ra[0]))
                new_e.append(lo + int(rb[0]))
    if not new_s:
        return start, end
    s = np.concatenate([start, new_s])
    e = np.concatenate([end, new_e])
    order = np.argsort(s, kind="stable")
    return s[order], e[order]


def bump_in_rest(norm, lo: int, hi: int, min_len: int = 2) -> tuple[int, int, float] | None:
    """The highest bump of the norm inside the rest ``[lo, hi)`` between two movements, or None.

    For a repetition short of a phase (event correction, :func:`~imulog.process.segmentation.repetitions._split_to`):
    a phase whose wrist barely turns (a hesitant return that mostly translates) can stay under the rescue's level
    and DynAMoS's. The neighbours' flanks are walked off first (the norm falls monotonically from their offset /
    rises to their onset); in what is left the rest's floor is the 10th percentile and its noise the standard
    deviation of the quieter half. A bump whose peak ``P`` stands more than 5 noise deviations above the floor
    gives the run above ``floor + (P - floor) / 2`` around its peak, which must lie inside the interior and last
    at least ``min_len`` samples; it is then widened down its flanks like DynAMoS's movements
    (:func:`~imulog.process.segmentation.dynamos.refine_boundaries`). Returns ``(start, end, P)`` (samples,
    rad/s)."""
    seg = np.asarray(norm[lo:hi], dtype=float)
    if len(seg) < 3:
        return None
    i, j = 0, len(seg) - 1
    while i < j and seg[i + 1] <= seg[i]:  # the previous movement's descending flank
        i += 1
    while j > i and seg[j - 1] <= seg[j]:  # the next movement's rising flank
        j -= 1
    inner = seg[i : j + 1]
    if len(inner) < max(3, min_len):
        return None
    floor = float(np.percentile(inner, 10))
    quiet = inner[inner <= np.median(inner)]
    noise = float(np.std(quiet)) if len(quiet) > 1 else 0.0
    k = int(np.argmax(inner))
    peak = float(inner[k])
    if peak - floor <= 5 * noise or peak <= floor:
        return None
    above = inner > floor + 0.5 * (peak - floor)
    a = k
    while a > 0 and above[a - 1]:
        a -= 1
    b = k + 1
    while b < len(inner) and above[b]:
        b += 1
    if a == 0 or b == len(inner) or b - a < min_len:  # touches a neighbour's flank: not a bump of its own
        return None
    # down its flanks as DynAMoS's movements are (to 10 % of the way from the floor to half the height), so that
    # its duration compares with theirs
    ra, rb = refine_boundaries(np.array([a]), np.array([b]), inner, floor + 0.5 * (peak - floor), 0.1, noise=floor)
    return lo + i + int(ra[0]), lo + i + int(rb[0]), peak
