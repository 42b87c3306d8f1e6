"""Time lag by cross-correlation of angular-velocity norms, and the constant rotations between the IMU, the
cluster and the world (Wahba / least squares). Times in int64 ns, rad/s. Split from
:mod:`imulog.process.alignment` (issue 24).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.alignment_clock import NS

# --------------------------------------------------------------------------------------------
# time lag by cross-correlation


@dataclass
class LagEstimate:
    """``offset_ns``: t_ref - t_dev at the window; ``score``: peak normalised correlation (0-1);
    ``t_dev_center_ns``: device time of the window's centre."""

    offset_ns: int
    score: float
    t_dev_center_ns: int


def _uniform(t_ns: np.ndarray, x: np.ndarray, t0_ns: int, rate_hz: float, n: int) -> np.ndarray:
    """``x`` linearly interpolated at ``t0 + k / rate`` (k < n); NaN -> 0 after mean removal."""
    grid = t0_ns + np.round(np.arange(n) * (NS / rate_hz)).astype(np.int64)
    ok = np.isfinite(x)
    y = np.interp(grid.astype(np.float64), t_ns[ok].astype(np.float64), x[ok], left=np.nan, right=np.nan)
    return y


def estimate_lag(
    t_dev_ns: np.ndarray,
    w_dev_norm: np.ndarray,
    t_ref_ns: np.ndarray,
    w_ref_norm: np.ndarray,
    *,
    window_start_s: float = 0.0,
    window_s: float = 120.0,
    max_lag_s: float = 60.0,
    grid_hz: float = 200.0,
    min_overlap: float = 0.5,
    prior_offset_ns: int | None = None,
) -> LagEstimate:
    """Clock offset by normalised cross-correlation of angular-velocity norms.

    The reference window is ``[t_ref[0] + window_start_s, + window_s]`` (default the first two
    minutes, the R2G protocol's static period and wave). The device signal is searched over the
    same stretch of its own clock +- ``max_lag_s`` (``prior_offset_ns`` given: of the reference window shifted
    by that offset, t_dev = t_ref - prior). Both are put on a ``grid_hz`` grid, mean-removed
    and correlated (normalised by the local energy of the overlapping device stretch, so a loud
    movement elsewhere does not win); the peak is refined to sub-sample precision by a parabola.
    """
    t_dev_ns = np.asarray(t_dev_ns, dtype=np.int64)
    t_ref_ns = np.asarray(t_ref_ns, dtype=np.int64)
    ws = int(round(window_start_s * NS))
    ref0 = int(t_ref_ns[0]) + ws
    # a recording shorter than the window: correlate what there is (else no lag reaches min_overlap)
    window_s = max(min(window_s, (int(t_ref_ns[-1]) - ref0) / NS), 0.0)
    na = int(window_s * grid_hz)
    a = _uniform(t_ref_ns, np.asarray(w_ref_norm, dtype=np.float64), ref0, grid_hz, na)
    prior = int(t_ref_ns[0]) - int(t_dev_ns[0]) if prior_offset_ns is None else int(prior_offset_ns)
    dev0 = ref0 - prior - int(round(max_lag_s * NS))
    nb = int((window_s + 2 * max_lag_s) * grid_hz)
    b = _uniform(t_dev_ns, np.asarray(w_dev_norm, dtype=np.float64), dev0, grid_hz, nb)
    a_ok = np.isfinite(a)
    if a_ok.sum() < 10:
        raise ValueError("reference angular velocity has no samples in the alignment window")
    a = np.where(a_ok, a - np.nanmean(a), 0.0)
    b_ok = np.isfinite(b)
    if b_ok.sum() < 10:
        raise ValueError("device angular velocity has no samples in the alignment window")
    b = np.where(b_ok, b - np.nanmean(b), 0.0)
    from scipy import signal

    c = signal.correlate(b, a, mode="full", method="fft")
    lags = signal.correlation_lags(len(b), len(a), mode="full")
    # local energy of b under the template, and overlap fraction
    cs = np.concatenate([[0.0], np.cumsum(b * b)])
    cok = np.concatenate([[0], np.cumsum(b_ok.astype(np.int64))])
    lo = np.clip(lags, 0, len(b))
    hi = np.clip(lags + len(a), 0, len(b))
    energy = cs[hi] - cs[lo]
    overlap = (cok[hi] - cok[lo]) / len(a)
    norm_a = np.sqrt(np.sum(a * a))
    with np.errstate(invalid="ignore", divide="ignore"):
        ncc = c / (norm_a * np.sqrt(energy))
    ncc[~np.isfinite(ncc) | (overlap < min_overlap)] = -np.inf
    if not np.isfinite(ncc).any():
        raise ValueError(
            f"no clock offset within +-{max_lag_s:g} s overlaps the {window_s:g} s reference window by "
            f">= {min_overlap:.0%}: check --window-start, --window and --max-lag against the recording"
        )
    k = int(np.argmax(ncc))
    frac = 0.0
    if 0 < k < len(ncc) - 1 and np.isfinite(ncc[k - 1]) and np.isfinite(ncc[k + 1]):
        y0, y1, y2 = ncc[k - 1], ncc[k], ncc[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            frac = 0.5 * (y0 - y2) / den
    lag = (lags[k] + frac) / grid_hz  # s: b[n + lag] ~ a[n]
    # device time dev0 + (n + lag)/grid matches reference time ref0 + n/grid
    offset_ns = int(round(ref0 - dev0 - lag * NS))
    center = int(round(ref0 + window_s * NS / 2)) - offset_ns
    return LagEstimate(offset_ns=offset_ns, score=float(ncc[k]), t_dev_center_ns=center)


# --------------------------------------------------------------------------------------------
# constant rotations


def _wahba(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation matrix R minimising sum |b_i - R a_i|^2 (SVD solution of Wahba's problem)."""
    h = a.T @ b
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def estimate_rotation_imu_to_cluster(w_imu_rad_s: np.ndarray, w_cluster_rad_s: np.ndarray) -> tuple[np.ndarray, float]:
    """Constant rotation (quaternion) from IMU sensor frame to cluster frame, and residual RMS rad/s.

    Least squares on time-aligned angular velocities, ``w_cluster ~ R w_imu`` (Chardonnens et al.
    2012 align inertial and optical frames from angular velocities); rows with NaN are skipped.
    """
    a = np.asarray(w_imu_rad_s, dtype=np.float64)
    b = np.asarray(w_cluster_rad_s, dtype=np.float64)
    ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    if ok.sum() < 10:
        raise ValueError("too few common angular-velocity samples to estimate the IMU-to-cluster rotation")
    r = _wahba(a[ok], b[ok])
    resid = b[ok] - a[ok] @ r.T
    return quat.from_rotation_matrix(r), float(np.sqrt(np.mean(np.sum(resid**2, axis=1))))


def rotation_global_to_world(
    q_imu_s2g: np.ndarray, q_cluster_to_world: np.ndarray, q_imu_to_cluster: np.ndarray
) -> np.ndarray:
    """Constant rotation from the IMU's global frame to the Vicon world frame (quaternion).

    With time-aligned samples, ``q_c2w(t) * q_i2c = q_g2w * q_s2g(t)``; the chordal mean of
    ``q_c2w * q_i2c * q_s2g^-1`` over the finite rows is returned.
    """
    e = quat.multiply(quat.multiply(q_cluster_to_world, q_imu_to_cluster), quat.conjugate(q_imu_s2g))
    ok = np.all(np.isfinite(e), axis=1)
    return quat.average(e[ok])


# --------------------------------------------------------------------------------------------
