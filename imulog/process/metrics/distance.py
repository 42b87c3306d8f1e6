"""Histogram of distance traversed in fixed windows and its linearly weighted area (Doshi 2011, chapter 5).

Algorithm (Appendix A.3, per axis j, sample period dt, window of W = window_s * rate samples)::

    h_j      = a_j - centred moving average of a_j over 2m+1 samples          (as in activity method 2)
    at every window start:  v_j = 0, s_j = 0
    inside a window (k >= 1):
        v_j[k] = v_j[k-1] + sign(a_j[k] - a_j[k-1]) * dt * h_j[k]      (sign = -1 when a_j does not increase)
        s_j[k] = s_j[k-1] + dt * v_j[k-1]
    d[k]     = 100 * sqrt(s_x^2 + s_y^2 + s_z^2)                            ["cm", see ``acc_unit``]

The rectification by the sign of the signal's slope makes ``s`` grow with the amount of movement rather than the
net displacement (which is bounded during repetitive tasks, section 5.2). The normalised histogram counts every
sample's ``d`` in 1 cm bins centred on 1, 2, ..., ``max_distance_cm`` (MATLAB ``hist``: values beyond the end
bins fall into them) and divides by the number of samples, in %. The **linearly weighted area** (section 5.3,
Appendix A.3) ignores distances up to ``weight_start_cm`` (published 60 cm = 0.5 * 120 cm) and weights the bin
centred on ``c`` by ``c - weight_start_cm``::

    area = sum_{c > start} (c - start) * hist_percent(c)              [% * cm]

Published defaults: window 5 s (section 5.2.1, 1 s is noise-dominated, 10 s saturates), bins up to 120 cm
(section 5.3: subjects rarely exceed 120 cm in 5 s), start of weighting 60 cm, moving-average half width
``m = m_in * f_sample`` with the section 4.2.4 value 0.5 s (m = 5 at 10 Hz).

Units: Appendix A.3 integrates the high-passed signal in g while labelling the result metres (the conversion to
m/s^2 is applied to an unused variable), so its "cm" are 1/9.80665 of SI centimetres. ``acc_unit="g"`` (default)
reproduces the published numbers and bin ranges; ``acc_unit="m/s^2"`` integrates in SI units (then adapt
``max_distance_cm`` and ``weight_start_cm``).

Multi-day comparison (section 5.2.2, the 8-day use case): single-day histograms are noisy; average consecutive
days (:func:`average_consecutive`, 2-day and 4-day averages in the thesis) and compare their weighted areas.

Reference: R. Doshi, M.S. thesis, Colorado State University, 2011, chapter 5 and Appendix A.3.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from imulog.process.metrics.activity import centred_moving_average
from imulog.process.metrics.arm_usage import STANDARD_GRAVITY


@dataclass(frozen=True)
class DistanceHistogramParams:
    """Parameters of the histogram of distance traversed (Doshi 2011 chapter 5, Appendix A.3).

    window_s: window width in s; published 5 s.
    m_s: half width of the moving average in s (m = m_s * rate samples); published 0.5 s (m = 5 at 10 Hz).
    bin_width_cm: histogram bin width in cm; published 1 cm.
    max_distance_cm: centre of the last bin in cm; published 120 cm.
    weight_start_cm: distance with weight 0 in the weighted area, in cm; published 60 cm (0.5 * max).
    acc_unit: unit the high-passed acceleration is integrated in: "g" reproduces Appendix A.3, "m/s^2" is SI.
    """

    window_s: float = 5.0
    m_s: float = 0.5
    bin_width_cm: float = 1.0
    max_distance_cm: float = 120.0
    weight_start_cm: float = 60.0
    acc_unit: Literal["g", "m/s^2"] = "g"

    def __post_init__(self) -> None:
        if not self.window_s > 0:
            raise ValueError(f"window_s must be > 0, got {self.window_s}")
        if not self.m_s > 0:
            raise ValueError(f"m_s must be > 0, got {self.m_s}")
        if not self.bin_width_cm > 0 or not self.max_distance_cm >= self.bin_width_cm:
            raise ValueError("need bin_width_cm > 0 and max_distance_cm >= bin_width_cm")
        if not 0 <= self.weight_start_cm < self.max_distance_cm:
            raise ValueError("weight_start_cm must lie in [0, max_distance_cm)")
        if self.acc_unit not in ("g", "m/s^2"):
            raise ValueError(f"acc_unit must be 'g' or 'm/s^2', got {self.acc_unit!r}")

    @property
    def bin_centres_cm(self) -> np.ndarray:
        n = int(round(self.max_distance_cm / self.bin_width_cm))
        return self.bin_width_cm * np.arange(1, n + 1, dtype=np.float64)


@dataclass(frozen=True)
class DistanceHistogram:
    """Result of :func:`distance_histogram`.

    distance_cm: (N,) distance accumulated since the start of each sample's window.
    window_distance_cm: (W,) distance at the last sample of each window (distance traversed in the window).
    bin_centres_cm: (B,) bin centres; histogram_percent: (B,) % of all samples in each bin.
    weighted_area: linearly weighted area under the histogram (% * cm).
    """

    distance_cm: np.ndarray
    window_distance_cm: np.ndarray
    bin_centres_cm: np.ndarray
    histogram_percent: np.ndarray
    weighted_area: float


def windowed_distance(acc_g: np.ndarray, rate_hz: float, params: DistanceHistogramParams | None = None) -> np.ndarray:
    """(N, C) per-axis rectified double integral, restarted at every window (Appendix A.3); unit m, see module."""
    p = params or DistanceHistogramParams()
    a = np.asarray(acc_g, dtype=np.float64)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] < 2:
        raise ValueError(f"acceleration must be (N, C) with N >= 2, got shape {np.shape(acc_g)}")
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
    a = np.where(np.isfinite(a), a, np.nan)
    a = _fill_nan(a)
    dt = 1.0 / rate_hz
    m = max(1, int(round(p.m_s * rate_hz)))
    h = a - centred_moving_average(a, m)
    if p.acc_unit == "m/s^2":
        h = h * STANDARD_GRAVITY
    n = a.shape[0]
    win = max(1, int(round(p.window_s * rate_hz)))
    sign = np.ones_like(a)
    sign[1:] = np.where(a[1:] > a[:-1], 1.0, -1.0)
    dv = sign * dt * h
    window_start = (np.arange(n) % win) == 0
    dv[window_start] = 0.0
    vel = _segmented_cumsum(dv, window_start)
    ds = np.zeros_like(vel)
    ds[1:] = dt * vel[:-1]
    ds[window_start] = 0.0
    return _segmented_cumsum(ds, window_start)


def _fill_nan(a: np.ndarray) -> np.ndarray:
    """Hold the last finite value over gaps (leading gaps take the first finite value); all-NaN columns -> 0."""
    out = a.copy()
    for j in range(a.shape[1]):
        col = out[:, j]
        ok = np.isfinite(col)
        if ok.all():
            continue
        if not ok.any():
            col[:] = 0.0
            continue
        idx = np.where(ok, np.arange(len(col)), 0)
        np.maximum.accumulate(idx, out=idx)
        first = np.flatnonzero(ok)[0]
        idx[:first] = first
        out[:, j] = col[idx]
    return out


def _segmented_cumsum(x: np.ndarray, segment_start: np.ndarray) -> np.ndarray:
    """Cumulative sum along axis 0 that restarts at each True of ``segment_start``."""
    c = np.cumsum(x, axis=0)
    starts = np.flatnonzero(segment_start)
    # value of the running sum just before each segment start, repeated over the segment
    before = np.zeros_like(c[: len(starts)])
    nonzero = starts > 0
    before[nonzero] = c[starts[nonzero] - 1]
    seg_id = np.cumsum(segment_start) - 1
    return c - before[seg_id]


def histogram_percent(distance_cm: np.ndarray, params: DistanceHistogramParams | None = None) -> np.ndarray:
    """% of samples per bin (centres ``params.bin_centres_cm``); out-of-range values go to the end bins."""
    p = params or DistanceHistogramParams()
    d = np.asarray(distance_cm, dtype=np.float64).ravel()
    d = d[np.isfinite(d)]
    centres = p.bin_centres_cm
    if len(d) == 0:
        return np.zeros_like(centres)
    idx = np.clip(np.floor(d / p.bin_width_cm + 0.5).astype(np.int64) - 1, 0, len(centres) - 1)
    return 100.0 * np.bincount(idx, minlength=len(centres)).astype(np.float64) / len(d)


def weighted_area(hist_percent: np.ndarray, bin_centres_cm: np.ndarray, start_cm: float = 60.0) -> float:
    """Linearly weighted area ``sum_{c > start} (c - start) * hist(c)`` (Doshi 2011 section 5.3), % * cm."""
    h = np.asarray(hist_percent, dtype=np.float64)
    c = np.asarray(bin_centres_cm, dtype=np.float64)
    if h.shape != c.shape:
        raise ValueError(f"histogram {h.shape} and bin centres {c.shape} differ in shape")
    above = c > start_cm
    return float(np.sum((c[above] - start_cm) * h[above]))


def distance_histogram(
    acc_g: np.ndarray, rate_hz: float, params: DistanceHistogramParams | None = None
) -> DistanceHistogram:
    """Histogram of distance traversed in windows and its weighted area for an (N, 3) acceleration in g."""
    p = params or DistanceHistogramParams()
    s = windowed_distance(acc_g, rate_hz, p)
    d_cm = 100.0 * np.sqrt((s * s).sum(axis=1))
    win = max(1, int(round(p.window_s * rate_hz)))
    last = np.append(np.arange(win - 1, len(d_cm), win), len(d_cm) - 1)
    last = np.unique(last)
    hist = histogram_percent(d_cm, p)
    centres = p.bin_centres_cm
    return DistanceHistogram(
        distance_cm=d_cm,
        window_distance_cm=d_cm[last],
        bin_centres_cm=centres,
        histogram_percent=hist,
        weighted_area=weighted_area(hist, centres, p.weight_start_cm),
    )


def average_consecutive(histograms: np.ndarray, group_size: int) -> np.ndarray:
    """Average consecutive rows (days) in groups of ``group_size`` (Doshi 2011 section 5.2.2: 2- and 4-day).

    ``histograms`` is (D, B), one normalised histogram per day in day order; returns (ceil(D / group_size), B),
    the last group averaging the days left over.
    """
    h = np.asarray(histograms, dtype=np.float64)
    if h.ndim != 2:
        raise ValueError(f"histograms must be (days, bins), got shape {h.shape}")
    if group_size < 1:
        raise ValueError(f"group_size must be >= 1, got {group_size}")
    return np.stack([h[i : i + group_size].mean(axis=0) for i in range(0, h.shape[0], group_size)])


def progress_areas(
    histograms: np.ndarray, bin_centres_cm: np.ndarray, group_size: int = 2, start_cm: float = 60.0
) -> np.ndarray:
    """Weighted areas of consecutive-day averaged histograms (Doshi 2011 section 5.2.2, the 8-day use case).

    ``histograms`` (D, B) are one subject's normalised histograms in day order (e.g. ``distance.histogram_percent``
    of each trial's ``imulog.metrics`` record, from the catalog); returns one area per group of ``group_size`` days.
    A rising sequence is the rehabilitation progress the thesis tracks.
    """
    groups = average_consecutive(histograms, group_size)
    return np.array([weighted_area(h, bin_centres_cm, start_cm) for h in groups])
