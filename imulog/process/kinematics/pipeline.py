"""From two orientation series to joint angles, joint centres and constraint masks (pure numpy).

    res = estimate_kinematics(q_ua_s2g, q_fa_s2g, t_ns, KinematicsConfig(...))

calibrates each series to the trunk frame in the neutral window (:mod:`.calibration`), solves the
unconstrained and constrained problems (:mod:`.solver`) and runs the forward kinematics of both.

The trunk is still (the paper's assumption) unless a third, trunk orientation series is given
(``q_trunk_s2g``, a sensor with its axes on the trunk axes): the trunk frame then follows that
sensor's rotation since the neutral posture, expressed in its own axes, ``T(t) = R(q_Tn^-1 q_T(t))``,
and each segment is expressed in it, ``T(t)^T R_seg(t)``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.kinematics.calibration import NeutralCalibration, fit_global_to_trunk, segment_rotations
from imulog.process.kinematics.dh import ArmModel, ForwardKinematics, JointLimits, forward_kinematics
from imulog.process.kinematics.errors import outside_workspace
from imulog.process.kinematics.solver import SolveResult, SolverParams, Workspace, solve_sequence

__all__ = ["KinematicsConfig", "KinematicsEstimate", "estimate_kinematics"]


@dataclass(frozen=True)
class KinematicsConfig:
    """Everything the estimate depends on (model geometry, limits, boxes, calibration, solver)."""

    model: ArmModel = ArmModel()
    limits: JointLimits = JointLimits()
    workspace: Workspace = Workspace()
    calibration: NeutralCalibration = NeutralCalibration()
    solver: SolverParams = SolverParams()


@dataclass
class KinematicsEstimate:
    """Unconstrained and constrained solutions with their forward kinematics (trunk frame)."""

    t_ns: np.ndarray
    unconstrained: SolveResult
    constrained: SolveResult | None
    fk_unconstrained: ForwardKinematics
    fk_constrained: ForwardKinematics | None
    t_out: np.ndarray  # (N,) unconstrained elbow or wrist outside its box
    q_global_to_trunk: dict[str, np.ndarray]
    timing_ms_per_sample: dict[str, float] = field(default_factory=dict)


def _fk_nan(q: np.ndarray, model: ArmModel) -> ForwardKinematics:
    ok = np.all(np.isfinite(q), axis=1)
    n = len(q)
    out = ForwardKinematics(
        np.full((n, 3, 3), np.nan), np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    )
    if ok.any():
        fk = forward_kinematics(q[ok], model)
        out.r_upper_arm[ok], out.r_forearm[ok], out.elbow_m[ok], out.wrist_m[ok] = (
            fk.r_upper_arm,
            fk.r_forearm,
            fk.elbow_m,
            fk.wrist_m,
        )
    return out


def calibrate_kinematics(
    q_upper_arm_s2g: np.ndarray,
    q_forearm_s2g: np.ndarray,
    t_ns: np.ndarray,
    config: KinematicsConfig = KinematicsConfig(),
    *,
    q_segment_to_sensor: dict[str, np.ndarray] | None = None,
    q_trunk_s2g: np.ndarray | None = None,
) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """The neutral-posture calibration: (global-to-trunk quaternion per segment, the trunk sensor's mean neutral
    orientation or None), from the samples of the neutral window (relative to ``t_ns[0]``)."""
    mount = q_segment_to_sensor or {}
    window = config.calibration.window_mask(t_ns)
    if not window.any():
        raise ValueError(
            f"the neutral window {config.calibration.window_s} s holds no sample "
            f"(recording lasts {(int(t_ns[-1]) - int(t_ns[0])) * 1e-9:.2f} s)"
        )
    fk_n = forward_kinematics(np.radians(config.calibration.pose_deg), config.model)
    g2t = {}
    for seg, q, r_model in (
        ("upper_arm", q_upper_arm_s2g, fk_n.r_upper_arm),
        ("forearm", q_forearm_s2g, fk_n.r_forearm),
    ):
        m = np.asarray(mount.get(seg, quat.IDENTITY), dtype=np.float64)
        g2t[seg] = fit_global_to_trunk(np.asarray(q)[window], r_model, m, config.calibration.mode)
    q_tn = None
    if q_trunk_s2g is not None:
        q_t = np.asarray(q_trunk_s2g, dtype=np.float64)
        q_tn = quat.average(q_t[window][np.all(np.isfinite(q_t[window]), axis=1)])
    return g2t, q_tn


def estimate_kinematics(
    q_upper_arm_s2g: np.ndarray,
    q_forearm_s2g: np.ndarray,
    t_ns: np.ndarray,
    config: KinematicsConfig = KinematicsConfig(),
    *,
    constrained: bool = True,
    q_segment_to_sensor: dict[str, np.ndarray] | None = None,
    q_trunk_s2g: np.ndarray | None = None,
    calibrated: tuple[dict[str, np.ndarray], np.ndarray | None] | None = None,
    warm_start: dict[str, np.ndarray] | None = None,
) -> KinematicsEstimate:
    """Joint angles from sensor-to-global quaternions (N, 4) of the upper-arm and forearm sensors
    (or marker clusters) sampled at ``t_ns``; ``q_segment_to_sensor`` optional mounting rotations;
    ``q_trunk_s2g`` (N, 4) an optional trunk sensor (or cluster) on the same samples.

    A recording in windows: ``calibrated`` is :func:`calibrate_kinematics` of its first window, ``warm_start``
    the previous window's last solutions (rad, keys ``unconstrained``/``constrained``): the windows then give
    the angles of the whole, sample by sample."""
    mount = q_segment_to_sensor or {}
    if calibrated is None:
        calibrated = calibrate_kinematics(
            q_upper_arm_s2g, q_forearm_s2g, t_ns, config, q_segment_to_sensor=mount, q_trunk_s2g=q_trunk_s2g
        )
    g2t, q_tn = calibrated
    rots = {}
    for seg, q in (("upper_arm", q_upper_arm_s2g), ("forearm", q_forearm_s2g)):
        m = np.asarray(mount.get(seg, quat.IDENTITY), dtype=np.float64)
        rots[seg] = segment_rotations(q, g2t[seg], m)
    if q_trunk_s2g is not None:
        q_t = np.asarray(q_trunk_s2g, dtype=np.float64)
        if q_t.shape != (len(t_ns), 4):
            raise ValueError(f"q_trunk_s2g must have shape ({len(t_ns)}, 4), got {q_t.shape}")
        trunk = quat.to_rotation_matrix(quat.multiply(quat.conjugate(q_tn), q_t))  # rotation since the posture
        for seg in rots:
            rots[seg] = np.einsum("nji,njk->nik", trunk, rots[seg])
    warm = warm_start or {}
    q0 = np.radians(config.calibration.pose_deg)
    n = len(t_ns)
    t0 = time.perf_counter()
    un = solve_sequence(
        rots["upper_arm"], rots["forearm"], config.model, q0_rad=warm.get("unconstrained", q0), params=config.solver
    )
    t1 = time.perf_counter()
    timing = {"unconstrained": (t1 - t0) * 1e3 / max(n, 1)}
    fk_un = _fk_nan(un.q_rad, config.model)
    t_out = outside_workspace(fk_un.elbow_m, fk_un.wrist_m, config.workspace) & np.all(np.isfinite(un.q_rad), axis=1)
    con = fk_con = None
    if constrained:
        lo, hi = config.limits.as_rad()
        t0 = time.perf_counter()
        con = solve_sequence(
            rots["upper_arm"],
            rots["forearm"],
            config.model,
            constrained=True,
            limits=config.limits,
            workspace=config.workspace,
            q0_rad=warm.get("constrained", np.clip(q0, lo, hi)),
            params=config.solver,
        )
        timing["constrained"] = (time.perf_counter() - t0) * 1e3 / max(n, 1)
        fk_con = _fk_nan(con.q_rad, config.model)
        # samples the solver could not bring inside the boxes (an infeasible box specification)
        outside = outside_workspace(fk_con.elbow_m, fk_con.wrist_m, config.workspace, config.solver.feasibility_tol_m)
        con.extra["n_infeasible"] = int(np.sum(outside & np.all(np.isfinite(con.q_rad), axis=1)))
    return KinematicsEstimate(np.asarray(t_ns, dtype=np.int64), un, con, fk_un, fk_con, t_out, g2t, timing)
