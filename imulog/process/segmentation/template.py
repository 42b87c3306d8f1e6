"""Template matching for repeated movements (R2G thesis 2.3.3, the slide bench).

Example segments of a repeated movement are averaged into a template (each resampled to the median length);
the normalised cross-correlation of the template with the signal peaks where the movement recurs; the
template's own start/end marks (by default its first and last sample) map onto every match.
Signals are 1-D (e.g. the angular-velocity norm in rad/s, or the acceleration norm in m/s^2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.param_rules import check_rules


@dataclass(frozen=True)
class TemplateParams:
    """Parameters of :func:`match_template`.

    min_correlation: lowest normalised cross-correlation (-1..1) accepted as a match.
    min_distance_fraction: matches closer than this fraction of the template length are one match.
    n_matches: keep at most this many best matches (0 = all), e.g. 30 slides per trial in the thesis.
    """

    min_correlation: float = 0.6
    min_distance_fraction: float = 0.8
    n_matches: int = 0
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def build_template(signal: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Average of the segments ``signal[start:end]`` after resampling each to the median segment length."""
    signal = np.asarray(signal, dtype=float)
    lengths = np.asarray(end) - np.asarray(start)
    if len(lengths) == 0 or lengths.min() < 2:
        raise ValueError("a template needs at least one segment of two samples or more")
    m = int(np.median(lengths))
    grid = np.linspace(0, 1, m)
    rows = [np.interp(grid, np.linspace(0, 1, b - a), signal[a:b]) for a, b in zip(start, end, strict=True)]
    return np.mean(rows, axis=0)


def normalised_xcorr(signal: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Pearson correlation of ``template`` with every window of ``signal`` (length ``len(signal)-m+1``)."""
    x = np.asarray(signal, dtype=float)
    t = np.asarray(template, dtype=float)
    m = len(t)
    if len(x) < m:
        return np.zeros(0)
    t = (t - t.mean()) / (t.std() * m or 1.0)
    num = np.correlate(x, t, mode="valid")
    c1 = np.concatenate([[0.0], np.cumsum(x)])
    c2 = np.concatenate([[0.0], np.cumsum(x * x)])
    mean = (c1[m:] - c1[:-m]) / m
    var = np.maximum((c2[m:] - c2[:-m]) / m - mean**2, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = num / np.sqrt(var)
    return np.where(np.isfinite(r), r, 0.0)


def match_template(
    signal: np.ndarray,
    template: np.ndarray,
    params: TemplateParams = TemplateParams(),
    marks: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Matches of ``template`` in ``signal``: ``start, end`` (samples, half-open) and correlation of each.

    ``marks`` = (start, end) sample offsets inside the template to map (default: the whole template).
    """
    from scipy.signal import find_peaks

    r = normalised_xcorr(signal, template)
    m = len(template)
    if len(r) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros(0)
    peaks, _ = find_peaks(r, height=params.min_correlation, distance=max(1, int(params.min_distance_fraction * m)))
    if params.n_matches and len(peaks) > params.n_matches:
        peaks = np.sort(peaks[np.argsort(-r[peaks], kind="stable")[: params.n_matches]])
    a, b = marks if marks is not None else (0, m)
    start = (peaks + a).astype(np.int64)
    end = np.minimum(peaks + b, len(signal)).astype(np.int64)
    return start, end, r[peaks]
