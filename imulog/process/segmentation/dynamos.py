"""DynAMoS: dynamic-movement segmentation from the wrist gyroscope (Dotti et al., Sensors 2024, 24:6119).

Pipeline (all on numpy arrays, angular velocity in rad/s, sample indices as ints):

1. 4th-order zero-phase Butterworth low-pass at 1.5 Hz on each gyroscope axis, then the norm (rad/s);
2. adaptive threshold: ``0.11 x max(norm)`` (paper default) or Otsu's threshold on the norm (thesis variant);
3. onset/offset runs: maximal runs of samples above the threshold are the raw movements;
4. statistics-based iterative post-processing with ``alpha = 0.8`` and ``beta = 1.4``: the median duration
   ``M`` is recomputed after every change; a movement shorter than ``alpha*M`` is merged with the neighbour
   closest in time (the other neighbour if that fails), accepted only when the merged duration lies in
   ``[alpha*M, beta*M]``; a movement longer than ``beta*M`` is split at its local minima of the norm, lowest
   first, accepted only when both parts lie in ``[alpha*M, beta*M]``; repeated until no outlier can be processed.

Optionally (``refine_boundaries``, an imulog addition, off in the published method) each onset/offset is moved
outward along the descending flank of the filtered norm down to the static noise level, which removes the
systematic lag of a threshold at 11 % of the maximum on smooth (minimum-jerk) movements.

Intervals are half-open sample ranges ``[start, end)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.param_rules import check_rules


@dataclass(frozen=True)
class DynamosParams:
    """Parameters of :func:`dynamos` (defaults: Dotti et al. 2024).

    cutoff_hz: low-pass cut-off (Hz) of the zero-phase Butterworth filter on each gyroscope axis.
    filter_order: Butterworth order (applied forward and backward, so the effective order doubles).
    threshold: ``"otsu"`` or a fraction (0..1) of the maximum filtered norm; paper default 0.11.
    alpha: short-movement factor: a movement shorter than ``alpha * median`` is an outlier.
    beta: long-movement factor: a movement longer than ``beta * median`` is an outlier.
    min_movement_s: raw runs shorter than this (s) are dropped before post-processing (0 keeps all).
    refine_boundaries: move onsets/offsets outward along the flank of the norm (imulog addition).
    refine_level: flank level where the refined boundary stops, as a fraction between the static noise
        level (0) and the detection threshold (1).
    continuation_s: with ``refine_boundaries``, a sub-threshold corrective sub-movement that starts within this
        time (s) after a movement's offset (and before the next movement) extends that movement (0 = off).
    continuation_level: a corrective sub-movement must rise above this level, as a fraction between the
        static noise level (0) and the detection threshold (1).
    continuation_peak_fraction: ... and reach at least this fraction of the movement's peak (the zero-phase
        low-pass rings after a fast movement at about 8 % of its peak; such ringing is not a sub-movement).
    max_iterations: safety bound on post-processing changes (1,000,000: never reached in practice; a week of
        daily life needs tens of thousands, each about 0.1 ms).
    """

    cutoff_hz: float = 1.5
    filter_order: int = 4
    threshold: float | str = 0.11
    alpha: float = 0.8
    beta: float = 1.4
    min_movement_s: float = 0.0
    refine_boundaries: bool = True
    refine_level: float = 0.1
    continuation_s: float = 1.0
    continuation_level: float = 0.3
    continuation_peak_fraction: float = 0.15
    max_iterations: int = 1_000_000
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


@dataclass(frozen=True)
class Segmentation:
    """Movements as half-open sample ranges with the signal they were found on.

    start, end: (K,) int sample indices, ``[start, end)``; norm: (N,) filtered angular-velocity norm (rad/s);
    threshold_rad_s: the detection threshold applied to ``norm``.
    """

    start: np.ndarray
    end: np.ndarray
    norm: np.ndarray
    threshold_rad_s: float

    def __len__(self) -> int:
        return len(self.start)

    @property
    def durations(self) -> np.ndarray:
        """Durations in samples."""
        return self.end - self.start

    def peaks(self) -> np.ndarray:
        """Peak filtered angular-velocity norm (rad/s) of each movement."""
        return np.array([self.norm[s:e].max() if e > s else 0.0 for s, e in zip(self.start, self.end, strict=True)])


def lowpass_norm(gyr_rad_s: np.ndarray, rate_hz: float, cutoff_hz: float = 1.5, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass of each axis of ``gyr_rad_s`` (N, 3), then the Euclidean norm (rad/s)."""
    gyr = np.asarray(gyr_rad_s, dtype=float)
    if gyr.ndim == 1:
        gyr = gyr[:, None]
    gyr = np.where(np.isfinite(gyr), gyr, 0.0)
    if cutoff_hz and cutoff_hz < rate_hz / 2:
        from scipy.signal import butter, sosfiltfilt  # lazy: scipy.signal costs ~0.5 s to import

        sos = butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")
        padlen = min(3 * (2 * len(sos) + 1), len(gyr) - 1)
        if padlen > 0:
            gyr = sosfiltfilt(sos, gyr, axis=0, padlen=padlen)
    return np.linalg.norm(gyr, axis=1)


def otsu_threshold(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold: the value maximising the between-class variance of a histogram of ``values``."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if len(v) == 0 or v.max() == v.min():
        return float(v.max()) if len(v) else 0.0
    hist, edges = np.histogram(v, bins=bins)
    return otsu_from_histogram(hist, edges)


def otsu_from_histogram(hist: np.ndarray, edges: np.ndarray) -> float:
    """Otsu's threshold from a histogram (counts per bin and the bin edges): maximal between-class variance."""
    centres = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(hist).astype(float)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * centres)
    with np.errstate(divide="ignore", invalid="ignore"):
        mu0 = m0 / w0
        mu1 = (m0[-1] - m0) / w1
        between = w0 * w1 * (mu0 - mu1) ** 2
    between = np.where(np.isfinite(between), between, -1.0)
    best = np.flatnonzero(between >= between.max() * (1 - 1e-9))  # a plateau over empty bins: its middle
    return float(0.5 * (edges[best[0] + 1] + edges[best[-1] + 1]))


def threshold_value(norm: np.ndarray, threshold: float | str) -> float:
    """Detection threshold (rad/s): ``threshold x max(norm)`` or Otsu's threshold when ``threshold == "otsu"``."""
    if isinstance(threshold, str):
        if threshold.lower() != "otsu":
            raise ValueError(f"threshold must be 'otsu' or a fraction of the maximum, got {threshold!r}")
        return otsu_threshold(norm)
    if not 0 < float(threshold) < 1:
        raise ValueError(f"threshold fraction must lie in (0, 1), got {threshold}")
    return float(threshold) * float(np.nanmax(norm)) if len(norm) else 0.0


def runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Half-open ``[start, end)`` sample ranges of the True runs of a boolean mask."""
    m = np.asarray(mask, dtype=bool)
    if len(m) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    d = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1).astype(np.int64), np.flatnonzero(d == -1).astype(np.int64)


def _local_minima(x: np.ndarray) -> np.ndarray:
    """Indices of strict-left/non-strict-right interior local minima of ``x``."""
    if len(x) < 3:
        return np.zeros(0, dtype=np.int64)
    i = np.flatnonzero((x[1:-1] < x[:-2]) & (x[1:-1] <= x[2:])) + 1
    return i.astype(np.int64)


def postprocess(
    start: np.ndarray,
    end: np.ndarray,
    norm: np.ndarray,
    alpha: float = 0.8,
    beta: float = 1.4,
    max_iterations: int = 1_000_000,
    stats: dict | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """DynAMoS iterative merge/split of outlier durations (see module docstring); returns new ``start, end``.

    One change at a time, as published: with ``M`` the median duration after the previous change, the shortest
    movement (earliest among equals) that can merge with a neighbour into ``[alpha*M, beta*M]`` merges (closest
    neighbour first, the left one among equals); when none can, the longest movement that can be split at a
    local minimum of the norm (lowest first) is split. Event-driven so that a week converges in time about linear
    in the number of movements: the median is kept in a sorted list, the movements that can merge in a heap that
    only the neighbours of each change update, and everything is re-evaluated only when ``M`` changes.

    ``norm`` needs only slicing (``norm[a:b]``); ``stats`` (optional dict) receives ``changes``: the merges and
    splits made (``max_iterations`` bounds them)."""
    import heapq
    from bisect import bisect_left, insort

    s = [int(v) for v in start]
    e = [int(v) for v in end]
    ordered = sorted(b - a for a, b in zip(s, e, strict=True))  # the durations, for the median
    bounds: tuple[float, float] | None = None
    merges: list[tuple[int, int]] = []  # (duration, start) of movements that may merge under ``bounds``
    splits: list[tuple[int, int]] = []  # (-duration, start) of movements longer than the upper bound
    minima_by_depth: dict[tuple[int, int], np.ndarray] = {}

    def position(first: int, dur: int) -> int | None:
        """Where the movement starting at ``first`` with duration ``dur`` is, if it still exists unchanged."""
        i = bisect_left(s, first)
        return i if i < len(s) and s[i] == first and e[i] - first == dur else None

    def merge_partner(i: int, lo: float, hi: float) -> int | None:
        """The neighbour a short movement ``i`` merges with under ``[lo, hi]``, closest first (left on a tie)."""
        candidates = []
        if i > 0:
            candidates.append((s[i] - e[i - 1], i - 1))
        if i < len(s) - 1:
            candidates.append((s[i + 1] - e[i], i + 1))
        for _gap, j in sorted(candidates):
            if lo <= e[max(i, j)] - s[min(i, j)] <= hi:
                return j
        return None

    def push_merge(i: int, lo: float, hi: float) -> None:
        if 0 <= i < len(s) and e[i] - s[i] < lo and merge_partner(i, lo, hi) is not None:
            heapq.heappush(merges, (e[i] - s[i], s[i]))

    changes = 0
    while changes < max_iterations and len(s) >= 2:
        n = len(ordered)
        med = float(ordered[(n - 1) // 2] + ordered[n // 2]) / 2.0 if n % 2 == 0 else float(ordered[n // 2])
        lo, hi = alpha * med, beta * med
        if bounds != (lo, hi):  # the median moved: every movement is re-evaluated
            bounds = (lo, hi)
            sa, ea = np.asarray(s), np.asarray(e)
            dur = ea - sa
            ok = np.zeros(len(sa), dtype=bool)  # a neighbour to merge with in [lo, hi] (the closest is tried first)
            left, right = ea[1:] - sa[:-1], ea[1:] - sa[:-1]  # merged extent with the previous / the next one
            ok[1:] |= (lo <= left) & (left <= hi)
            ok[:-1] |= (lo <= right) & (right <= hi)
            pick = np.flatnonzero(ok & (dur < lo))
            merges = list(zip(dur[pick].tolist(), sa[pick].tolist(), strict=True))
            heapq.heapify(merges)
            long = np.flatnonzero(dur > hi)
            splits = list(zip((-dur[long]).tolist(), sa[long].tolist(), strict=True))
            heapq.heapify(splits)
        done = False
        while merges:
            dur, first = heapq.heappop(merges)
            i = position(first, dur)
            j = None if i is None else merge_partner(i, lo, hi)
            if j is None:
                continue  # changed or no longer mergeable (it is pushed again if a neighbour changes)
            a, b = min(i, j), max(i, j)
            for d in (e[a] - s[a], e[b] - s[b]):
                del ordered[bisect_left(ordered, d)]
            e[a] = e[b]
            del s[b], e[b]
            insort(ordered, e[a] - s[a])
            for k in (a - 1, a, a + 1):
                push_merge(k, lo, hi)
            done = True
            break
        while not done and splits:
            neg, first = heapq.heappop(splits)
            i = position(first, -neg)
            if i is None:
                continue
            order = minima_by_depth.get((s[i], e[i]))
            if order is None:  # the local minima of the norm, lowest first (kept: bounds change, minima do not)
                seg = norm[s[i] : e[i]]
                minima = _local_minima(seg)
                order = minima_by_depth[(s[i], e[i])] = minima[np.argsort(seg[minima], kind="stable")]
            fits = (lo <= order) & (order <= hi) & (lo <= e[i] - s[i] - order) & (e[i] - s[i] - order <= hi)
            if fits.any():
                cut = s[i] + int(order[fits][0])
                del ordered[bisect_left(ordered, e[i] - s[i])]
                insort(ordered, cut - s[i])
                insort(ordered, e[i] - cut)
                s.insert(i + 1, cut)
                e.insert(i, cut)
                for k in (i - 1, i + 2):
                    push_merge(k, lo, hi)
                done = True
        if not done:
            break
        changes += 1
    if stats is not None:
        stats["changes"] = changes
    return np.asarray(s, dtype=np.int64), np.asarray(e, dtype=np.int64)


def refine_boundaries(
    start: np.ndarray,
    end: np.ndarray,
    norm: np.ndarray,
    threshold: float,
    level: float = 0.1,
    continuation_samples: int = 0,
    continuation_level: float = 0.3,
    continuation_peak_fraction: float = 0.15,
    noise: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Move each onset back (offset forward) while the norm keeps falling and stays above a stop level.

    The stop level is ``noise + level * (threshold - noise)`` with ``noise`` the median norm below the
    threshold (rad/s; given as ``noise`` when ``norm`` is a piece of a longer recording whose median it is).
    Boundaries never cross the neighbouring movement.
    """
    if noise is None:
        below = norm[norm < threshold]
        noise = float(np.median(below)) if len(below) else 0.0
    stop = noise + level * (threshold - noise)
    s = np.array(start, dtype=np.int64)
    e = np.array(end, dtype=np.int64)
    for k in range(len(s)):
        limit = e[k - 1] if k > 0 else 0
        i = s[k]
        while i - 1 >= limit and norm[i - 1] <= norm[i] and norm[i - 1] > stop:
            i -= 1
        s[k] = i
        limit = s[k + 1] if k + 1 < len(s) else len(norm)
        j = e[k]  # exclusive; last sample j-1
        while j < limit and norm[j] <= norm[j - 1] and norm[j] > stop:
            j += 1
        if continuation_samples > 0:
            cont = noise + continuation_level * (threshold - noise)
            window = norm[j : min(j + continuation_samples, limit)]
            above = np.flatnonzero(window > cont)
            peak = float(norm[s[k] : j].max()) if j > s[k] else 0.0
            if len(above) and window.max() >= continuation_peak_fraction * peak:
                j2 = j + int(above[0])
                while j2 < limit and norm[j2] > cont:  # ride over the bump
                    j2 += 1
                while j2 < limit and norm[j2] <= norm[j2 - 1] and norm[j2] > stop:
                    j2 += 1
                if j2 < limit:  # the bump ended before the next movement
                    j = j2
        e[k] = j
    return s, e


def dynamos(gyr_rad_s: np.ndarray, rate_hz: float, params: DynamosParams = DynamosParams()) -> Segmentation:
    """Segment dynamic movements from a gyroscope signal (N, 3) rad/s sampled at ``rate_hz``."""
    norm = lowpass_norm(gyr_rad_s, rate_hz, params.cutoff_hz, params.filter_order)
    return dynamos_from_norm(norm, rate_hz, params)


def dynamos_from_norm(norm: np.ndarray, rate_hz: float, params: DynamosParams = DynamosParams()) -> Segmentation:
    """DynAMoS steps 2-4 on an already filtered angular-velocity norm (rad/s)."""
    norm = np.asarray(norm, dtype=float)
    thr = threshold_value(norm, params.threshold)
    start, end = runs(norm > thr)
    if params.min_movement_s > 0:
        keep = (end - start) >= params.min_movement_s * rate_hz
        start, end = start[keep], end[keep]
    start, end = postprocess(start, end, norm, params.alpha, params.beta, params.max_iterations)
    if params.refine_boundaries:
        start, end = refine_boundaries(
            start,
            end,
            norm,
            thr,
            params.refine_level,
            int(round(params.continuation_s * rate_hz)),
            params.continuation_level,
            params.continuation_peak_fraction,
        )
    return Segmentation(start=start, end=end, norm=norm, threshold_rad_s=thr)
