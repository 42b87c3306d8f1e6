"""The solver on real upper-limb marker data (kineticstoolkit wheelchair-propulsion C3D, right arm).

No real two-IMU recording exists in the shared data; the right arm and forearm marker clusters give
real, noisy segment orientations (70 Hz, 10 s) to check robustness: feasibility of every constrained
sample and per-sample optimality against SciPy on data the solver was not designed around.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imulog.process import quaternion as quat
from imulog.process.alignment import cluster_frame_oxy
from imulog.process.kinematics import (
    ArmModel,
    JointLimits,
    KinematicsConfig,
    NeutralCalibration,
    Workspace,
    WorkspaceBox,
    estimate_kinematics,
    forward_kinematics,
    solve_sample_scipy,
)


@pytest.fixture(scope="module")
def clusters(shared_data: Path):
    converters = pytest.importorskip("imulog.converters.c3d")
    rec = converters.read_c3d(shared_data / "c3d" / "ktk_sample_propulsion_upperlimb.c3d")
    m = rec.markers[0]

    def q(prefix: str) -> np.ndarray:
        p = [m.pos[:, m.labels.index(f"{prefix}{k}")] for k in (1, 2, 3)]
        return quat.from_rotation_matrix(cluster_frame_oxy(*p))

    return m.t_ns, q("ArmR"), q("ForearmR")


def test_real_marker_orientations_constrained_is_feasible_and_optimal(clusters):
    t_ns, q_ua, q_fa = clusters
    model = ArmModel()
    # the clusters are not aligned with the DH segment axes: calibrate fully on the first 0.3 s
    calib = NeutralCalibration(pose_deg=(60.0, 30.0, 0.0, 60.0, 60.0), window_s=(0.0, 0.3), mode="full")
    free = estimate_kinematics(q_ua, q_fa, t_ns, KinematicsConfig(model=model, calibration=calib), constrained=False)
    el, wr = free.fk_unconstrained.elbow_m, free.fk_unconstrained.wrist_m
    # boxes that cut the real movement (inner 10-90 % of each coordinate): constraints become active
    ws = Workspace(
        WorkspaceBox(tuple(np.percentile(el, 10, axis=0)), tuple(np.percentile(el, 90, axis=0))),
        WorkspaceBox(tuple(np.percentile(wr, 10, axis=0)), tuple(np.percentile(wr, 90, axis=0))),
    )
    config = KinematicsConfig(model=model, workspace=ws, calibration=calib)
    est = estimate_kinematics(q_ua, q_fa, t_ns, config)
    con = est.constrained
    assert np.isfinite(con.q_rad).all()
    assert 0.2 < con.any_active.mean() < 1.0
    lo, hi = JointLimits().as_rad()
    assert np.all(con.q_rad >= lo) and np.all(con.q_rad <= hi)
    fk = forward_kinematics(con.q_rad, model)
    assert ws.elbow.contains(fk.elbow_m, 1e-6).all() and ws.wrist.contains(fk.wrist_m, 1e-6).all()
    # (the clusters are not on the segment axes and there is no static posture, so the angles are
    # not anatomical here: only the solver's properties are checked, not their values)
    # per-sample optimality against SciPy SLSQP from the same warm start
    from imulog.process.kinematics.calibration import segment_rotations

    r_ua = segment_rotations(q_ua, est.q_global_to_trunk["upper_arm"])
    r_fa = segment_rotations(q_fa, est.q_global_to_trunk["forearm"])
    rng = np.random.default_rng(0)
    for k in rng.choice(np.arange(1, len(t_ns)), 10, replace=False):
        _, f_ref = solve_sample_scipy(r_ua[k], r_fa[k], model, constrained=True, workspace=ws, q0_rad=con.q_rad[k - 1])
        assert con.cost_rad2[k] <= f_ref + 1e-6
