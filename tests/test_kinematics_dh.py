"""DH model of Caruso et al. 2024: forward kinematics against the paper's closed forms, Jacobians."""

from __future__ import annotations

import math

import numpy as np
import pytest

from imulog.process.kinematics.dh import JOINT_NAMES, ArmModel, JointLimits, forward_kinematics, jacobians


def test_planar_case_matches_appendix_a_equations():
    """Appendix A, eqs. (9) and (13): elevation 90 deg, delta = carrying angle = axial = prono = 0."""
    model = ArmModel(upper_arm_length_m=0.3, forearm_length_m=0.3, styloid_distance_m=0.0, carrying_angle_deg=0.0)
    rng = np.random.default_rng(1)
    for t1, t4 in rng.uniform(-2.0, 2.0, (20, 2)):
        fk = forward_kinematics(np.array([t1, math.pi / 2, 0.0, t4, 0.0]), model)
        s1, c1 = math.sin(t1), math.cos(t1)
        s14, c14 = math.sin(t1 + t4), math.cos(t1 + t4)
        np.testing.assert_allclose(fk.r_upper_arm, [[s1, c1, 0], [-c1, s1, 0], [0, 0, 1]], atol=1e-12)
        np.testing.assert_allclose(fk.r_forearm, [[s14, c14, 0], [-c14, s14, 0], [0, 0, 1]], atol=1e-12)
        np.testing.assert_allclose(fk.wrist_m, [0.3 * c1 + 0.3 * c14, 0.3 * s1 + 0.3 * s14, 0.0], atol=1e-12)


def test_trunk_frame_axes_and_segment_lengths():
    model = ArmModel(upper_arm_length_m=0.31, forearm_length_m=0.26, styloid_distance_m=0.05, carrying_angle_deg=12)
    # arm hanging (elevation 0): elbow straight below the shoulder (z up)
    fk = forward_kinematics(np.zeros(5), model)
    np.testing.assert_allclose(fk.elbow_m, [0, 0, -0.31], atol=1e-12)
    # elevation 90 deg: plane 0 -> lateral (+x), plane 90 -> anterior (+y)
    np.testing.assert_allclose(
        forward_kinematics(np.radians([0, 90, 0, 0, 0]), model).elbow_m, [0.31, 0, 0], atol=1e-12
    )
    np.testing.assert_allclose(
        forward_kinematics(np.radians([90, 90, 0, 0, 0]), model).elbow_m, [0, 0.31, 0], atol=1e-12
    )
    q = np.random.default_rng(2).uniform(-2, 2, (50, 5))
    fk = forward_kinematics(q, model)
    np.testing.assert_allclose(np.linalg.norm(fk.elbow_m, axis=1), 0.31, atol=1e-12)
    np.testing.assert_allclose(
        np.linalg.norm(fk.wrist_m - fk.elbow_m, axis=1), 0.26 / math.cos(model.delta_rad), atol=1e-12
    )
    for r in (fk.r_upper_arm, fk.r_forearm):
        np.testing.assert_allclose(np.einsum("nji,njk->nik", r, r), np.broadcast_to(np.eye(3), r.shape), atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    # the carrying angle is the fixed angle between the humerus and the forearm axis at full extension
    fk0 = forward_kinematics(np.zeros(5), ArmModel(styloid_distance_m=0.0, carrying_angle_deg=20.0))
    u = -fk0.elbow_m / np.linalg.norm(fk0.elbow_m)
    v = (fk0.elbow_m - fk0.wrist_m) / np.linalg.norm(fk0.elbow_m - fk0.wrist_m)
    assert math.degrees(math.acos(np.dot(u, v))) == pytest.approx(20.0, abs=1e-9)


def test_delta_follows_equation_1():
    m = ArmModel(forearm_length_m=0.3, styloid_distance_m=0.06)
    assert m.delta_rad == pytest.approx(math.atan(0.03 / 0.3))
    assert math.degrees(m.delta_rad) == pytest.approx(5.7, abs=0.05)  # the paper's "delta = 6 deg"


def test_analytic_jacobians_match_finite_differences():
    model = ArmModel()
    rng = np.random.default_rng(3)
    h = 1e-6
    for q in rng.uniform(-1.5, 1.5, (10, 5)):
        jac = jacobians(q, model)
        fk = forward_kinematics(q, model)
        for j in range(5):
            dq = np.zeros(5)
            dq[j] = h
            fp, fm = forward_kinematics(q + dq, model), forward_kinematics(q - dq, model)
            np.testing.assert_allclose((fp.elbow_m - fm.elbow_m) / (2 * h), jac["elbow"][:, j], atol=1e-7)
            np.testing.assert_allclose((fp.wrist_m - fm.wrist_m) / (2 * h), jac["wrist"][:, j], atol=1e-7)
            for key, r0, rp, rm in (
                ("omega_upper_arm", fk.r_upper_arm, fp.r_upper_arm, fm.r_upper_arm),
                ("omega_forearm", fk.r_forearm, fp.r_forearm, fm.r_forearm),
            ):
                w = ((rp - rm) / (2 * h)) @ r0.T  # [omega]x
                np.testing.assert_allclose([w[2, 1], w[0, 2], w[1, 0]], jac[key][:, j], atol=1e-7)


def test_joint_limits_default_to_table_1():
    lo, hi = JointLimits().as_rad()
    pi = math.pi
    np.testing.assert_allclose(lo, [-2 * pi / 3, 0, -2 * pi / 3, 0, 0])
    np.testing.assert_allclose(hi, [2 * pi / 3, 11 * pi / 12, 2 * pi / 3, 5 * pi / 6, pi])
    limits = JointLimits.from_metadata({"joint_limits_deg": {"elevation": [10, 100]}})
    assert limits.elevation_deg == (10.0, 100.0) and limits.flexion_extension_deg == (0.0, 150.0)
    with pytest.raises(ValueError, match="unknown joint"):
        JointLimits.from_metadata({"joint_limits_deg": {"wrist": [0, 1]}})
    with pytest.raises(ValueError, match="lower"):
        JointLimits(elevation_deg=(10.0, 0.0))
    assert len(JOINT_NAMES) == 5


def test_model_from_metadata_and_validation():
    m = ArmModel.from_metadata({"upper_arm_length_m": 0.28, "carrying_angle_deg": 10, "subject": "x"})
    assert (m.upper_arm_length_m, m.forearm_length_m, m.carrying_angle_deg) == (0.28, 0.30, 10.0)
    with pytest.raises(ValueError):
        ArmModel(upper_arm_length_m=0.0)
    with pytest.raises(ValueError, match="columns"):
        forward_kinematics(np.zeros(6))
