"""Small numpy helpers shared by the converters, the archive and the steps (pure, no I/O)."""

from __future__ import annotations

import numpy as np


def finite_rows(a: np.ndarray) -> np.ndarray:
    """True where every value along the last axis of ``a`` is finite: shape ``a.shape[:-1]``.

    Equals ``np.isfinite(a).all(axis=-1)``; for a short last axis (x, y, z) it tests one component at a time,
    which is several times faster than numpy's strided reduction over an axis of length 3.
    """
    a = np.asarray(a)
    width = a.shape[-1]
    if width == 0 or width > 8:
        return np.isfinite(a).all(axis=-1)
    out = np.isfinite(a[..., 0])
    for k in range(1, width):
        out &= np.isfinite(a[..., k])
    return out


def median_int(a: np.ndarray) -> float:
    """``float(np.median(a))`` of an integer array (e.g. time steps in ns), exactly; by counting values instead
    of sorting when they span a range at most 4x the array's length (a sampling clock's steps; an AX6 block clock's
    hour of 100 Hz steps: 1.1 ms instead of 2.4), else numpy's partition. NaN for an empty array, as numpy."""
    a = np.asarray(a)
    n = len(a)
    if a.ndim != 1 or a.dtype.kind not in "iu" or n < 64:
        return float(np.median(a))
    lo, hi = int(a.min()), int(a.max())
    if hi - lo >= min(4 * n, 1 << 22):  # counting would cost more than sorting (or too much memory)
        return float(np.median(a))
    cum = np.cumsum(np.bincount((a - lo).astype(np.intp, copy=False), minlength=hi - lo + 1))
    return lo + _middle(cum)


def moving_mean(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving mean along the first axis over ``w`` samples (at least 1), shrinking at the ends: sample i
    averages ``x[i - w // 2 : i - w // 2 + w]`` clipped to the array. Same shape as ``x`` (1-D or (N, D))."""
    x = np.asarray(x, dtype=np.float64)
    n, w = len(x), max(1, int(w))
    c = np.concatenate([np.zeros((1, *x.shape[1:])), np.cumsum(x, axis=0)])
    lo = np.clip(np.arange(n) - w // 2, 0, n)
    hi = np.clip(np.arange(n) - w // 2 + w, 0, n)
    count = np.maximum(hi - lo, 1).reshape(-1, *([1] * (x.ndim - 1)))
    return (c[hi] - c[lo]) / count


def step_rate_hz(steps_ns: np.ndarray) -> float | None:
    """Sampling rate (Hz) from sample intervals (ns): the mean of the intervals within 0.5-1.5x their median, so a
    gap or a dropped sample does not count and a clock that jitters around its rate (Axivity block times at
    12.5 Hz: 79, 81 and 82 ms steps) gives that rate, not its most frequent step. None without two such steps."""
    dt = np.asarray(steps_ns, dtype=np.float64)
    dt = dt[dt > 0]
    if len(dt) < 2:
        return None
    med = float(np.median(dt))
    steady = dt[(dt >= 0.5 * med) & (dt <= 1.5 * med)]
    return 1e9 / float(steady.mean())


def add_counts(counts: dict[int, int], values: np.ndarray) -> None:
    """Add integer ``values`` to ``counts`` (value -> how many times it occurred), e.g. sample steps piece by piece."""
    keys, n = np.unique(np.asarray(values, dtype=np.int64), return_counts=True)
    for k, c in zip(keys.tolist(), n.tolist(), strict=True):
        counts[k] = counts.get(k, 0) + c


def median_of_counts(counts: dict[int, int]) -> float | None:
    """``np.median`` of the integers that ``counts`` (value -> occurrences) describes, exactly (None when empty)."""
    if sum(counts.values()) == 0:
        return None
    keys = sorted(counts)
    lo = keys[0]
    return lo + _middle(np.cumsum([counts[k] for k in keys]), np.asarray(keys, dtype=np.int64) - lo)


def _middle(cum: np.ndarray, offsets: np.ndarray | None = None) -> float:
    """The median's offset from the smallest value, given the cumulative counts ``cum`` of the sorted distinct
    values at ``offsets`` from it (default: every integer from 0): the mean of the middle value(s)."""
    below, above = np.searchsorted(cum, [(int(cum[-1]) - 1) // 2, int(cum[-1]) // 2], side="right")
    if offsets is not None:
        below, above = offsets[below], offsets[above]
    return (float(below) + float(above)) / 2.0
