"""Per-sample solver: the paper's Appendix A cases, exact recovery, feasibility, agreement with SciPy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from imulog.process import quaternion as quat
from imulog.process.kinematics.dh import ArmModel, JointLimits, forward_kinematics
from imulog.process.kinematics.errors import kinematics_errors, outside_workspace, rms_deg
from imulog.process.kinematics.solver import Workspace, WorkspaceBox, solve_sample_scipy, solve_sequence


def _rz(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])


# Appendix A (eq. 12 and Table 3): elevation pinned at 90 deg, axial/prono/carrying/delta 0;
# l_UA = l_FA = 0.3 m; phi_UA = -40 deg, phi_FA = 135 deg.
PLANAR = ArmModel(0.3, 0.3, 0.0, 0.0)
FREE = JointLimits((-180, 180), (90, 90), (0, 0), (-10, 200), (0, 0))
G1 = JointLimits((-90, 60), (90, 90), (0, 0), (0, 150), (0, 0))
G2 = Workspace(wrist=WorkspaceBox((-0.16, 0.22, None), (-0.06, 0.32, None)))


@pytest.mark.parametrize(
    ("case", "limits", "workspace", "theta1", "theta4", "f_obj"),
    [
        ("a", FREE, Workspace(), 50, 175, 0.0),
        ("b", G1, Workspace(), 60, 150, 0.10),
        ("c", FREE, G2, 63, 126, 0.45),
        ("d", G1, G2, 60, 128, 0.46),
    ],
)
def test_appendix_a_table_3(case, limits, workspace, theta1, theta4, f_obj):
    res = solve_sequence(
        _rz(-40)[None],
        _rz(135)[None],
        PLANAR,
        constrained=True,
        limits=limits,
        workspace=workspace,
        q0_rad=np.radians([0, 90, 0, 90, 0]),
    )
    q = np.degrees(res.q_rad[0])
    # Table 3 rounds angles to whole degrees and f_obj to 0.01 rad^2
    assert q[0] == pytest.approx(theta1, abs=0.5), case
    assert q[3] == pytest.approx(theta4, abs=0.5), case
    assert res.cost_rad2[0] == pytest.approx(f_obj, abs=0.006), case


def _trajectory(n: int = 1500, seed: int = 0) -> np.ndarray:
    t = np.arange(n) / 100.0
    rng = np.random.default_rng(seed)
    f = rng.uniform(0.1, 0.4, 5)
    c = np.radians([40, 60, 10, 70, 80])
    a = np.radians([50, 40, 60, 60, 70])
    return c + a * np.sin(2 * np.pi * np.outer(t, f) + rng.uniform(0, 6, 5))


def _perturb(r: np.ndarray, sd_deg: float, rng: np.random.Generator) -> np.ndarray:
    dq = quat.from_rotation_vector(rng.normal(0.0, math.radians(sd_deg), (len(r), 3)))
    return quat.to_rotation_matrix(dq) @ r


@pytest.mark.parametrize("constrained", [False, True])
def test_perfect_orientations_give_the_true_angles(constrained):
    q = _trajectory()
    model = ArmModel(0.29, 0.26, 0.05, 17.0)
    fk = forward_kinematics(q, model)
    # default start (neutral + restarts): the solver must find the true branch by itself
    res = solve_sequence(fk.r_upper_arm, fk.r_forearm, model, constrained=constrained)
    assert np.max(np.abs(np.degrees(res.q_rad - q))) < 1e-6
    assert np.all(res.cost_rad2 < 1e-16)


def test_constrained_solution_never_leaves_limits_or_boxes_and_matches_scipy():
    rng = np.random.default_rng(5)
    q = _trajectory(2000, seed=1)
    model = ArmModel()
    fk = forward_kinematics(q, model)
    ws = Workspace(
        WorkspaceBox(tuple(fk.elbow_m.min(0)), tuple(fk.elbow_m.max(0))),
        WorkspaceBox(tuple(fk.wrist_m.min(0)), tuple(fk.wrist_m.max(0))),
    )
    r_ua, r_fa = _perturb(fk.r_upper_arm, 4.0, rng), _perturb(fk.r_forearm, 4.0, rng)
    un = solve_sequence(r_ua, r_fa, model, q0_rad=q[0])
    con = solve_sequence(r_ua, r_fa, model, constrained=True, workspace=ws, q0_rad=q[0])
    lo, hi = JointLimits().as_rad()
    assert np.all(con.q_rad >= lo) and np.all(con.q_rad <= hi)
    fkc = forward_kinematics(con.q_rad, model)
    assert ws.elbow.contains(fkc.elbow_m, tol_m=1e-6).all()
    assert ws.wrist.contains(fkc.wrist_m, tol_m=1e-6).all()
    # the noise pushes the unconstrained centres out often: the constraints really are exercised
    fku = forward_kinematics(un.q_rad, model)
    t_out = outside_workspace(fku.elbow_m, fku.wrist_m, ws)
    assert 0.1 < t_out.mean() < 0.9
    assert con.any_active[t_out].all()
    # a constrained optimum can never fit the orientations better than the unconstrained one
    assert np.all(con.cost_rad2 >= un.cost_rad2 - 1e-12)
    # where nothing is active both solutions coincide
    free = ~con.any_active
    assert np.max(np.abs(con.q_rad[free] - un.q_rad[free])) < 1e-6
    # the per-sample optimum is at least as good as SciPy's SLSQP / BFGS from the same warm start
    for k in rng.choice(np.arange(1, len(q)), 12, replace=False):
        _, f_ref = solve_sample_scipy(r_ua[k], r_fa[k], model, constrained=True, workspace=ws, q0_rad=con.q_rad[k - 1])
        assert con.cost_rad2[k] <= f_ref + 1e-6
        _, f_ref = solve_sample_scipy(r_ua[k], r_fa[k], model, q0_rad=un.q_rad[k - 1])
        assert un.cost_rad2[k] <= f_ref + 1e-8


def test_nan_samples_are_skipped_and_keep_the_warm_start():
    q = _trajectory(300)
    fk = forward_kinematics(q, ArmModel())
    r_ua = fk.r_upper_arm.copy()
    r_ua[100:120] = np.nan
    res = solve_sequence(r_ua, fk.r_forearm, ArmModel(), constrained=True, q0_rad=q[0])
    assert np.isnan(res.q_rad[100:120]).all()
    ok = np.ones(len(q), bool)
    ok[100:120] = False
    assert np.max(np.abs(res.q_rad[ok] - q[ok])) < 1e-8


def test_error_metrics_follow_section_ii_f():
    ref = np.radians(np.tile([10.0, 20, 30, 40, 50], (10, 1)))
    un = ref + np.radians(2.0)
    con = ref + np.radians(1.0)
    t_out = np.zeros(10, bool)
    t_out[:4] = True
    un[:4, 0] += np.radians(6.0)  # larger error only in t_out, plane of elevation
    e = kinematics_errors(un, con, ref, t_out)
    assert e["e_tot_con_deg"]["elevation"] == pytest.approx(1.0)
    assert e["e_out_un_deg"]["plane_of_elevation"] == pytest.approx(8.0)
    assert e["e_tot_un_deg"]["plane_of_elevation"] == pytest.approx(math.sqrt((4 * 64 + 6 * 4) / 10))
    assert e["t_out_fraction"] == pytest.approx(0.4)
    # wrapped differences: 359 deg vs 1 deg is a 2 deg error
    assert rms_deg(np.radians([[359.0]]), np.radians([[1.0]]))[0] == pytest.approx(2.0)


def test_workspace_box_validation_and_round_trip():
    box = WorkspaceBox((0.0, None, -1.0), (1.0, 2.0, None))
    assert box.as_list() == [[0.0, None, -1.0], [1.0, 2.0, None]]
    assert WorkspaceBox.from_list(box.as_list()) == box
    with pytest.raises(ValueError, match="exceeds"):
        WorkspaceBox((1.0, 0, 0), (0.0, 1, 1))
    with pytest.raises(ValueError, match="N, 3, 3"):
        solve_sequence(np.zeros((3, 4)), np.zeros((3, 4)))


def _gradient(q: np.ndarray, r_ua: np.ndarray, r_fa: np.ndarray, model: ArmModel) -> tuple[float, np.ndarray]:
    """(f rad^2, J'r = the gradient of f / 2) at ``q`` from the forward kinematics and joint-axis Jacobians."""
    from imulog.process.kinematics.dh import jacobians

    fk = forward_kinematics(q, model)
    r = np.concatenate(
        [
            quat.to_rotation_vector(quat.from_rotation_matrix(fk.r_upper_arm @ r_ua.T)),
            quat.to_rotation_vector(quat.from_rotation_matrix(fk.r_forearm @ r_fa.T)),
        ]
    )
    j = jacobians(q, model)
    return float(r @ r), j["omega_upper_arm"].T @ r[:3] + j["omega_forearm"].T @ r[3:]


def test_newton_matrix_is_the_hessian_of_the_cost():
    """The exact Hessian the solver steps with equals central differences of J'r (and J'r those of f / 2)."""
    from imulog.process.kinematics.dh import jacobians
    from imulog.process.kinematics.solver_core import _newton_matrix

    rng = np.random.default_rng(3)
    model = ArmModel(0.29, 0.26, 0.05, 17.0)
    checked = definite = 0
    for _ in range(60):
        q = rng.uniform(-1.5, 1.5, 5)
        r_ua, r_fa = quat.to_rotation_matrix(quat.from_rotation_vector(rng.normal(0.0, 0.8, (2, 3))))
        f, g = _gradient(q, r_ua, r_fa, model)
        fk = forward_kinematics(q, model)
        r = np.concatenate(
            [
                quat.to_rotation_vector(quat.from_rotation_matrix(fk.r_upper_arm @ r_ua.T)),
                quat.to_rotation_vector(quat.from_rotation_matrix(fk.r_forearm @ r_fa.T)),
            ]
        )
        if max(np.linalg.norm(r[:3]), np.linalg.norm(r[3:])) > 2.9:
            continue
        j = jacobians(q, model)
        h, ll = np.empty((5, 5)), np.empty((5, 5))
        definite += _newton_matrix(r, j["omega_upper_arm"], j["omega_forearm"], h, ll)
        e = 1e-6
        h_fd = np.empty((5, 5))
        g_fd = np.empty(5)
        for k in range(5):
            dq = np.zeros(5)
            dq[k] = e
            h_fd[:, k] = (_gradient(q + dq, r_ua, r_fa, model)[1] - _gradient(q - dq, r_ua, r_fa, model)[1]) / (2 * e)
            g_fd[k] = (_gradient(q + dq, r_ua, r_fa, model)[0] - _gradient(q - dq, r_ua, r_fa, model)[0]) / (4 * e)
        assert np.max(np.abs(g - g_fd)) < 1e-6
        assert np.max(np.abs(h - h_fd)) < 1e-5
        checked += 1
    assert checked >= 40 and 0 < definite < checked  # both branches: Newton's step and the Gauss-Newton fallback


def test_unconstrained_solutions_are_stationary_when_the_orientations_do_not_fit_the_model():
    """Segment orientations no arm can take (the forearm turned 60 deg off the model's): every sample still ends
    at a stationary point of f (J'r ~ 0), within the iteration bound."""
    q = _trajectory(1500, seed=2)
    model = ArmModel()
    fk = forward_kinematics(q, model)
    off = quat.to_rotation_matrix(quat.from_rotation_vector(np.radians([35.0, -40.0, 25.0])))
    r_fa = fk.r_forearm @ off
    res = solve_sequence(fk.r_upper_arm, r_fa, model, q0_rad=q[0])
    assert np.median(res.cost_rad2) > 0.1  # a large residual: the Newton and Gauss-Newton steps differ
    assert np.all(res.iterations < 50)
    worst = max(
        np.max(np.abs(_gradient(res.q_rad[k], fk.r_upper_arm[k], r_fa[k], model)[1])) for k in range(0, 1500, 7)
    )
    assert worst < 1e-8
