"""White-noise level of an IMU channel from its still periods (issue 31 point 1: the simulator's noise against
real devices').

A still period is found by a rule, not by hand: the recording is cut into non-overlapping windows, each window's
*motion score* is the summed per-axis variance of the channel after removing a least-squares line (a slow drift or
a slowly turning gravity is not noise), and a window is still when its score is at most ``max_ratio`` times the
quietest window's (noise alone varies far less than that between windows of a few hundred samples; a hand that
moves, or tremor, adds to it; a quantisation-limited device's floor is at least its quantisation's variance).
The noise level in those windows is given two ways:

* the per-sample sd (per axis, detrended; the rms over the axes), and the density it implies if the noise were
  white up to the Nyquist frequency, ``sd / sqrt(rate / 2)``;
* the density measured in a band (Welch periodogram of each still window, averaged, the mean one-sided PSD over
  ``band_hz``): what a movement's own band sees, whatever the device's anti-alias filter does above it.

Quantisation: the smallest step between the values the still windows hold; a white noise far below it is not
resolved (the sd then lies between ``step / sqrt(12)`` and about ``step``). Pure numpy/scipy; no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process.calibration import GRAVITY_M_S2 as G0  # m/s^2 per g (re-exported for the reports)

__all__ = [
    "G0",
    "NoiseLevel",
    "StillParams",
    "detrended",
    "motion_scores",
    "noise_level",
    "smallest_step",
    "still_windows",
    "window_bounds",
]


@dataclass(frozen=True)
class StillParams:
    """The still-window rule and the density band.

    ``window_s``: length of a candidate window (s, non-overlapping); ``max_ratio``: a window is still when its
    motion score is at most this times the quietest window's (dimensionless); ``band_hz``: (low, high) Hz of the
    band density, the high end capped at ``band_cap`` times the rate (below the anti-alias roll-off)."""

    window_s: float = 2.0
    max_ratio: float = 2.0
    band_hz: tuple[float, float] = (1.0, 10.0)
    band_cap: float = 0.4


@dataclass(frozen=True)
class NoiseLevel:
    """Noise of one 3-axis channel in its still windows (units of the channel: m/s^2 or rad/s).

    ``sd``: per-sample sd (rms over the axes); ``density_white``: ``sd / sqrt(rate/2)`` per sqrt(Hz);
    ``density_band``: sqrt of the mean one-sided PSD over the band, per sqrt(Hz) (nan when the band is empty);
    ``step``: smallest step between values (0 for none seen); ``still_s``: seconds of still windows used."""

    sd: float
    density_white: float
    density_band: float
    step: float
    still_s: float
    band_hz: tuple[float, float]

    @property
    def quantisation_limited(self) -> bool:
        """The sd is under one quantisation step: the device's white noise is not resolved by its LSB."""
        return self.step > 0 and self.sd < self.step


def detrended(x: np.ndarray) -> np.ndarray:
    """``x`` (N, D) minus each column's least-squares line over the samples."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    if n < 3:
        return x - x.mean(axis=0)
    t = np.arange(n, dtype=float) - (n - 1) / 2.0
    slope = (t @ (x - x.mean(axis=0))) / float(t @ t)
    return x - x.mean(axis=0) - np.outer(t, slope)


def window_bounds(n: int, rate_hz: float, window_s: float) -> np.ndarray:
    """(K, 2) sample index bounds ``[i0, i1)`` of the non-overlapping windows of ``window_s`` in ``n`` samples."""
    w = max(3, int(round(window_s * rate_hz)))
    starts = np.arange(0, n - w + 1, w)
    return np.column_stack([starts, starts + w]).astype(np.int64)


def motion_scores(x: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Per window, the summed per-axis variance of ``x`` (N, D) after removing its line (units of x squared);
    inf for a window holding a non-finite value."""
    out = np.empty(len(bounds))
    for k, (i0, i1) in enumerate(bounds):
        w = x[i0:i1]
        out[k] = float(np.sum(np.var(detrended(w), axis=0))) if np.all(np.isfinite(w)) else np.inf
    return out


def still_windows(motion: np.ndarray, rate_hz: float, params: StillParams = StillParams()) -> np.ndarray:
    """(K, 2) bounds of the still windows of a recording whose motion channel (the gyroscope where there is one,
    else the accelerometer) is ``motion`` (N, D) sampled at ``rate_hz``: score at most ``max_ratio`` times the
    quietest window's, or than the variance of the quantisation alone (``D step^2 / 12``) where that is larger (a
    quantisation-limited device reads exactly constant in its quietest windows). Empty when the recording is
    shorter than one window."""
    motion = np.asarray(motion, dtype=float)
    bounds = window_bounds(len(motion), rate_hz, params.window_s)
    if len(bounds) == 0:
        return bounds
    scores = motion_scores(motion, bounds)
    finite = np.isfinite(scores)
    if not finite.any():
        return bounds[:0]
    floor = max(float(np.min(scores[finite])), motion.shape[1] * smallest_step(motion) ** 2 / 12.0)
    return bounds[finite & (scores <= params.max_ratio * floor)]


def smallest_step(x: np.ndarray) -> float:
    """Smallest positive difference between the distinct values of any column of ``x`` (N, D) (the quantisation
    step as the file holds it; 0 when every column is constant); values equal to 1e-9 relative are one value."""
    steps = []
    for col in np.asarray(x, dtype=float).T:
        col = col[np.isfinite(col)]
        if len(col) < 2:
            continue
        scale = max(float(np.max(np.abs(col))), 1e-300)
        u = np.unique(np.round(col / scale, 9))
        d = np.diff(u) * scale
        d = d[d > 0]
        if len(d):
            steps.append(float(np.min(d)))
    return min(steps) if steps else 0.0


def noise_level(x: np.ndarray, rate_hz: float, windows: np.ndarray, params: StillParams = StillParams()) -> NoiseLevel:
    """Noise of channel ``x`` (N, 3) sampled at ``rate_hz`` over the still ``windows`` (K, 2) (see module doc)."""
    from scipy.signal import welch

    x = np.asarray(x, dtype=float)
    if len(windows) == 0:
        raise ValueError("no still window: the recording is shorter than one window or never still")
    var, psd, n, held = [], [], 0, []
    lo, hi = params.band_hz[0], min(params.band_hz[1], params.band_cap * rate_hz)
    for i0, i1 in windows:
        w = detrended(x[i0:i1])
        var.append(np.var(w, axis=0) * len(w))
        n += len(w)
        held.append(x[i0:i1])
        f, p = welch(w, fs=rate_hz, nperseg=len(w), detrend=False, axis=0)
        psd.append(p)
    sd = float(np.sqrt(np.sum(var) / (n * x.shape[1])))
    mean_psd = np.mean(psd, axis=0)  # (F, 3)
    band = (f >= lo) & (f <= hi)
    density_band = float(np.sqrt(np.mean(mean_psd[band]))) if band.any() and hi > lo else float("nan")
    return NoiseLevel(
        sd=sd,
        density_white=sd / np.sqrt(rate_hz / 2.0),
        density_band=density_band,
        step=smallest_step(np.concatenate(held)),
        still_s=n / rate_hz,
        band_hz=(lo, hi),
    )
