"""Zero-velocity (static) intervals for ZUPT.

* :func:`static_from_movements`: the complement of movements found by any segmentation (DynAMoS, the double
  threshold, template matching), optionally shrunk by a safety margin;
* :func:`gyro_norm_static`: baseline detector: a sample is static when the windowed mean of the gyroscope
  norm stays below a threshold (default 0.1 rad/s, the static threshold of the R2G thesis 3.3.3); static
  runs shorter than ``min_static_s`` are discarded.

Masks are (N,) bool with True = zero velocity; intervals are half-open sample ranges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.numeric import moving_mean
from imulog.param_rules import check_rules
from imulog.process.segmentation.dynamos import runs


@dataclass(frozen=True)
class GyroNormStaticParams:
    """Parameters of :func:`gyro_norm_static`.

    threshold_rad_s: static when the windowed gyroscope norm is below this (rad/s); R2G thesis: 0.1.
        For a foot IMU in gait, gaitmap's NormZeroVelocityDetection uses 70 deg/s (1.22 rad/s).
    window_s: length (s) of the centred moving window; metric: ``"mean"`` or ``"max"`` over the window.
    min_static_s: static runs shorter than this (s) are treated as movement.
    """

    threshold_rad_s: float = 0.1
    window_s: float = 0.15
    metric: str = "mean"
    min_static_s: float = 0.2
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def mask_from_intervals(n: int, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(n,) bool mask, True inside the half-open intervals ``[start, end)``."""
    d = np.zeros(n + 1, dtype=np.int64)
    s = np.clip(np.asarray(start, dtype=np.int64), 0, n)
    e = np.clip(np.asarray(end, dtype=np.int64), 0, n)
    np.add.at(d, s, 1)
    np.add.at(d, e, -1)
    return np.cumsum(d[:-1]) > 0


def static_from_movements(
    n: int, start: np.ndarray, end: np.ndarray, rate_hz: float, margin_s: float = 0.0, min_static_s: float = 0.0
) -> np.ndarray:
    """Zero-velocity mask: outside the movements widened by ``margin_s`` (s), static runs >= ``min_static_s``."""
    pad = int(round(margin_s * rate_hz))
    static = ~mask_from_intervals(n, np.asarray(start) - pad, np.asarray(end) + pad)
    return drop_short_runs(static, int(round(min_static_s * rate_hz)))


def drop_short_runs(mask: np.ndarray, min_samples: int) -> np.ndarray:
    """Copy of ``mask`` with True runs shorter than ``min_samples`` set False."""
    out = np.asarray(mask, dtype=bool).copy()
    if min_samples > 1:
        s, e = runs(out)
        for a, b in zip(s, e, strict=True):
            if b - a < min_samples:
                out[a:b] = False
    return out


def _moving(x: np.ndarray, w: int, metric: str) -> np.ndarray:
    if w <= 1:
        return x
    if metric == "mean":
        return moving_mean(x, w)
    if metric == "max":
        from scipy.ndimage import maximum_filter1d

        return maximum_filter1d(x, size=w, mode="nearest")
    raise ValueError(f"metric must be 'mean' or 'max', got {metric!r}")


def gyro_norm_static(
    gyr_rad_s: np.ndarray, rate_hz: float, params: GyroNormStaticParams = GyroNormStaticParams()
) -> np.ndarray:
    """Baseline zero-velocity mask from the windowed gyroscope norm (gyr (N, 3) in rad/s)."""
    gyr = np.asarray(gyr_rad_s, dtype=float)
    norm = np.linalg.norm(np.where(np.isfinite(gyr), gyr, 0.0), axis=1)
    metric = _moving(norm, int(round(params.window_s * rate_hz)), params.metric)
    return drop_short_runs(metric < params.threshold_rad_s, int(round(params.min_static_s * rate_hz)))
