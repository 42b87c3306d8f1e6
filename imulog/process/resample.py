"""Anti-aliased resampling of IMU-derived channels onto the reference (Vicon) clock.

The R2G thesis resamples the 115 Hz BlueBuddy signals to Vicon's 100 Hz with MATLAB's
``interp1``; plain interpolation to a lower rate aliases content between the new Nyquist frequency
(50 Hz) and the old one (57.5 Hz). Here the source is first low-pass filtered, zero-phase, below
the destination Nyquist frequency, then interpolated at the destination times. Orientation
quaternions are resampled on the unit sphere (sign-continuous, filtered, renormalised, slerp).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat

__all__ = ["ResampleParams", "resample_quaternions", "resample_signal", "uniform_grid"]

NS = 1_000_000_000


@dataclass(frozen=True)
class ResampleParams:
    """``cutoff_ratio``: anti-alias low-pass at this fraction of the destination Nyquist frequency
    (0.9; 0 = no filter, interpolation only); ``order``: Butterworth order (4, applied
    forward-backward)."""

    cutoff_ratio: float = 0.9
    order: int = 4


def _rate(t_ns: np.ndarray) -> float:
    return NS / float(np.median(np.diff(t_ns)))


def uniform_grid(start_ns: int, end_ns: int, rate_hz: float) -> np.ndarray:
    """int64 ns times ``start + k / rate`` up to ``end`` (inclusive)."""
    n = int(np.floor((end_ns - start_ns) * rate_hz / NS)) + 1
    return start_ns + np.round(np.arange(max(n, 0)) * (NS / rate_hz)).astype(np.int64)


def _lowpass(values: np.ndarray, src_rate: float, dst_rate: float, params: ResampleParams) -> np.ndarray:
    if not params.cutoff_ratio or params.cutoff_ratio <= 0:
        return values  # interpolation only
    cutoff = params.cutoff_ratio * dst_rate / 2.0
    if cutoff >= src_rate / 2.0 * 0.999:
        return values
    from scipy import signal  # lazy: `imulog info` imports the align step for its summary, not the filter

    sos = signal.butter(params.order, cutoff, fs=src_rate, output="sos")
    out = values.copy()
    ok = np.all(np.isfinite(values), axis=1)
    d = np.diff(np.concatenate([[0], ok.astype(np.int8), [0]]))
    for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        if e - s > 3 * (2 * len(sos) + 1):
            out[s:e] = signal.sosfiltfilt(sos, values[s:e], axis=0)
    return out


def resample_signal(
    t_src_ns: np.ndarray,
    values: np.ndarray,
    t_dst_ns: np.ndarray,
    params: ResampleParams = ResampleParams(),
    dst_rate_hz: float | None = None,
) -> np.ndarray:
    """Values (N, C) at ``t_src_ns`` resampled at ``t_dst_ns`` (both on one clock), anti-aliased.

    NaN outside the source span and in source gaps.
    """
    t_src = np.asarray(t_src_ns, dtype=np.int64)
    t_dst = np.asarray(t_dst_ns, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64)
    squeeze = v.ndim == 1
    v = v.reshape(len(v), -1)
    dst_rate = dst_rate_hz or (_rate(t_dst) if len(t_dst) > 1 else _rate(t_src))
    f = _lowpass(v, _rate(t_src), dst_rate, params)
    out = np.full((len(t_dst), v.shape[1]), np.nan)
    ok = np.all(np.isfinite(f), axis=1)
    ts = t_src.astype(np.float64)
    td = t_dst.astype(np.float64)
    for c in range(v.shape[1]):
        col = np.interp(td, ts[ok], f[ok, c], left=np.nan, right=np.nan)
        out[:, c] = col
    # gaps: a destination sample whose neighbouring source samples are missing stays NaN
    if not ok.all():
        j = np.clip(np.searchsorted(t_src, t_dst), 1, len(t_src) - 1)
        out[~(ok[j] & ok[j - 1])] = np.nan
    return out[:, 0] if squeeze else out


def resample_quaternions(
    t_src_ns: np.ndarray,
    q: np.ndarray,
    t_dst_ns: np.ndarray,
    params: ResampleParams = ResampleParams(),
    dst_rate_hz: float | None = None,
) -> np.ndarray:
    """Unit quaternions (N, 4) resampled at ``t_dst_ns``: hemisphere-continuous, anti-aliased, slerp."""
    t_src = np.asarray(t_src_ns, dtype=np.int64)
    t_dst = np.asarray(t_dst_ns, dtype=np.int64)
    q = quat.normalize(np.asarray(q, dtype=np.float64))
    # make the sign continuous so that component-wise filtering is meaningful
    q = q.copy()
    d = np.sum(q[1:] * q[:-1], axis=1)
    flips = np.concatenate([[False], np.nan_to_num(d, nan=1.0) < 0])
    sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    q *= sign[:, None]
    dst_rate = dst_rate_hz or (_rate(t_dst) if len(t_dst) > 1 else _rate(t_src))
    f = quat.normalize(_lowpass(q, _rate(t_src), dst_rate, params))
    out = np.full((len(t_dst), 4), np.nan)
    inside = (t_dst >= t_src[0]) & (t_dst <= t_src[-1])
    j = np.clip(np.searchsorted(t_src, t_dst[inside], side="right"), 1, len(t_src) - 1)
    i = j - 1
    frac = (t_dst[inside] - t_src[i]) / (t_src[j] - t_src[i]).astype(np.float64)
    out[inside] = quat.slerp(f[i], f[j], frac)
    return out
