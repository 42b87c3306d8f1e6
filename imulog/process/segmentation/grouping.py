"""Which movements belong to which repetition of a multi-task recording (R2G thesis 3.3.2 and imulog additions).

* :func:`split_repetitions` (thesis 3.3.2): samples whose angular-velocity norm exceeds 10 % of its maximum are
  "non-static"; the ``n - 1`` longest gaps between consecutive non-static samples separate the ``n``
  repetitions (the protocol puts a long rest between repetitions).
* :func:`group_movements` (default, more robust): the same idea on the DynAMoS movements, see its docstring.
* :func:`burst_mask` (imulog addition): the calibration wave before the first task (a burst of fast
  alternating rotations, many movements with almost no rest between them) is left out of the repetitions.

Used by :func:`~imulog.process.segmentation.repetitions.segment_repetitions`. Units: samples; intervals are
half-open sample ranges.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def split_repetitions(norm: Any, n_repetitions: int, activity_fraction: float = 0.10) -> tuple[np.ndarray, np.ndarray]:
    """Split a recording into ``n_repetitions`` tasks (thesis 3.3.2); returns ``[start, end)`` sample ranges.

    ``norm`` is the angular-velocity norm (rad/s): an array, or a store read piece by piece (``chunks()``, see
    :mod:`imulog.process.segmentation.reduce`). Each repetition runs from its first to its last non-static sample;
    the cuts are the longest gaps between non-static samples (the earliest among equal ones).
    """
    from imulog.process.segmentation.reduce import ArrayStore, store_max, threshold_runs

    store = norm if hasattr(norm, "chunks") else ArrayStore(np.asarray(norm, dtype=float))
    level = activity_fraction * store_max(store)
    rs, re = threshold_runs(iter([*store.chunks(), (len(store), np.zeros(0))]), level)
    empty = np.zeros(0, dtype=np.int64)
    if len(rs) == 0 or n_repetitions < 1:
        return empty, empty
    n_active = int((re - rs).sum())
    k = min(n_repetitions - 1, n_active - 1)
    pos_end = np.cumsum(re - rs) - 1  # position (among the active samples) of each run's last sample
    gaps = rs[1:] - (re[:-1] - 1)  # the gap after each run but the last (>= 2); inside a run every gap is 1
    inter = np.argsort(-gaps, kind="stable")[:k]
    cuts = [(int(pos_end[i]), int(re[i]), int(rs[i + 1])) for i in inter]
    taken = {int(pos_end[i]) for i in inter}
    p, j = 0, 0
    while len(cuts) < k:  # fewer gaps between runs than cuts: the earliest gaps of 1 inside the runs
        while p > pos_end[j]:
            j += 1
        if p not in taken and p != pos_end[j]:
            sample = int(rs[j] + p - (pos_end[j] - (re[j] - rs[j]) + 1))
            cuts.append((p, sample + 1, sample + 1))
        p += 1
    cuts.sort()
    starts = np.array([int(rs[0])] + [c[2] for c in cuts], dtype=np.int64)
    ends = np.array([c[1] for c in cuts] + [int(re[-1])], dtype=np.int64)
    return starts, ends


def burst_mask(
    start: np.ndarray, end: np.ndarray, rate_hz: float, gap_s: float = 0.2, min_movements: int = 5
) -> np.ndarray:
    """True for movements in a burst: a run of at least ``min_movements`` movements whose gaps are all
    shorter than ``gap_s`` (s).

    The R2G protocol (thesis 2.2.2) opens with a "wave" of fast back-and-forth rotations about each sensor
    axis; DynAMoS cuts it into many movements with (almost) no rest between them (simulator: 9-16 movements,
    gaps <= 0.02 s). A drinking repetition is four movements separated by static pauses: at most a fused
    phase split at a minimum of the norm or a phase and its corrective sub-movement follow each other that
    closely (runs of 2), so a run of ``n_phases + 1`` cannot be one repetition's phases.
    """
    start, end = np.asarray(start), np.asarray(end)
    mask = np.zeros(len(start), dtype=bool)
    if min_movements < 1 or len(start) < min_movements:
        return mask
    close = (start[1:] - end[:-1]) < gap_s * rate_hz
    i = 0
    while i < len(start):
        j = i
        while j < len(close) and close[j]:
            j += 1
        if j - i + 1 >= min_movements:
            mask[i : j + 1] = True
        i = j + 1
    return mask


def _optimal_cuts(
    gaps: np.ndarray,
    n_groups: int,
    min_size: int,
    max_size_factor: int = 4,
    soft_size: int = 0,
    short_penalty: float = 0.0,
) -> list[int] | None:
    """Cuts (after item k) splitting ``len(gaps) + 1`` items into ``n_groups`` groups of ``min_size`` to
    ``max_size_factor * min_size`` items that maximise the summed gap at the cuts (dynamic programming);
    None when impossible. A group smaller than ``soft_size`` costs ``short_penalty`` (gap units): a
    repetition with a fused phase is allowed, but only where the rests demand it."""
    m = len(gaps) + 1
    max_size = max_size_factor * max(min_size, soft_size)
    if n_groups < 1 or m < n_groups * min_size:
        return None
    neg = -np.inf
    best = np.full((n_groups + 1, m + 1), neg)
    back = np.zeros((n_groups + 1, m + 1), dtype=np.int64)
    best[0, 0] = 0.0
    gain = np.concatenate([[0.0], np.asarray(gaps, dtype=float)])  # gain[i]: cut before item i (i >= 1)
    for c in range(1, n_groups + 1):
        for j in range(c * min_size, m + 1):
            lo, hi = max(0, j - max_size), j - min_size
            if hi < lo:
                continue
            i = np.arange(lo, hi + 1)
            cand = best[c - 1, i] + np.where(i > 0, gain[i], 0.0) - np.where(j - i < soft_size, short_penalty, 0.0)
            k = int(np.argmax(cand))
            best[c, j], back[c, j] = cand[k], i[k]
    if not np.isfinite(best[n_groups, m]):
        return None
    cuts, j = [], m
    for c in range(n_groups, 0, -1):
        i = int(back[c, j])
        if i > 0:
            cuts.append(i - 1)
        j = i
    return sorted(cuts)


def group_movements(
    start: np.ndarray,
    end: np.ndarray,
    heights: np.ndarray,
    n_repetitions: int,
    n_phases: int = 4,
    major_fraction: float = 0.5,
    extra_cut_fraction: float = 0.5,
    min_size: int | None = None,
    angles: np.ndarray | None = None,
) -> np.ndarray:
    """Candidate repetition of each movement (0-based, in time order) from the longest rests.

    A movement is major when its height is at least ``major_fraction`` x the median height (so small
    adjustments inside a rest do not cut the rest in two); when the major movements cannot fill
    ``n_repetitions`` groups of ``n_phases`` (a slow subject's low phase counts as minor), every movement
    counts. With ``angles`` (rad turned by each movement, the norm integrated over it) a movement is also major
    when its angle is at least ``major_fraction`` x the median angle: a slow subject's low phase turns the wrist
    as far as the others, only slower (an adjustment in a rest turns it little), and a repetition holding two
    such phases besides a missing one must still be a group. The ``n_repetitions - 1`` borders are the gaps between consecutive major movements that
    maximise the summed rest with every repetition holding ``n_phases`` to ``4 n_phases`` major movements
    (dynamic programming); further gaps at least ``extra_cut_fraction`` x the median border gap are cut as
    well (longest first, while every group keeps ``n_phases`` major movements), so that activity which is not
    a task (e.g. a calibration wave that :func:`burst_mask` did not catch) forms groups of its own; :func:`segment_repetitions` then keeps the
    ``n_repetitions`` groups that best match the correct repetitions. Minor movements join the group whose
    span contains (or is nearest to) their mid-point.
    """
    start, end, heights = np.asarray(start), np.asarray(end), np.asarray(heights, dtype=float)
    angles = None if angles is None else np.asarray(angles, dtype=float)
    if len(start) == 0:
        return np.zeros(0, dtype=np.int64)
    size = n_phases if min_size is None else int(min_size)

    def majors(fraction: float) -> np.ndarray:
        turned = np.zeros(len(start), dtype=bool) if angles is None else angles >= fraction * np.median(angles)
        return np.flatnonzero((heights >= fraction * np.median(heights)) | turned)

    for fraction in (major_fraction, 0.0):  # a low phase (slow subject) can fall below major_fraction
        major = majors(fraction)
        gaps = start[major[1:]] - end[major[:-1]]
        if size < n_phases:  # fused partition: short groups allowed at a price of the median gap between majors
            penalty = float(np.sort(gaps)[-max(1, n_repetitions - 1) :].mean()) if len(gaps) else 0.0
            cuts = _optimal_cuts(gaps, n_repetitions, size, 4, n_phases, penalty)
        else:
            cuts = _optimal_cuts(gaps, n_repetitions, size, max(1, 4 * n_phases // size))
        if cuts is not None:
            break
    if cuts is None:  # too few movements for the constraint: plain longest gaps between major movements
        major = majors(major_fraction)
        gaps = start[major[1:]] - end[major[:-1]]
        cuts = sorted(np.argsort(-gaps, kind="stable")[: n_repetitions - 1].tolist())
    elif len(cuts) and size >= n_phases:  # (a fused partition only moves borders, it adds no groups)
        floor = extra_cut_fraction * float(np.median(gaps[cuts]))
        for k in np.argsort(-gaps, kind="stable"):  # non-task activity: more cuts at long rests
            if gaps[k] < floor:
                break
            trial = sorted({*cuts, int(k)})
            if np.diff([-1, *trial, len(major) - 1]).min() >= size:
                cuts = trial
    bounds = np.asarray(cuts, dtype=np.int64)
    rep_s = start[major[np.concatenate([[0], bounds + 1])]]
    rep_e = end[major[np.concatenate([bounds, [len(major) - 1]])]]
    return assign_to_repetitions(start, end, rep_s, rep_e)


def assign_to_repetitions(start: np.ndarray, end: np.ndarray, rep_start: np.ndarray, rep_end: np.ndarray) -> np.ndarray:
    """0-based repetition of each movement: the repetition containing (or nearest to) its mid-point."""
    mid = 0.5 * (np.asarray(start) + np.asarray(end))
    rs, re = np.asarray(rep_start, dtype=float), np.asarray(rep_end, dtype=float)
    dist = np.maximum(rs[None, :] - mid[:, None], 0) + np.maximum(mid[:, None] - re[None, :], 0)
    return np.argmin(dist, axis=1).astype(np.int64)
