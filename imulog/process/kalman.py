"""Kalman filter tracking with a first-order autoregressive acceleration model (Doshi 2011, ch. 6.5).

Per axis the state is ``[s, v, a]`` (m, m/s, m/s^2) with the transition (Doshi eq. 6.9)::

    F = [[1, dt, 0],
         [0, 1, dt],
         [0, 0, alpha]]

and the measurement ``z = a + noise`` (H = [0, 0, 1], eq. 6.8). The 2D/3D filter (eqs. 6.10-6.12)
is the same model per axis with a block-diagonal F, so axes are filtered independently here
(vectorised over axes). Doshi's chosen parameters: ``alpha = 1`` and ``Q = 0.001`` on the
acceleration state; ``R`` is the accelerometer noise variance measured at rest.

Extensions (off by default, as Doshi notes the filter alone drifts in the no-motion periods):
zero-velocity pseudo-measurements ``v = 0`` in static samples, and a Rauch-Tung-Striebel smoother.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from imulog.param_rules import check_rules


@dataclass(frozen=True)
class KalmanParams:
    """AR(1) acceleration Kalman filter.

    alpha: AR(1) coefficient of the acceleration (dimensionless), Doshi's choice 1.0.
    process_var_m2ps4: variance of the acceleration innovation per step ((m/s^2)^2), Doshi's 0.001.
    meas_var_m2ps4: accelerometer noise variance ((m/s^2)^2); None estimates it from the static
        samples (fallback 1e-3 when there are none).
    zero_velocity: add ``v = 0`` pseudo-measurements in static samples.
    zero_velocity_var_m2ps2: variance of that pseudo-measurement ((m/s)^2).
    smoother: run the RTS smoother after the forward pass.
    init_var: initial variance of position (m^2), velocity ((m/s)^2) and acceleration ((m/s^2)^2).
    """

    alpha: float = 1.0
    process_var_m2ps4: float = 1e-3
    meas_var_m2ps4: float | None = None
    zero_velocity: bool = False
    zero_velocity_var_m2ps2: float = 1e-6
    smoother: bool = False
    init_var: tuple[float, float, float] = (1e-8, 1e-8, 1.0)
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


@dataclass
class KalmanResult:
    """Filtered (or smoothed) states, each (N,) or (N, D): position m, velocity m/s, acceleration m/s^2."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


def estimate_noise_var(acc_mps2: np.ndarray, static_mask: np.ndarray | None) -> float:
    """Accelerometer noise variance ((m/s^2)^2) from the static samples, averaged over axes."""
    a = np.asarray(acc_mps2, dtype=np.float64).reshape(len(acc_mps2), -1)
    if static_mask is None or np.count_nonzero(static_mask) < 10:
        return 1e-3
    return float(np.mean(np.nanvar(a[np.asarray(static_mask, bool)], axis=0)))


@njit(cache=True)
def _forward(z, static, dts, alpha, q, r, rz, zero_velocity, init_var):  # pragma: no cover - compiled
    n, d = z.shape
    xf = np.zeros((n, d, 3))
    pf = np.zeros((n, d, 3, 3))
    xp = np.zeros((n, d, 3))
    pp = np.zeros((n, d, 3, 3))
    for j in range(d):
        x = np.zeros(3)
        if np.isfinite(z[0, j]):
            x[2] = z[0, j]
        p = np.zeros((3, 3))
        for i in range(3):
            p[i, i] = init_var[i]
        f = np.eye(3)
        for k in range(n):
            if k > 0:
                dt = dts[k]
                f[0, 1] = dt
                f[1, 2] = dt
                f[2, 2] = alpha
                x = f @ x
                p = f @ p @ f.T
                p[2, 2] += q
            xp[k, j] = x
            pp[k, j] = p
            if np.isfinite(z[k, j]):
                s = p[2, 2] + r
                g = p[:, 2] / s
                x = x + g * (z[k, j] - x[2])
                p = p - np.outer(g, p[2, :])
            if zero_velocity and static[k]:
                s = p[1, 1] + rz
                g = p[:, 1] / s
                x = x - g * x[1]
                p = p - np.outer(g, p[1, :])
            p = 0.5 * (p + p.T)
            xf[k, j] = x
            pf[k, j] = p
    return xf, pf, xp, pp


@njit(cache=True)
def _rts(xf, pf, xp, pp, dts, alpha):  # pragma: no cover - compiled
    n, d, _ = xf.shape
    xs = xf.copy()
    f = np.eye(3)
    for j in range(d):
        for k in range(n - 2, -1, -1):
            dt = dts[k + 1]
            f[0, 1] = dt
            f[1, 2] = dt
            f[2, 2] = alpha
            c = pf[k, j] @ f.T @ np.linalg.inv(pp[k + 1, j])
            xs[k, j] = xf[k, j] + c @ (xs[k + 1, j] - xp[k + 1, j])
    return xs


def kalman_track(
    acc_mps2: np.ndarray,
    t_s: np.ndarray,
    static_mask: np.ndarray | None = None,
    params: KalmanParams = KalmanParams(),
) -> KalmanResult:
    """Track position from acceleration ``acc_mps2`` (N,) or (N, D) sampled at ``t_s`` (N,) s (NaN = no measurement)."""
    a_in = np.asarray(acc_mps2, dtype=np.float64)
    squeeze = a_in.ndim == 1
    z = np.ascontiguousarray(a_in[:, None] if squeeze else a_in)
    n, d = z.shape
    t = np.asarray(t_s, dtype=np.float64)
    if t.shape != (n,):
        raise ValueError(f"t_s must have shape ({n},), got {t.shape}")
    static = np.zeros(n, bool) if static_mask is None else np.ascontiguousarray(static_mask, dtype=bool)
    r = params.meas_var_m2ps4 if params.meas_var_m2ps4 is not None else estimate_noise_var(z, static_mask)
    dts = np.diff(t, prepend=t[0])
    xf, pf, xp, pp = _forward(
        z,
        static,
        dts,
        float(params.alpha),
        float(params.process_var_m2ps4),
        float(r),
        float(params.zero_velocity_var_m2ps2),
        bool(params.zero_velocity),
        np.asarray(params.init_var, dtype=np.float64),
    )
    if params.smoother:
        xf = _rts(xf, pf, xp, pp, dts, float(params.alpha))
    pos, vel, acc = xf[:, :, 0], xf[:, :, 1], xf[:, :, 2]
    if squeeze:
        pos, vel, acc = pos[:, 0], vel[:, 0], acc[:, 0]
    return KalmanResult(position=pos, velocity=vel, acceleration=acc)
