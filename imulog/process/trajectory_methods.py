"""Every trajectory method on one window: :func:`reconstruct` and the parameters of all of them.

A window is a repetition, or a whole trial without repetitions. Gravity-free global acceleration in m/s^2,
times in s, positions in m relative to the window's first sample. :data:`BASELINE` (``dedrift``, double
integration with linear velocity de-drift between the window's first and last sample) is the figure every
method must beat (issue 32).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.param_rules import check_rules
from imulog.process.acc_rest_calibration import AccRestParams
from imulog.process.drift import HighpassParams, WaveletParams, highpass, wavelet_detrend
from imulog.process.integration import AnchorParams, DdiParams, RotatingBiasParams, ZuptParams, double_integrate, zupt
from imulog.process.kalman import KalmanParams, kalman_track
from imulog.process.minjerk import R2GWaypoints, r2g_reference
from imulog.process.rests import RestParams
from imulog.process.trajectory_checks import CheckParams
from imulog.process.trajectory_optimize import OptimizationParams, optimize_repetition

METHODS = ("ddi", "zupt", "highpass", "wavelet", "kalman", "zupt_bias", "optimized")
BASELINE = "dedrift"  # double integration with linear velocity de-drift between the window's boundaries


@dataclass(frozen=True)
class TrajectoryParams:
    """Parameters of every reconstruction method (see each class for units)."""

    ddi: DdiParams = DdiParams()
    zupt: ZuptParams = ZuptParams()
    highpass: HighpassParams = HighpassParams()
    wavelet: WaveletParams = WaveletParams()
    kalman: KalmanParams = KalmanParams(zero_velocity=True, smoother=True)
    rotating_bias: RotatingBiasParams = RotatingBiasParams()
    optimized: OptimizationParams = OptimizationParams()
    anchor: AnchorParams = AnchorParams()
    rests: RestParams = RestParams()
    checks: CheckParams = CheckParams()
    acc_rests: AccRestParams = AccRestParams()
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def reconstruct(
    method: str,
    t_s: np.ndarray,
    acc_mps2: np.ndarray,
    static_mask: np.ndarray | None = None,
    *,
    phase_bounds_s: np.ndarray | None = None,
    waypoints: R2GWaypoints | None = None,
    acc_compensated_mps2: np.ndarray | None = None,
    params: TrajectoryParams = TrajectoryParams(),
) -> np.ndarray:
    """Position (N, 3) m relative to the window start from gravity-free global acceleration (N, 3) m/s^2.

    ``zupt``, ``kalman`` (its zero-velocity updates), ``zupt_bias`` and ``optimized`` need ``static_mask``;
    ``optimized`` also needs the four R2G ``phase_bounds_s`` (4, 2) s and ``waypoints``. ``zupt_bias`` needs
    ``acc_compensated_mps2`` (the acceleration after :func:`compensate_rotating_bias`); ``optimized`` starts
    from ZUPT on it when given, else from ZUPT on ``acc_mps2``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    a = np.asarray(acc_mps2, dtype=np.float64)
    if method == "ddi":
        return double_integrate(a, t, params.ddi)[1]
    if method == BASELINE:  # zero velocity at the window's first and last sample only
        ends = np.zeros(len(t), dtype=bool)
        ends[[0, -1]] = True
        return zupt(a, t, ends, params.zupt)[1]
    if method in ("highpass", "wavelet"):
        pos = double_integrate(a, t, params.ddi)[1]
        if method == "highpass":
            rate = (len(t) - 1) / (t[-1] - t[0])
            out = highpass(pos, rate, params.highpass)
        else:
            out = wavelet_detrend(pos, params.wavelet)
        return out - out[0]
    if static_mask is None:
        raise ValueError(f"method {method!r} needs a static mask")
    if method == "zupt":
        return zupt(a, t, static_mask, params.zupt)[1]
    if method == "kalman":
        res = kalman_track(a, t, static_mask, params.kalman)
        return res.position - res.position[0]
    if method == "zupt_bias":
        if acc_compensated_mps2 is None:
            raise ValueError("method 'zupt_bias' needs the orientation (for the rotating-bias compensation)")
        return zupt(acc_compensated_mps2, t, static_mask, params.zupt)[1]
    if method == "optimized":
        if phase_bounds_s is None or waypoints is None:
            raise ValueError("method 'optimized' needs phase bounds and waypoints")
        base = a if acc_compensated_mps2 is None else np.asarray(acc_compensated_mps2, dtype=np.float64)
        initial = zupt(base, t, static_mask, params.zupt)[1]
        reference = r2g_reference(t, phase_bounds_s, waypoints)
        return optimize_repetition(t, initial, reference, phase_bounds_s, static_mask, params.optimized).position
    raise ValueError(f"unknown method {method!r}; choose from {', '.join((*METHODS, BASELINE))}")


DEFAULT_PARAMS = TrajectoryParams()


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of scalar-first unit quaternions (N, 4)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )
