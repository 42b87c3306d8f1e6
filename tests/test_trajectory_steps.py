"""The trajectory and evaluate steps and CLI on simulated R2G trials with ground truth."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, append_derived, write_trial
from imulog.cli import cli
from imulog.model import Intervals, SignalStream
from imulog.process import quaternion as quat
from imulog.process.orientation import estimate_orientation, gravity_free_acceleration
from imulog.simulate.core import simulate
from imulog.steps.evaluate import run_evaluate
from imulog.steps.trajectory import compute_trajectories, run_trajectory


def _mae(record, method, axis):
    return record["methods"][method]["summary"][axis]["mae_cm"]["mean"]


@pytest.fixture(scope="module")
def sim_trial(tmp_path_factory):
    """A 4-repetition R2G trial with derived inputs built here from imulog's orientation estimate and the
    simulator's true phases, static mask and alignment (independent of the other steps)."""
    sim = simulate("r2g", subject=2, seed=0, repetitions=4)
    path = tmp_path_factory.mktemp("traj") / "trial.mcap"
    _write_with_inputs(path, sim)
    return sim, path


def _write_with_inputs(path, sim, recording=None):
    """Write ``recording`` (default: the simulated one) with the trajectory step's inputs appended."""
    write_trial(path, recording or sim.recording)
    imu = sim.recording.imus[0]
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) / 1e9)
    est = estimate_orientation(imu.gyr, imu.acc, rate)
    acc_g = gravity_free_acceleration(est.quat, imu.acc, est.static)
    truth = sim.truth
    # the global-to-world rotation an alignment against the cluster would find
    alignment = dict(truth.alignment)
    q_g2w = quat.average(quat.multiply(truth.imu_orientation, quat.conjugate(est.quat)))
    alignment["rotation_global_to_world"] = [float(v) for v in q_g2w]
    streams = [
        SignalStream("/derived/orientation/wrist", imu.t_ns, ["qw", "qx", "qy", "qz"], ["1"] * 4, est.quat),
        SignalStream("/derived/acc_global/wrist", imu.t_ns, ["ax", "ay", "az"], ["m/s^2"] * 3, acc_g),
        SignalStream(
            "/derived/static/wrist", imu.t_ns, ["static"], ["1"], truth.imu_static_mask.astype(float)[:, None]
        ),
        Intervals(
            "/derived/phases/wrist",
            truth.phases.start_ns,
            truth.phases.end_ns,
            truth.phases.labels,
            truth.phases.task_index,
        ),
    ]
    append_derived(
        path,
        streams,
        run={"step": "test-inputs", "algorithm": "test", "params": {}, "inputs": ["/imu/wrist"]},
        metadata={"imulog.alignment": alignment, "imulog.timing": {"clock": "reference"}},
    )


def test_step_writes_every_method_on_reference_clock_and_world_frame(sim_trial):
    sim, path = sim_trial
    outcome = run_trajectory(path)
    assert not outcome.skipped
    with TrialReader(path) as trial:
        topics = trial.topics()
        for m in ("ddi", "zupt", "highpass", "wavelet", "kalman", "zupt_bias", "optimized"):
            assert f"/derived/trajectory/{m}" in topics
        s = trial.read("/derived/trajectory/optimized")
        info = trial.metadata["imulog.trajectory"]
    assert s.columns == ["x", "y", "z"] and s.units == ["m"] * 3 and s.frame_id == "world"
    info = {k: json.loads(v) if isinstance(v, str) and v[:1] in "[{" else v for k, v in info.items()}
    assert [r["index"] for r in info["repetitions"]] == [1, 2, 3, 4]
    # reference clock: the trajectory's samples fall inside the true repetitions (+- the padding)
    ph = sim.truth.phases
    assert s.t_ns[0] >= ph.start_ns.min() - 2_000_000_000 and s.t_ns[-1] <= ph.end_ns.max() + 2_000_000_000
    # rerunning with the same inputs and params writes nothing
    assert run_trajectory(path).skipped


def test_evaluate_against_markers_orders_methods(sim_trial):
    _, path = sim_trial
    run_trajectory(path)
    _, record = run_evaluate(path)
    assert record["reference"] == "/markers/vicon:O"
    for axis in "xyz":
        ddi, zupt, opt = (_mae(record, m, axis) for m in ("ddi", "zupt", "optimized"))
        assert ddi > zupt and ddi > opt, (axis, ddi, zupt, opt)
    with TrialReader(path) as trial:
        assert "imulog.evaluation" in trial.metadata


@pytest.mark.xfail(
    strict=True,
    reason="issue 31 point 2, the 'below ZUPT' half: with the heading through rests (default since 2026-12-07) "
    "ZUPT is at 0.78 cm in y on this trial and the optimized trajectory at 0.88 cm, its start zupt_bias at 0.96 cm "
    "(docs/accuracy.md)",
)
def test_evaluate_ranks_optimized_below_zupt(sim_trial):
    _, path = sim_trial
    run_trajectory(path)
    _, record = run_evaluate(path)
    for axis in "xyz":
        zupt, opt = (_mae(record, m, axis) for m in ("zupt", "optimized"))
        assert zupt > opt, (axis, zupt, opt)


def test_compute_trajectories_without_phases_or_alignment(sim_trial):
    sim, _ = sim_trial
    imu = sim.recording.imus[0]
    acc = np.zeros((len(imu.t_ns), 3))
    static = np.ones(len(imu.t_ns))
    streams, record = compute_trajectories(
        imu.t_ns, acc, imu="wrist", methods=["ddi", "zupt", "optimized"], static=(imu.t_ns, static)
    )
    assert [s.topic for s in streams] == [
        "/derived/trajectory/ddi",
        "/derived/trajectory/zupt",
        "/derived/trajectory_baseline/dedrift",  # the baseline every method must beat (issue 32)
    ]
    assert record["clock"] == "device" and record["frame"] == "wrist_global" and record["methods"] == ["ddi", "zupt"]
    assert all(np.all(s.values == 0) for s in streams)
    with pytest.raises(ValueError, match="process phases"):
        compute_trajectories(imu.t_ns, acc, imu="wrist", methods=["zupt"])


def test_cli_trajectory_and_evaluate(sim_trial, tmp_path):
    _, path = sim_trial
    runner = CliRunner()
    res = runner.invoke(cli, ["process", "trajectory", str(path), "--method", "zupt,optimized", "--force"])
    assert res.exit_code == 0, res.output
    assert "/derived/trajectory/optimized" in res.output
    res = runner.invoke(cli, ["evaluate", str(path), "--method", "zupt,optimized"])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert lines[1].startswith("method") and any(line.startswith("optimized") for line in lines)
    res = runner.invoke(cli, ["evaluate", str(path), "--json"])
    rec = json.loads(res.output)
    assert set(rec["methods"]) >= {"zupt", "optimized"}
    # a trial without the orientation step: one clear line, non-zero exit
    bare = tmp_path / "bare.mcap"
    write_trial(bare, simulate("r2g", subject=0, seed=1, repetitions=1).recording)
    res = runner.invoke(cli, ["process", "trajectory", str(bare)])
    assert res.exit_code != 0 and "process orientation" in res.output
    res = runner.invoke(cli, ["process", "trajectory", str(path), "--method", "nope"])
    assert res.exit_code != 0 and "unknown method" in res.output


def test_full_chain_of_steps_reproduces_thesis_ordering(tmp_path):
    """simulate -> orientation -> align -> phases (other engineers' steps) -> trajectory -> evaluate,
    2 subjects x 6 repetitions, realistic noise: DDI > ZUPT on every axis, optimized below ZUPT in 3D and
    within the issue's 1 cm on every axis (the full 3 x 25 study is benchmarks/trajectory_accuracy.py)."""
    from imulog.process.segmentation.pipeline import PhaseParams
    from imulog.process.segmentation.repetitions import RepetitionParams
    from imulog.steps.align import run_align
    from imulog.steps.orientation import run_orientation
    from imulog.steps.phases import run_phases

    rows: dict[str, list] = {"ddi": [], "zupt": [], "optimized": []}
    for subject in (1, 2):
        path = tmp_path / f"s{subject}.mcap"
        write_trial(path, simulate("r2g", subject=subject, seed=0, repetitions=6).recording)
        run_orientation(path)
        run_align(path)
        run_phases(path, params=PhaseParams(repetitions=RepetitionParams(n_repetitions=6)))
        run_trajectory(path, methods=list(rows))
        _, record = run_evaluate(path)
        for m in rows:
            rows[m] += record["methods"][m]["repetitions"]
    assert all(len(v) == 12 for v in rows.values())
    norm = {m: np.mean([r["mae_norm_cm"] for r in rows[m]]) for m in rows}
    assert norm["ddi"] > norm["zupt"] > norm["optimized"], norm
    for axis in "xyz":
        ddi, zupt, opt = (np.mean([r[axis]["mae_cm"] for r in rows[m]]) for m in ("ddi", "zupt", "optimized"))
        assert ddi > zupt, (axis, ddi, zupt)
        assert opt <= 1.0, (axis, opt)


def test_non_r2g_task_skips_optimized_instead_of_failing():
    """A simulated slide trial (3 phases per repetition: reach, slide, return): the default method list used
    to fail the whole step with 'no complete repetition to measure waypoints from'; now every method but
    the R2G optimisation is written and the skip is recorded. Asking for optimized alone is a clear error."""
    sim = simulate("slide", seed=0, repetitions=3)
    imu, truth = sim.recording.imus[0], sim.truth
    reps = np.asarray(truth.phases.task_index)
    assert {int(np.sum(reps == k)) for k in set(reps.tolist())} == {3}
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) / 1e9)
    est = estimate_orientation(imu.gyr, imu.acc, rate)
    acc_g = gravity_free_acceleration(est.quat, imu.acc, est.static)
    kw = dict(
        imu="wrist",
        static=(imu.t_ns, truth.imu_static_mask.astype(float)),
        phases=truth.phases,
        orientation=(imu.t_ns, est.quat),
        alignment=dict(truth.alignment),
    )
    streams, record = compute_trajectories(imu.t_ns, acc_g, **kw)
    written = [s.topic.rsplit("/", 1)[1] for s in streams]
    assert written == [m for m in ("ddi", "zupt", "highpass", "wavelet", "kalman", "zupt_bias", "dedrift")]
    assert record["methods"] == written[:-1]
    assert "optimized" in record["skipped"] and len(record["repetitions"]) == 3
    with pytest.raises(ValueError, match="R2G"):
        compute_trajectories(imu.t_ns, acc_g, methods=["optimized"], **kw)


def _processed_wrist(path):
    """The processed simulated trial's gravity-free acceleration, its alignment record and the keyword arguments of
    :func:`compute_trajectories` for ZUPT and the optimisation on it (static mask and phases from the archive)."""
    with TrialReader(path) as t:
        acc, static = t.read("/derived/acc_global/wrist"), t.read("/derived/static/wrist")
        phases, alignment = t.read("/derived/phases/wrist"), t.metadata["imulog.alignment"]
    kw = dict(imu="wrist", methods=["zupt", "optimized"], static=(static.t_ns, static.values[:, 0]), phases=phases)
    return acc, alignment, kw


def test_missing_anthropometrics_is_recorded_and_reported(sim_trial):
    """Without h1/h2/h3 the optimisation measures its waypoints from ZUPT: the record and the CLI say so
    (it used to fall back silently)."""
    sim, path = sim_trial
    acc, alignment, kw = _processed_wrist(path)
    _, record = compute_trajectories(acc.t_ns, acc.values, alignment=alignment, **kw)
    assert record["waypoints_from"] == "zupt" and "no imulog.anthropometrics" in record["notes"][0]
    anth = sim.recording.metadata["imulog.anthropometrics"]
    _, record = compute_trajectories(acc.t_ns, acc.values, alignment=alignment, anthropometrics=anth, **kw)
    assert record["waypoints_from"] == "anthropometrics" and "notes" not in record
    _, record = compute_trajectories(acc.t_ns, acc.values, alignment=alignment, anthropometrics={"h1_m": 0.3}, **kw)
    assert record["waypoints_from"] == "zupt" and "h2" in record["notes"][0]


def _cli_trajectory_warnings(path, sim, metadata, needle):
    """The simulated trial written to ``path`` with ``metadata`` and the step's inputs, `imulog process trajectory`
    run on it (ZUPT and the optimisation), and its stderr lines containing ``needle``."""
    import dataclasses

    _write_with_inputs(path, sim, dataclasses.replace(sim.recording, metadata=metadata))
    result = CliRunner().invoke(cli, ["process", "trajectory", str(path), "--method", "zupt,optimized"])
    assert result.exit_code == 0, result.output
    return path, [ln for ln in result.stderr.splitlines() if needle in ln]


def test_anthropometrics_are_checked_against_the_imu(sim_trial, tmp_path):
    """Issue 31, point 4: a given h1 that is 10 cm off where the hand goes is named in one line by the CLI and
    recorded; the right values raise nothing; marked approximate, the IMU's estimate replaces it."""
    sim, path = sim_trial
    anth = sim.recording.metadata["imulog.anthropometrics"]
    acc, alignment, kw = _processed_wrist(path)
    _, record = compute_trajectories(acc.t_ns, acc.values, alignment=alignment, anthropometrics=anth, **kw)
    assert record["input_checks"] and not record.get("input_warnings")  # the simulator's own values agree
    wrong = {**anth, "h1_m": anth["h1_m"] - 0.10}
    _, record = compute_trajectories(acc.t_ns, acc.values, alignment=alignment, anthropometrics=wrong, **kw)
    (line,) = record["input_warnings"]
    assert line.startswith(f"h1_m = {wrong['h1_m'] * 100:.1f} cm, but the IMU puts the bottle's x at")
    approx = {**wrong, "h1_m_status": "approximate"}
    _, rec2 = compute_trajectories(acc.t_ns, acc.values, alignment=alignment, anthropometrics=approx, **kw)
    (h1,) = [c for c in rec2["input_checks"] if c["name"] == "h1_m"]
    assert h1["replaced"] and rec2["waypoints_m"]["bottle"][0] == pytest.approx(h1["estimated_m"], abs=0.03)
    assert abs(h1["estimated_m"] - anth["h1_m"]) < 0.03  # the IMU's estimate is near the true value

    # through the CLI: the warning is printed on stderr, one line
    meta = {**sim.recording.metadata, "imulog.anthropometrics": wrong}
    _, warnings = _cli_trajectory_warnings(tmp_path / "wrong.mcap", sim, meta, "warning: h1_m")
    assert len(warnings) == 1 and "h1_m_status=approximate" in warnings[0]


def test_evaluate_without_markers_says_what_is_missing(tmp_path):
    """A BROAD-like trial (IMU + optical poses, no markers): the poses are the reference (docs/alignment.md, "A
    rigid body's poses"): evaluate names the step that is missing first (the orientation it evaluates), and align
    on a body that never turns fails in one line naming the pose channel, writing nothing."""
    from imulog.model import ImuStream, PoseStream, Recording

    t = np.arange(200, dtype=np.int64) * 10_000_000
    rec = Recording(
        imus=[ImuStream("imu", t, acc=np.tile([0.0, 0.0, 9.81], (200, 1)), gyr=np.zeros((200, 3)))],
        poses=[PoseStream("/poses/optical", t, np.zeros((200, 3)), np.tile([1.0, 0, 0, 0], (200, 1)))],
    )
    path = tmp_path / "broad_like.mcap"
    write_trial(path, rec)
    result = CliRunner().invoke(cli, ["evaluate", str(path)])
    assert result.exit_code == 1 and "imulog process orientation" in result.output
    assert "Traceback" not in result.output
    result = CliRunner().invoke(cli, ["process", "align", str(path)])
    assert result.exit_code == 1 and "/poses/optical" in result.output and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1
    with TrialReader(path) as trial:
        assert "imulog.alignment" not in trial.metadata


def test_rerun_with_fewer_methods_removes_the_stale_trajectories(sim_trial, tmp_path):
    """Re-running the step with --method ddi,zupt used to leave the other methods' channels of the earlier
    run (computed from other inputs) in the trial, and evaluate then mixed them in."""
    import shutil

    from imulog.archive.doctor import check_file

    _, src = sim_trial
    path = tmp_path / "trial.mcap"
    shutil.copy(src, path)
    run_trajectory(path, methods=["ddi", "zupt", "kalman"], force=True)
    out = run_trajectory(path, methods=["ddi", "zupt"], force=True)
    with TrialReader(path) as t:
        present = sorted(x for x in t.topics() if x.startswith("/derived/trajectory/"))
    written = sorted(x for x in out.topics if x.startswith("/derived/trajectory/"))
    assert present == ["/derived/trajectory/ddi", "/derived/trajectory/zupt"] == written
    assert run_trajectory(path, methods=["ddi", "zupt"]).skipped
    _, record = run_evaluate(path)
    assert sorted(record["methods"]) == ["ddi", "dedrift", "zupt"] and record["baseline"] == "dedrift"
    assert check_file(path).ok


def test_the_placement_side_is_checked_against_the_imu(sim_trial, tmp_path):
    """Issue 31, point 4: the simulated right hand drinks towards +y; labelled left (the device's placement),
    the step says so in one line naming the placement and what the IMU saw, records it with the other checks and
    changes nothing; labelled right (the simulator's imulog.trial side) it is silent."""
    sim, path = sim_trial
    anth = sim.recording.metadata["imulog.anthropometrics"]
    acc, alignment, kw = _processed_wrist(path)
    kw |= dict(alignment=alignment, anthropometrics=anth)
    _, right = compute_trajectories(acc.t_ns, acc.values, side=("right", "imulog.trial side"), **kw)
    assert not right.get("input_warnings")
    _, left = compute_trajectories(acc.t_ns, acc.values, side=("left", "the test's label"), **kw)
    imu_line, h2_line = left["input_warnings"]
    assert imu_line.startswith("placement side = left (the test's label), but the IMU puts the mouth's y at ")
    assert "a right hand's drink" in imu_line and h2_line.startswith(f"h2_m = {anth['h2_m'] * 100:.1f} cm")
    (rec,) = [c for c in left["input_checks"] if c["name"] == "placement_side"]
    assert rec["side"] == "left" and rec["seen"] == "right" and rec["disagrees"] and not rec["replaced"]
    assert abs(rec["value_m"] - anth["h2_m"]) < 0.03  # the IMU's mouth y is the true one
    assert left["waypoints_m"] == right["waypoints_m"]  # the side changes no waypoint

    # through the CLI: the device record's placement names the side
    meta = {**sim.recording.metadata, "imulog.device.wrist": {**sim.recording.metadata["imulog.device.wrist"]}}
    meta["imulog.device.wrist"]["placement"] = "left wrist"
    left_path, warnings = _cli_trajectory_warnings(tmp_path / "left.mcap", sim, meta, "warning: placement side")
    assert len(warnings) == 1 and "(imulog.device.wrist placement 'left wrist')" in warnings[0]
    with TrialReader(left_path) as t:
        assert t.metadata["imulog.device.wrist"]["placement"] == "left wrist"  # the metadata is not changed
