"""Whole-recording quantities of the segmentation reduced from pieces (a window at a time), exactly.

The phases step (:mod:`imulog.steps.phases_windows`) reads a recording in bounded windows; what DynAMoS and the
boundary refinements take from the whole recording is reduced here from per-window summaries: the runs above the
threshold joined across windows (:func:`threshold_runs`), Otsu's threshold from a histogram of the norm with exact
counts (:func:`otsu_from_chunks`), the exact median of the norm below the threshold (:func:`exact_median_below`,
narrowing histograms), the gyroscope's and accelerometer's white noise (:class:`NoiseHistogram`), and the phase
summaries of the timing record (:func:`duration_summary`, :func:`period_rows`). Pure numpy; a "store" is any object
with ``chunks()`` yielding ``(first index, values)`` and contiguous slicing (an array in memory, or a file).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np


class ArrayStore:
    """A norm held in memory with the store interface of a norm file: slicing and ``chunks()``."""

    def __init__(self, values: np.ndarray) -> None:
        self.array = np.asarray(values, dtype=float)

    def __len__(self) -> int:
        return len(self.array)

    def __getitem__(self, key: slice) -> np.ndarray:
        return self.array[key]

    def chunks(self, size: int = 1 << 20) -> Iterator[tuple[int, np.ndarray]]:
        for a in range(0, len(self.array), size):
            yield a, self.array[a : a + size]


def store_max(store: Any) -> float:
    """Maximum of a store (0 when empty), as ``np.nanmax`` of the whole."""
    return max((float(np.nanmax(x)) for _, x in store.chunks() if len(x)), default=0.0)


def otsu_from_chunks(chunks: Callable[[], Iterator[tuple[int, np.ndarray]]], bins: int = 256) -> float:
    """:func:`~imulog.process.segmentation.dynamos.otsu_threshold` of the values of ``chunks()`` (called twice:
    their range, then a histogram with exact counts on the same edges ``np.histogram`` uses on the whole)."""
    from imulog.process.segmentation.dynamos import otsu_from_histogram

    lo, hi, n = np.inf, -np.inf, 0
    for _, x in chunks():
        x = x[np.isfinite(x)]
        if len(x):
            lo, hi, n = min(lo, float(x.min())), max(hi, float(x.max())), n + len(x)
    if n == 0 or lo == hi:
        return float(hi) if n else 0.0
    hist = np.zeros(bins, dtype=np.int64)
    for _, x in chunks():
        hist += np.histogram(x[np.isfinite(x)], bins=bins, range=(lo, hi))[0]
    return otsu_from_histogram(hist, np.histogram_bin_edges([lo, hi], bins=bins, range=(lo, hi)))


DURATION_BINS_S = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 20.0, 60.0)


class NoiseHistogram:
    """Per-axis histograms of second differences, for :func:`~imulog.process.segmentation.boundaries.
    white_noise_rad_s` of a whole recording added piece by piece (units of the signal).

    Each bin keeps its count and the sum of its values, so a bin holding one distinct value (a quantised sensor:
    bins are far narrower than its resolution) gives that value back: the medians are then exact (to rounding);
    otherwise they are within a bin width (``2 half_range / bins``)."""

    def __init__(self, half_range: float, bins: int = 200_000) -> None:
        self.half = float(half_range)
        self.bins = int(bins)
        self.width = 2 * self.half / self.bins
        self.counts = np.zeros((3, self.bins + 2), dtype=np.int64)  # [below, bins..., above]
        self.sums = np.zeros((3, self.bins + 2))

    def add(self, d2: np.ndarray) -> None:
        """Second differences ``x[i+1] - 2 x[i] + x[i-1]`` (M, 3)."""
        for j in range(3):
            k = np.clip(np.floor((d2[:, j] + self.half) / self.width).astype(np.int64) + 1, 0, self.bins + 1)
            self.counts[j] += np.bincount(k, minlength=self.bins + 2)
            self.sums[j] += np.bincount(k, weights=d2[:, j], minlength=self.bins + 2)

    @staticmethod
    def _median(values: np.ndarray, counts: np.ndarray) -> float:
        """``np.median`` of ``values`` repeated ``counts`` times."""
        keep = counts > 0
        order = np.argsort(values[keep], kind="stable")
        v, w = values[keep][order], counts[keep][order]
        n = int(w.sum())
        if n == 0:
            return 0.0
        cum = np.cumsum(w)
        lo = v[np.searchsorted(cum, (n - 1) // 2 + 1)]
        hi = v[np.searchsorted(cum, n // 2 + 1)]
        return float(0.5 * (lo + hi))

    def white_noise(self) -> float:
        """Per-sample white noise, rms over the axes of 1.4826 x MAD / sqrt 6 (as ``white_noise_rad_s``)."""
        mads = []
        for j in range(3):
            counts = self.counts[j]
            values = self.sums[j] / np.maximum(counts, 1)
            med = self._median(values, counts)
            mads.append(1.4826 * self._median(np.abs(values - med), counts) / np.sqrt(6.0))
        return float(np.sqrt(np.mean(np.square(mads))))

    def cutoff_hz(self, rate_hz: float, params: Any) -> float:
        """:func:`~imulog.process.segmentation.boundaries.adaptive_cutoff_hz` with this recording's noise."""
        if params.target_level_rad_s <= 0 or not params.cutoff_hz:
            return params.cutoff_hz
        noise = self.white_noise()
        if noise <= 0:
            return params.cutoff_hz
        f = (params.target_level_rad_s / (params.n_sigma * noise)) ** 2 * rate_hz / 2
        return float(np.clip(f, params.min_cutoff_hz, params.cutoff_hz))


def second_differences(x: np.ndarray, k0: int, k1: int, first: bool, last: bool) -> np.ndarray:
    """Second differences centred on samples ``k0..k1-1`` of ``x`` (N, 3), leaving out the recording's first and
    last sample (``first``/``last``: ``k0``/``k1 - 1`` is that sample)."""
    a = k0 + (1 if first else 0)
    b = k1 - (1 if last else 0)
    a, b = max(a, 1), min(b, len(x) - 1)
    if b <= a:
        return np.zeros((0, x.shape[1]))
    return x[a + 1 : b + 1] - 2 * x[a:b] + x[a - 1 : b - 1]


def threshold_runs(chunks: Iterator[tuple[int, np.ndarray]], threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Half-open runs where consecutive chunks ``(first index, values)`` exceed ``threshold``, joined across chunks."""
    from imulog.process.segmentation.dynamos import runs

    starts: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    open_start: int | None = None
    for off, x in chunks:
        s, e = runs(x > threshold)
        s, e = s + off, e + off
        if open_start is not None:
            if len(s) and s[0] == off:
                s[0] = open_start
            else:
                starts.append(np.array([open_start]))
                ends.append(np.array([off]))
            open_start = None
        if len(e) and e[-1] == off + len(x):
            open_start = int(s[-1])
            s, e = s[:-1], e[:-1]
        starts.append(s)
        ends.append(e)
    if open_start is not None:
        raise RuntimeError("threshold_runs: the last chunk must close its run (call with a final empty chunk)")
    if not starts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(starts).astype(np.int64), np.concatenate(ends).astype(np.int64)


def in_range(values: np.ndarray, lo: int, hi: int) -> slice:
    """Slice of the sorted ``values`` that lie in ``[lo, hi)``."""
    return slice(int(np.searchsorted(values, lo)), int(np.searchsorted(values, hi)))


def duration_summary(durations_s: np.ndarray) -> dict[str, Any]:
    """Median, deciles, longest and total (s) of phase durations, and their histogram (bin edges in s)."""
    d = np.asarray(durations_s, dtype=float)
    edges = [*DURATION_BINS_S, float("inf")]
    counts = np.histogram(d, bins=np.asarray(edges))[0] if len(d) else np.zeros(len(edges) - 1, np.int64)
    out: dict[str, Any] = {"n": int(len(d)), "total_s": round(float(d.sum()), 3)}
    if len(d):
        p10, p50, p90 = np.percentile(d, [10, 50, 90])
        out.update(median_s=round(float(p50), 4), p10_s=round(float(p10), 4), p90_s=round(float(p90), 4))
        out["max_s"] = round(float(d.max()), 4)
    out["histogram"] = {"bin_edges_s": [*DURATION_BINS_S, None], "counts": [int(c) for c in counts]}
    return out


def exact_median_below(norm: Any, threshold: float, bins: int = 4096, max_values: int = 200_000) -> float:
    """``np.median(norm[norm < threshold])`` over the file, exactly, in memory bounded by ``max_values``.

    Each pass histograms the values in the current range ``[lo, hi)`` and narrows it to the bins holding the two
    middle ranks, until at most ``max_values`` values remain (or they are all equal: the zeros of a long gap);
    those are sorted."""
    n, lo = 0, np.inf
    for _, x in norm.chunks():
        x = x[x < threshold]
        n += len(x)
        if len(x):
            lo = min(lo, float(x.min()))
    if n == 0:
        return 0.0
    ranks = ((n - 1) // 2, n // 2)
    hi = float(threshold)
    for _ in range(16):
        width = (hi - lo) / bins
        counts = np.zeros(bins, dtype=np.int64)
        below, vmin, vmax = 0, np.inf, -np.inf
        for _, x in norm.chunks():
            x = x[x < threshold]
            below += int(np.count_nonzero(x < lo))
            y = x[(x >= lo) & (x < hi)]
            if len(y):
                vmin, vmax = min(vmin, float(y.min())), max(vmax, float(y.max()))
                k = np.clip(((y - lo) / width).astype(np.int64), 0, bins - 1) if width > 0 else np.zeros(len(y), int)
                counts += np.bincount(k, minlength=bins)
        if vmin == vmax:  # every value left is the same (both middle ranks are in the range)
            return vmin
        if counts.sum() <= max_values or width <= 0:
            break
        cum = below + np.cumsum(counts)
        b1, b2 = (int(np.searchsorted(cum, r + 1)) for r in ranks)
        new_lo, new_hi = lo + b1 * width, min(hi, lo + (b2 + 1) * width)
        if (new_lo, new_hi) == (lo, hi):
            break
        lo, hi = new_lo, new_hi
    picked = []
    for _, x in norm.chunks():
        x = x[x < threshold]
        picked.append(x[(x >= lo) & (x < hi)])
    values = np.sort(np.concatenate(picked))
    return float(0.5 * (values[ranks[0] - below] + values[ranks[1] - below]))


def period_rows(
    phase_start_ns: np.ndarray,
    durations_s: np.ndarray,
    known: np.ndarray,
    static: np.ndarray,
    origin_ns: int,
    origin_time: Any,
    period_s: float,
    rate_hz: float,
    first_ns: int,
) -> list[dict[str, Any]]:
    """Per period: start (wall clock when known), phases starting in it, their time (s), static percentage of the
    recorded samples and the recorded time (s). ``known``/``static``: sample counts per period."""
    from datetime import timedelta

    period_ns = int(round(period_s * 1e9))
    n = len(known)
    k = ((np.asarray(phase_start_ns, np.int64) - origin_ns) // period_ns).astype(np.int64)
    k = np.clip(k, 0, max(n - 1, 0))
    counts = np.bincount(k, minlength=n)[:n]
    moving = np.bincount(k, weights=durations_s, minlength=n)[:n] if len(k) else np.zeros(n)
    rows = []
    for i in range(n):
        if known[i] == 0:
            continue
        label = "" if origin_time is None else (origin_time + timedelta(seconds=i * period_s)).isoformat()
        rows.append(
            {
                "start": label,
                "start_s": round((origin_ns + i * period_ns - first_ns) * 1e-9, 3),
                "phases": int(counts[i]),
                "moving_s": round(float(moving[i]), 3),
                "static_percent": round(100.0 * float(static[i]) / float(known[i]), 3),
                "recorded_s": round(float(known[i]) / rate_hz, 3),
            }
        )
    return rows
