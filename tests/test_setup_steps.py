"""Whole setups (issue 27), the steps after orientation: one line on the heading frame after orienting several
IMUs and in ``info``, kinematics' clock from the IMU's own alignment record, trajectories and evaluation per IMU,
and the batch's per-IMU steps.

Real files: the APDM Opal CSV with four sensors (Static, Upper, Middle, Lower), the gaitmap sample's two feet
with their markers; and the simulated setup (:mod:`imulog.simulate.setup`)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.cli import cli


def run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


@pytest.fixture
def opals(shared_data, tmp_path):
    path = tmp_path / "opals.mcap"
    code, _, stderr = run("convert", shared_data / "devices" / "apdm_csv" / "imuData01.csv", "-o", path)
    assert code == 0, stderr
    return path


def _heading_line(stdout: str) -> str:
    lines = [line for line in stdout.splitlines() if line.startswith("heading:")]
    assert len(lines) == 1, stdout
    return lines[0]


def test_orientation_says_whether_the_imus_share_one_heading_frame(opals):
    code, stdout, stderr = run("process", "orientation", opals)
    assert code == 0, stderr
    # 6D: each its own heading; the Opals' own orientations (one recording) relate them, without `process heading`
    assert _heading_line(stdout).startswith("heading: one frame for static, upper, middle, lower: device")
    code, stdout, _ = run("info", opals)
    assert code == 0 and "heading: one frame" in stdout
    # a declared pose relates them: the same command now reports one frame
    code, stdout, stderr = run("process", "heading", opals, "--static-pose", "0.2,1.0")
    assert code == 0, stderr
    code, stdout, _ = run("process", "orientation", opals)
    assert _heading_line(stdout).startswith("heading: one frame for static, upper, middle, lower: static pose")
    # re-orienting two IMUs re-relates every oriented IMU, the declared pose kept
    code, stdout, _ = run("process", "orientation", opals, "--imu", "upper", "--imu", "lower", "--backend", "madgwick")
    assert code == 0 and _heading_line(stdout).startswith("heading: one frame for upper, lower: static pose")
    from imulog.archive import TrialReader

    with TrialReader(opals) as trial:
        assert set(trial.metadata["imulog.heading"]["imus"]) == {"static", "upper", "middle", "lower"}
    code, stdout, _ = run("process", "orientation", opals, "--imu", "upper")  # one IMU: no heading line
    assert code == 0 and "heading:" not in stdout


def test_kinematics_reads_the_arm_imus_own_alignment_record():
    """In a setup aligned as a whole, ``imulog.alignment`` is the first IMU's; the upper arm's clock is its own."""
    from imulog.steps.common import alignment_for, alignment_record
    from imulog.steps.kinematics import _reference_times

    first = {"imu": "/imu/forearm", "offset_ns": 5_000_000, "drift_ppm": 0.0}
    own = {"imu": "/imu/upper_arm", "offset_ns": -20_000_000, "drift_ppm": 0.0}

    class Trial:
        metadata = {"imulog.alignment": first, "imulog.alignment.upper_arm": own}

    t = np.arange(0, 10**9, 10**7, dtype=np.int64)
    assert alignment_record(Trial.metadata, "/imu/upper_arm") == "imulog.alignment.upper_arm"
    assert alignment_record(Trial.metadata, "/imu/forearm") == "imulog.alignment"
    assert alignment_for(Trial.metadata, "/imu/upper_arm")["offset_ns"] == -20_000_000
    shifted = _reference_times(Trial, "/imu/upper_arm", t)
    expected = _reference_times(type("T", (), {"metadata": {"imulog.alignment": own}}), "/imu/upper_arm", t)
    assert np.array_equal(shifted, expected) and not np.array_equal(shifted, t)
    assert np.array_equal(_reference_times(Trial, "/imu/trunk", t), t)  # no record for it: device clock


@pytest.fixture(scope="module")
def setup_trial(tmp_path_factory):
    """The simulated setup (upper arm, forearm, trunk IMUs, their clusters), oriented, aligned as a whole and
    segmented, every IMU by default."""
    from imulog.archive import write_trial
    from imulog.simulate.setup import simulate_setup

    path = write_trial(
        tmp_path_factory.mktemp("setup") / "setup.mcap", simulate_setup(seed=0, duration_s=40.0).recording
    )
    for step in ("orientation", "align", "phases"):
        code, _, stderr = run("process", step, path)
        assert code == 0, stderr
    return path


def test_trajectories_and_evaluation_per_imu(setup_trial, tmp_path):
    import shutil

    from imulog.archive import TrialReader

    path = shutil.copy(setup_trial, tmp_path / "t.mcap")
    code, stdout, stderr = run("process", "trajectory", path, "--method", "ddi,highpass")
    assert code == 0, stderr
    assert stdout.startswith(f"trajectory: 3 IMUs of {path}")
    with TrialReader(path) as trial:
        topics, meta = trial.topics(), trial.metadata
        runs = sorted(r["step"] for r in trial.runs().values() if r["step"].startswith("trajectory"))
        clocks = {t: trial.channel(t).metadata.get("clock") for t in topics if t.startswith("/derived/trajectory/")}
    imus = ("upper_arm", "forearm", "trunk")
    assert runs == sorted(f"trajectory:{n}" for n in imus)  # one provenance run per IMU
    for n in imus:
        assert {f"/derived/trajectory/{m}/{n}" for m in ("ddi", "highpass")} <= set(topics)
        assert f"/derived/trajectory_baseline/dedrift/{n}" in topics
    assert not any(t in topics for t in ("/derived/trajectory/ddi", "/derived/trajectory/highpass"))
    assert set(clocks.values()) == {"reference"}  # every IMU is on the station's shared clock
    # the aligned (primary) IMU keeps imulog.trajectory, the others their own record
    assert meta["imulog.trajectory"]["imu"] == "/imu/upper_arm"
    assert meta["imulog.trajectory.forearm"]["imu"] == "/imu/forearm"
    assert meta["imulog.trajectory.trunk"]["frame"] == "trunk_global"  # no cluster: no world frame
    assert meta["imulog.trajectory.forearm"]["frame"] == "world"
    code, stdout, _ = run("process", "trajectory", path, "--method", "ddi,highpass")
    assert code == 0 and stdout.count("unchanged") == 3
    # metrics' smoothness reads the IMU's own trajectory and cluster
    from imulog.steps.metrics import pick_trajectory

    assert pick_trajectory(topics, "", "forearm", meta) == "/derived/trajectory/highpass/forearm"
    assert pick_trajectory(topics, "vicon", "forearm", meta) == "/derived/vicon/cluster_pose/forearm"
    with pytest.raises(ValueError, match="/derived/trajectory/zupt/trunk"):
        pick_trajectory(topics, "zupt", "trunk", meta)
    # evaluate: every IMU against its own cluster; the trunk has none (the setup's IMU without a cluster)
    code, stdout, stderr = run("evaluate", path)
    assert code == 1 and "1 of 3 IMUs not evaluated: trunk" in stderr
    assert f"{path}: upper_arm: errors against /derived/vicon/cluster_pose/upper_arm" in stdout
    assert f"{path}: forearm: errors against /derived/vicon/cluster_pose/forearm" in stdout
    with TrialReader(path) as trial:
        meta = trial.metadata
        steps = sorted(r["step"] for r in trial.runs().values() if r["step"].startswith("evaluate"))
    assert steps == ["evaluate:forearm", "evaluate:upper_arm"]
    assert meta["imulog.evaluation"]["imu"] == "/imu/upper_arm"
    assert meta["imulog.evaluation.forearm"]["reference"] == "/derived/vicon/cluster_pose/forearm"
    # the two arms' errors differ: each was compared with its own trajectory and cluster
    mae = [meta[r]["methods"]["highpass"]["summary"] for r in ("imulog.evaluation", "imulog.evaluation.forearm")]
    assert mae[0] != mae[1]
    code, stdout, _ = run("evaluate", path, "--imu", "forearm", "--json")
    assert code == 0 and list(__import__("json").loads(stdout)["imus"]) == ["forearm"]
    # the catalog row keeps the primary IMU's evaluation and the others' under per_imu
    import json

    import pyarrow.parquet as pq

    from imulog.batch import build_catalog

    build_catalog(tmp_path, tmp_path / "catalog.parquet")
    row = pq.read_table(tmp_path / "catalog.parquet").to_pylist()[0]
    ev = json.loads(row["evaluation_json"])
    assert ev["imu"] == "/imu/upper_arm" and list(ev["per_imu"]) == ["forearm"]
    assert {"trajectory:forearm", "evaluate:forearm"} <= set(row["steps"])


def test_older_one_set_trajectories_of_a_setup_are_read_then_replaced(setup_trial, tmp_path, monkeypatch):
    """An archive written before per-IMU trajectories: one set, /derived/trajectory/METHOD, for the IMU its
    imulog.trajectory names. Evaluate reads it as that IMU's; the new step replaces it with the per-IMU set."""
    import shutil

    from imulog.archive import TrialReader
    from imulog.steps import trajectory as step
    from imulog.steps.evaluate import run_evaluate
    from imulog.steps.trajectory_topics import trajectories_by_imu

    path = shutil.copy(setup_trial, tmp_path / "old.mcap")
    monkeypatch.setattr(step, "per_imu_layout", lambda topics: False)  # the old layout
    step.run_trajectory(path, imu="forearm", methods=["highpass"])
    monkeypatch.undo()
    with TrialReader(path) as trial:
        topics, meta = trial.topics(), trial.metadata
    assert "/derived/trajectory/highpass" in topics and meta["imulog.trajectory"]["imu"] == "/imu/forearm"
    assert trajectories_by_imu(topics, meta) == {"forearm": {"highpass": "/derived/trajectory/highpass"}}
    from imulog.steps.metrics import pick_trajectory

    assert pick_trajectory(topics, "", "forearm", meta) == "/derived/trajectory/highpass"
    assert pick_trajectory(topics, "", "upper_arm", meta) == "/derived/vicon/cluster_pose/upper_arm"
    _, record = run_evaluate(path, strides=False)
    assert list(record["imus"]) == ["forearm"]
    assert record["imus"]["forearm"]["reference"] == "/derived/vicon/cluster_pose/forearm"
    step.run_trajectory(path, imu="forearm", methods=["highpass"])
    with TrialReader(path) as trial:
        topics = trial.topics()
    assert "/derived/trajectory/highpass/forearm" in topics and "/derived/trajectory/highpass" not in topics


def test_batch_runs_the_per_imu_steps_on_every_imu(tmp_path):
    """The batch on a setup: orientation, phases and trajectory once per IMU (step:IMU runs), as the commands;
    a second pass is up to date; ``imu=NAME`` still runs one."""
    from imulog.archive import TrialReader, write_trial
    from imulog.batch import run_file
    from imulog.simulate.setup import simulate_setup

    path = write_trial(tmp_path / "setup.mcap", simulate_setup(seed=1, duration_s=30.0).recording)
    plan = [("orientation", {}), ("align", {}), ("phases", {}), ("trajectory", {"methods": "ddi,highpass"})]
    result = run_file(str(path), plan)
    assert result.status == "processed", result.error
    assert [s.step for s in result.steps] == ["orientation", "align", "phases", "trajectory"]
    with TrialReader(path) as trial:
        steps = sorted(r["step"] for r in trial.runs().values())
        topics = trial.topics()
    for name in ("upper_arm", "forearm", "trunk"):
        for step in ("orientation", "phases", "trajectory"):
            assert f"{step}:{name}" in steps
        assert f"/derived/trajectory/highpass/{name}" in topics
    again = run_file(str(path), plan)
    assert again.status == "up_to_date" and all(s.skipped for s in again.steps)
    one = run_file(str(path), [("orientation", {"imu": "trunk", "backend": "madgwick"})])
    assert one.status == "processed"
    with TrialReader(path) as trial:
        assert sum(r["step"] == "orientation:trunk" for r in trial.runs().values()) == 2
        assert sum(r["step"] == "orientation:forearm" for r in trial.runs().values()) == 1


def test_four_opals_get_one_trajectory_set_each_on_their_own_clock(opals):
    """The APDM file (four Opals, no markers): trajectories per IMU on each IMU's device clock."""
    from imulog.archive import TrialReader

    for step in ("orientation", "phases"):
        code, _, stderr = run("process", step, opals)
        assert code == 0, stderr
    code, stdout, stderr = run("process", "trajectory", opals, "--method", "zupt")
    assert code == 0, stderr
    rows = [line.split()[:2] for line in stdout.splitlines() if line.startswith("  ") and ":" not in line]
    assert rows[1:] == [[n, "wrote"] for n in ("static", "upper", "middle", "lower")]
    with TrialReader(opals) as trial:
        for n in ("static", "upper", "middle", "lower"):
            ch = trial.channel(f"/derived/trajectory/zupt/{n}")
            assert ch.metadata["clock"] == f"/imu/{n}" and ch.sample_count > 0
        assert trial.metadata["imulog.trajectory"]["clock"] == "device"
    code, stdout, stderr = run("evaluate", opals, "--windows")  # nothing optical to compare with: one line
    assert code == 1 and "no optical reference" in stderr and "Traceback" not in stdout + stderr
