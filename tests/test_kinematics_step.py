"""`imulog process kinematics` on archived simulated arm trials: channels, errors, provenance, CLI."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.model import PoseStream, SignalStream
from imulog.process.kinematics.dh import JOINT_NAMES, ArmModel, JointLimits, forward_kinematics
from imulog.process.kinematics.errors import rms_deg
from imulog.process.kinematics.solver import Workspace
from imulog.simulate.arm import simulate_arm
from imulog.steps.kinematics import KinematicsOptions, run_kinematics


@pytest.fixture(scope="module")
def arm_trial(tmp_path_factory):
    sim = simulate_arm(seed=7, duration_s=30.0)
    path = write_trial(tmp_path_factory.mktemp("arm") / "arm.mcap", sim.recording, attach_sources=False)
    return sim, path


def test_step_writes_angles_poses_mask_and_errors(arm_trial):
    sim, path = arm_trial
    outcome = run_kinematics(path)
    assert not outcome.skipped
    assert run_kinematics(path).skipped  # same inputs and parameters: nothing written
    with TrialReader(path) as trial:
        un = trial.read("/derived/kinematics/joint_angles_unconstrained")
        con = trial.read("/derived/kinematics/joint_angles_constrained")
        ref = trial.read("/derived/kinematics/joint_angles_reference")
        elbow = trial.read("/derived/kinematics/elbow")
        wrist = trial.read("/derived/kinematics/wrist")
        mask = trial.read("/derived/kinematics/constraint_active")
        meta = trial.metadata
    assert isinstance(con, SignalStream) and con.columns == list(JOINT_NAMES) and set(con.units) == {"deg"}
    assert isinstance(elbow, PoseStream) and elbow.frame_id == "trunk"
    np.testing.assert_array_equal(con.t_ns, sim.recording.imus[0].t_ns)
    truth = sim.truth.q_rad
    assert rms_deg(np.radians(un.values), truth).max() < 3.0
    assert rms_deg(np.radians(con.values), truth).max() < 3.0
    # the marker reference (same solver on the clusters) is close to the truth
    assert rms_deg(np.radians(ref.values), truth).max() < 1.0
    # poses are the forward kinematics of the constrained angles, inside the boxes of the metadata
    model = ArmModel.from_metadata(meta["imulog.anthropometrics"])
    fk = forward_kinematics(np.radians(con.values), model)
    np.testing.assert_allclose(elbow.position, fk.elbow_m, atol=1e-9)
    np.testing.assert_allclose(wrist.position, fk.wrist_m, atol=1e-9)
    ws = Workspace.from_metadata(meta["imulog.kinematics"])
    assert ws.elbow.contains(elbow.position, 1e-6).all() and ws.wrist.contains(wrist.position, 1e-6).all()
    lo, hi = JointLimits().as_rad()
    assert np.all(np.radians(con.values) >= lo - 1e-12) and np.all(np.radians(con.values) <= hi + 1e-12)
    cols = {c: mask.values[:, i] for i, c in enumerate(mask.columns)}
    assert cols["active"].mean() > 0.01
    # wherever the unconstrained centres left the workspace, the constrained solution sits on a constraint
    out = cols["outside_unconstrained"] == 1
    assert out.any() and np.all(cols["active"][out] == 1)
    err = meta["imulog.kinematics_errors"]
    assert set(err["e_tot_un_deg"]) == set(JOINT_NAMES)
    assert err["t_out_fraction"] == pytest.approx(out.mean(), abs=0.02)
    # e_tot equals the RMS between the written series
    np.testing.assert_allclose(
        [err["e_tot_con_deg"][j] for j in JOINT_NAMES],
        rms_deg(np.radians(con.values), np.radians(ref.values)),
        rtol=1e-9,
    )
    assert meta["imulog.kinematics_calibration"]["ms_per_sample"]["constrained"] < 5.0


def test_step_uses_the_orientation_step_output_when_present(tmp_path):
    from imulog.steps.orientation import run_orientation

    sim = simulate_arm(seed=8, duration_s=12.0)
    path = write_trial(tmp_path / "arm.mcap", sim.recording, attach_sources=False)
    for imu in ("upper_arm", "forearm"):
        run_orientation(path, imu=imu)
    outcome = run_kinematics(path, options=KinematicsOptions(use_markers=False))
    topics = {k for k in outcome.input_hashes if not k.startswith("metadata:")}
    assert topics == {"/derived/orientation/upper_arm", "/derived/orientation/forearm"}
    assert "metadata:imulog.kinematics" in outcome.input_hashes
    with TrialReader(path) as trial:
        con = trial.read("/derived/kinematics/joint_angles_constrained")
        assert "imulog.kinematics_errors" not in trial.metadata
    assert rms_deg(np.radians(con.values), sim.truth.q_rad).max() < 3.0


def test_cli_prints_errors_and_fails_clearly(arm_trial, tmp_path):
    sim, _ = arm_trial
    path = write_trial(tmp_path / "cli.mcap", sim.recording, attach_sources=False)
    runner = CliRunner()
    res = runner.invoke(cli, ["process", "kinematics", str(path)])
    assert res.exit_code == 0, res.output
    assert "e_tot_un" in res.output and "flexion_extension" in res.output and "ms/sample" in res.output
    res = runner.invoke(cli, ["process", "kinematics", str(path), "--upper-arm", "shoulder"])
    assert res.exit_code == 1 and "no channel /imu/shoulder" in res.output
    res = runner.invoke(cli, ["process", "kinematics", str(path), "--neutral-window", "0.5"])
    assert res.exit_code == 2 and "--neutral-window" in res.output
    res = runner.invoke(cli, ["process", "kinematics", str(path), "--neutral-window", "100,101", "--force"])
    assert res.exit_code == 1 and "neutral window" in res.output
    res = runner.invoke(cli, ["process", "kinematics", "--help"])
    assert res.exit_code == 0 and "Examples" in res.output


def test_step_with_a_trunk_imu(tmp_path):
    sim = simulate_arm(seed=9, duration_s=15.0, trunk_imu=True, trunk_sway_deg=12.0)
    path = write_trial(tmp_path / "sway.mcap", sim.recording, attach_sources=False)
    outcome = run_kinematics(path)
    assert "/imu/trunk" in outcome.input_hashes
    with TrialReader(path) as trial:
        con = trial.read("/derived/kinematics/joint_angles_constrained")
        ref = trial.read("/derived/kinematics/joint_angles_reference")
        assert trial.metadata["imulog.kinematics_calibration"]["trunk_imu"] == "trunk"
    assert rms_deg(np.radians(con.values), sim.truth.q_rad).max() < 3.0
    assert rms_deg(np.radians(ref.values), sim.truth.q_rad).max() < 1.0
    # --trunk '' falls back to a still trunk: the shoulder angles degrade
    run_kinematics(path, options=KinematicsOptions(trunk=""), force=True)
    with TrialReader(path) as trial:
        still = trial.read("/derived/kinematics/joint_angles_unconstrained")
    assert rms_deg(np.radians(still.values[:, :3]), sim.truth.q_rad[:, :3]).max() > 2.0


def test_windows_give_the_angles_of_the_whole(arm_trial, tmp_path):
    """Cut into 7-s windows (calibrated on the first, each warm-started from the previous one's last solution),
    the trial gives the one-window angles, poses and constraint flags sample by sample; no length refusal."""
    import shutil

    from imulog.steps.orientation import run_orientation
    from imulog.steps.windows import WindowParams

    _, path = arm_trial
    one, cut = tmp_path / "one.mcap", tmp_path / "cut.mcap"
    shutil.copy(path, one)
    for name in ("upper_arm", "forearm"):
        run_orientation(one, imu=name)
    shutil.copy(one, cut)
    # without orientation channels (computed in memory: at once for one window, core by core as the orientation
    # step would for several) the windows give the one-window angles too: no refusal for length
    bare_one, bare_cut = tmp_path / "bare_one.mcap", tmp_path / "bare_cut.mcap"
    shutil.copy(path, bare_one)
    shutil.copy(path, bare_cut)
    run_kinematics(bare_one, options=KinematicsOptions(use_markers=False))
    cut_7s = WindowParams(core_s=7.0, margin_s=0.0)
    run_kinematics(bare_cut, options=KinematicsOptions(use_markers=False), windows=cut_7s)
    with TrialReader(bare_one) as b, TrialReader(bare_cut) as c:
        assert "/derived/orientation/upper_arm" not in c.topics()
        assert c.metadata["imulog.kinematics_calibration"]["windows"] == 5
        for kind in ("joint_angles_unconstrained", "joint_angles_constrained", "constraint_active"):
            x, y = b.read(f"/derived/kinematics/{kind}"), c.read(f"/derived/kinematics/{kind}")
            np.testing.assert_array_equal(x.t_ns, y.t_ns)
            np.testing.assert_allclose(x.values, y.values, atol=1e-6 if kind.startswith("joint") else 1e-9)
    run_kinematics(one, options=KinematicsOptions(use_markers=False))
    run_kinematics(cut, options=KinematicsOptions(use_markers=False), windows=cut_7s)
    with TrialReader(one) as a, TrialReader(cut) as b:
        assert b.metadata["imulog.kinematics_calibration"]["windows"] == 5
        assert (
            b.metadata["imulog.kinematics_calibration"]["q_global_to_trunk"]
            == (a.metadata["imulog.kinematics_calibration"]["q_global_to_trunk"])
        )
        for kind in ("joint_angles_unconstrained", "joint_angles_constrained", "constraint_active"):
            x, y = a.read(f"/derived/kinematics/{kind}"), b.read(f"/derived/kinematics/{kind}")
            np.testing.assert_array_equal(x.t_ns, y.t_ns)
            # angles (deg): the solver stops when a step is below 1e-9 rad, so two starts (warm from the previous
            # window or not) agree to a few of those steps, 1e-6 deg = 1.7e-8 rad; flags and poses exactly below
            np.testing.assert_allclose(x.values, y.values, atol=1e-6 if kind.startswith("joint") else 1e-9)
        np.testing.assert_allclose(
            a.read("/derived/kinematics/wrist").position, b.read("/derived/kinematics/wrist").position, atol=1e-9
        )
