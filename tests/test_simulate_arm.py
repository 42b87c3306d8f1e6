"""``imulog simulate arm``: raw exports that ``imulog convert`` turns back into the simulated two-IMU trial,
and kinematics on the converted trial against the written true joint angles."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.process import quaternion as quat
from imulog.process.kinematics.dh import JOINT_NAMES
from imulog.process.kinematics.errors import rms_deg
from imulog.simulate.arm import load_arm_truth, main, save_arm_truth, simulate_arm
from imulog.simulate.imu_model import EARTH_G

SECONDS, SEED = 20.0, 2
STEM = "arm_s00_t00"


def _run(*args) -> str:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    """``imulog simulate arm`` into a folder, then ``imulog convert`` of the folder."""
    root = tmp_path_factory.mktemp("arm")
    _run("simulate", "arm", "-o", root / "sim", "--seconds", SECONDS, "--seed", SEED)
    out = _run("convert", root / "sim", "-o", root / "trials")
    assert "wrote 1 trial(s)" in out  # the IMU file and the Vicon file group into one trial
    return root / "sim", root / "trials" / f"{STEM}.mcap"


def _kinematics_cli(path: Path) -> dict[str, np.ndarray]:
    _run("process", "orientation", path, "--imu", "upper_arm")
    _run("process", "orientation", path, "--imu", "forearm")
    _run("process", "kinematics", path)
    with TrialReader(path) as trial:
        return {
            kind: trial.read(f"/derived/kinematics/joint_angles_{kind}").values
            for kind in ("unconstrained", "constrained", "reference")
        } | {"errors": trial.metadata["imulog.kinematics_errors"]}


def test_converted_trial_is_the_simulated_recording(converted):
    sim_dir, path = converted
    names = sorted(p.name for p in sim_dir.iterdir())
    assert names == sorted(
        f"{STEM}{s}" for s in ("_imu.csv", "_imu.mapping.json", "_vicon.csv", "_meta.json", "_truth.json", "_truth.npz")
    )
    sim = simulate_arm(seed=SEED, duration_s=SECONDS)
    truth = load_arm_truth(sim_dir / f"{STEM}_truth.json")
    np.testing.assert_array_equal(truth.q_rad, sim.truth.q_rad)
    with TrialReader(path) as trial:
        channels = {c.topic: c for c in trial.channels}
        meta = trial.metadata
        imus = {name: trial.read(f"/imu/{name}") for name in ("upper_arm", "forearm")}
        markers = trial.read("/markers/vicon")
    assert {"/imu/upper_arm", "/imu/forearm", "/markers/vicon"} <= set(channels)
    # sample counts and rates of the truth
    truth_rate = 1e9 / np.median(np.diff(truth.t_ns))
    for topic in ("/imu/upper_arm", "/imu/forearm", "/markers/vicon"):
        assert channels[topic].sample_count == len(truth.t_ns)
        assert channels[topic].rate_hz == pytest.approx(truth_rate, rel=1e-9)
    # every value and time stamp as simulated (the writers print exact decimals)
    for s in sim.recording.imus:
        np.testing.assert_array_equal(imus[s.name].t_ns, truth.t_ns)
        for q in ("acc", "gyr", "mag"):
            np.testing.assert_array_equal(getattr(imus[s.name], q), getattr(s, q))
    m = sim.recording.markers[0]
    assert markers.labels == m.labels == [f"{s}_{k}" for s in ("upper_arm", "forearm") for k in "OXYA"]
    np.testing.assert_array_equal(markers.t_ns, m.t_ns)
    np.testing.assert_array_equal(markers.pos, m.pos)  # NaN gaps in the same places
    assert np.isnan(m.pos).any()
    # the meta file's nested records come back through convert's sibling <stem>_meta.json
    for record in ("imulog.trial", "imulog.anthropometrics", "imulog.kinematics"):
        assert meta[record] == json.loads(json.dumps(sim.recording.metadata[record])), record
    assert meta["imulog.kinematics"]["clusters"]["forearm"] == ["forearm_O", "forearm_X", "forearm_Y"]


def test_kinematics_on_converted_trial_matches_truth_and_in_memory_trial(converted, tmp_path):
    sim_dir, path = converted
    truth = load_arm_truth(sim_dir / STEM)
    got = _kinematics_cli(path)
    # the bounds of tests/test_kinematics_sim.py and test_kinematics_step.py (in-memory trials)
    assert rms_deg(np.radians(got["unconstrained"]), truth.q_rad).max() < 3.0
    assert rms_deg(np.radians(got["constrained"]), truth.q_rad).max() < 3.0
    assert rms_deg(np.radians(got["reference"]), truth.q_rad).max() < 1.0
    assert set(got["errors"]["e_tot_con_deg"]) == set(JOINT_NAMES)
    # the in-memory recording, archived directly, gives the same angles and marker reference
    sim = simulate_arm(seed=SEED, duration_s=SECONDS)
    direct = write_trial(tmp_path / "direct.mcap", sim.recording, attach_sources=False)
    want = _kinematics_cli(direct)
    for kind in ("unconstrained", "constrained", "reference"):
        np.testing.assert_allclose(got[kind], want[kind], atol=1e-9, equal_nan=True)


def test_trunk_imu_noise_free_files_convert_with_meta_file(tmp_path):
    _run("simulate", "arm", "-o", tmp_path, "--seconds", 6, "--seed", 4, "--trunk-imu", "--noise-free")
    out = tmp_path / "arm.mcap"
    files = [tmp_path / f"{STEM}_imu.csv", tmp_path / f"{STEM}_vicon.csv"]
    _run("convert", *files, "--meta-file", tmp_path / f"{STEM}_meta.json", "-o", out)
    sim = simulate_arm(seed=4, duration_s=6.0, trunk_imu=True, noise_free=True)
    with TrialReader(out) as trial:
        imus = [t.split("/")[-1] for t in trial.topics() if t.startswith("/imu/")]
        markers = trial.read("/markers/vicon")
        kin = trial.metadata["imulog.kinematics"]
        trunk = trial.read("/imu/trunk")
        trial_acc = {name: trial.read(f"/imu/{name}").acc for name in ("upper_arm", "forearm", "trunk")}
    assert sorted(imus) == ["forearm", "trunk", "upper_arm"]
    assert kin["trunk_imu"] == "trunk" and kin["clusters"]["trunk"] == ["trunk_O", "trunk_X", "trunk_Y"]
    assert not np.isnan(markers.pos).any()  # noise-free: no occlusion gaps
    np.testing.assert_array_equal(trunk.gyr, sim.recording.imus[2].gyr)
    truth = load_arm_truth(tmp_path / f"{STEM}_truth.npz")
    assert sorted(truth.q_world_sensor) == ["forearm", "trunk", "upper_arm"]
    # in the still neutral posture the noise-free accelerometers read gravity through the true orientations
    still = truth.t_ns < 2.5e9
    for name in ("upper_arm", "forearm", "trunk"):
        acc = trial_acc[name][still]
        g_sensor = quat.rotate_inverse(truth.q_world_sensor[name][still], np.tile([0.0, 0.0, EARTH_G], (len(acc), 1)))
        np.testing.assert_allclose(acc, g_sensor, atol=1e-6)


def test_seed_subjects_and_errors(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    _run("simulate", "arm", "-o", a, "--seconds", 5, "--subjects", 2)
    _run("simulate", "arm", "-o", b, "--seconds", 5, "--subjects", 2)
    for stem in ("arm_s00_t00", "arm_s01_t00"):
        for suffix in ("_imu.csv", "_vicon.csv", "_meta.json", "_truth.json"):
            assert (a / f"{stem}{suffix}").read_bytes() == (b / f"{stem}{suffix}").read_bytes()
    assert (a / "arm_s00_t00_imu.csv").read_bytes() != (a / "arm_s01_t00_imu.csv").read_bytes()
    assert json.loads((a / "arm_s01_t00_meta.json").read_text())["imulog.trial"]["subject"] == "S01"
    runner = CliRunner()
    bad = runner.invoke(cli, ["simulate", "arm", "-o", str(tmp_path), "--set", "duraton_s=5"])
    assert bad.exit_code != 0 and "did you mean duration_s" in bad.output and "Traceback" not in bad.output
    bad = runner.invoke(cli, ["simulate", "arm", "-o", str(tmp_path), "--repetitions", "3"])
    assert bad.exit_code != 0 and "--seconds" in bad.output
    bad = runner.invoke(cli, ["simulate", "r2g", "-o", str(tmp_path), "--trunk-imu"])
    assert bad.exit_code != 0 and "arm protocol only" in bad.output
    listed = runner.invoke(cli, ["simulate", "arm", "-o", str(tmp_path), "--list-parameters"])
    assert "workspace_margin_m" in listed.output and "gyr_noise_dps" in listed.output


def test_imu_parameters_reach_the_model_and_truth_round_trips(tmp_path):
    quiet = simulate_arm(seed=1, duration_s=5.0, gyr_noise_dps=0.0, gyr_bias_rw_dps_per_sqrt_s=0.0)
    loud = simulate_arm(seed=1, duration_s=5.0, gyr_noise_dps=1.0, gyr_bias_rw_dps_per_sqrt_s=0.0)
    still = (quiet.truth.t_ns < 2.5e9)[:, None]
    assert np.std(loud.recording.imus[0].gyr, axis=0, where=still).min() > np.radians(0.5)
    assert np.std(quiet.recording.imus[0].gyr, axis=0, where=still).max() < np.radians(0.2)
    npz, js = save_arm_truth(quiet.truth, tmp_path / "x")
    back = load_arm_truth(js)
    for name in ("t_ns", "q_rad", "r_forearm", "elbow_m", "q_world_trunk"):
        np.testing.assert_array_equal(getattr(back, name), getattr(quiet.truth, name))
    np.testing.assert_array_equal(back.q_world_sensor["forearm"], quiet.truth.q_world_sensor["forearm"])
    with pytest.raises(TypeError, match="did you mean"):
        simulate_arm(duraton_s=5.0)


def test_module_entry_point_still_writes_mcap(tmp_path):
    main([str(tmp_path / "arm.mcap"), "--seconds", "5", "--seed", "1"])
    with TrialReader(tmp_path / "arm.mcap") as trial:
        assert {"/imu/upper_arm", "/imu/forearm", "/markers/vicon"} <= set(trial.topics())
        assert trial.metadata["imulog.kinematics"]["upper_arm_imu"] == "upper_arm"
