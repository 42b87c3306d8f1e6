"""The twelfth round's combination in the trajectory step (issue 31 point 2; ``--accelerometer rests``): the step
corrects the accelerometer from the phases step's rests and re-runs the orientation step's filter on it
(:mod:`imulog.steps.trajectory_acc_rests`), and gives what ``benchmarks/trajectory_paired.py --change
rest-tilt-acc-rests-scatter`` measured."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.model import Intervals
from imulog.process import quaternion as quat
from imulog.process.orientation import OrientationParams
from imulog.process.trajectory_accelerometer import accelerometer_of, with_accelerometer
from imulog.process.trajectory_opt import DEFAULT_PARAMS as D
from imulog.steps.orientation import orientation_with_gaps
from imulog.steps.trajectory import compute_trajectories
from imulog.steps.trajectory_acc_rests import OrientationSource, rest_calibrated

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

RESTS = with_accelerometer(D, "rests")
LABELS = ("reach", "lift", "return_bottle", "return_hand")


def test_the_preset_is_the_benchmarks_combination():
    from trajectory_paired import CHANGES

    assert CHANGES["rest-tilt-acc-rests-scatter"] == (D, RESTS)
    assert accelerometer_of(D) == "recorded" and accelerometer_of(RESTS) == "rests"
    assert with_accelerometer(D, "recorded") is D
    with pytest.raises(ValueError, match="accelerometer must be one of recorded, rests"):
        with_accelerometer(D, "raw")


def _step_and_benchmark(name: str, subject: int) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """{"zupt" | "optimized": (step positions, benchmark positions, truth) (N, 3) m} of one simulated development
    trial (subject and seed ``subject``, 10 repetitions): the benchmark's pipeline (``pipeline_inputs`` and
    :func:`reconstruct_repetitions` as ``evaluate_trial`` runs it) and the step's pure part on the same simulated
    recording, with the orientation step's function on the raw IMU, the benchmark's phases and static mask, the
    simulator's clock and the world rotation an alignment against the cluster would find for the step's frame."""
    from trajectory_paired import pipeline_inputs

    from imulog.process.alignment import device_to_reference
    from imulog.process.rests import true_rests
    from imulog.process.trajectory_opt import merge_overlapping, reconstruct_repetitions, repetition_windows
    from imulog.simulate.core import simulate
    from imulog.simulate.grid import condition

    inputs = pipeline_inputs(name, subject, 10, RESTS)
    t = inputs["t_s"]
    rests = true_rests(
        inputs["static"], inputs["acc_gate"], (len(t) - 1) / t[-1], D.rests, orientation=inputs["q_gate"]
    )
    reps, _ = merge_overlapping(repetition_windows(t, inputs["phase_bounds"], rests))
    bench = reconstruct_repetitions(
        t,
        inputs["acc_world"],
        rests,
        reps,
        ["zupt", "optimized"],
        anthropometrics=inputs["anthropometrics"],
        orientation=inputs["q_world"],
        params=RESTS,
        acc_calibration=inputs["acc_calibration"],
    )
    sim = simulate("r2g", subject=subject, seed=subject, repetitions=10, **condition(name))
    imu = sim.recording.imus[0]
    streams, _ = orientation_with_gaps(imu.t_ns, imu.acc, imu.gyr, None, "wrist", OrientationParams())
    q_channel, acc_channel = streams[0].values, streams[1].values
    t_ref = np.round(device_to_reference(imu.t_ns, sim.truth.alignment)).astype(np.int64)
    source = OrientationSource(imu.t_ns, imu.acc, imu.gyr, "/imu/wrist", OrientationParams())
    frame = rest_calibrated(
        imu.t_ns, (t_ref - t_ref[0]) / 1e9, inputs["static"], q_channel, source, imu="wrist", params=RESTS.acc_rests
    ).quat
    alignment = dict(sim.truth.alignment)
    g2w = quat.average(quat.multiply(sim.truth.imu_orientation, quat.conjugate(frame)))
    alignment["rotation_global_to_world"] = [float(v) for v in g2w]
    rows = [
        (t_ref[0] + round(a * 1e9), t_ref[0] + round(b * 1e9), k, LABELS[i % 4])
        for k, bounds in inputs["phase_bounds"].items()
        for i, (a, b) in enumerate(bounds)
    ]
    phases = Intervals(
        "/derived/phases/wrist",
        np.array([r[0] for r in rows], np.int64),
        np.array([r[1] for r in rows], np.int64),
        [r[3] for r in rows],
        np.array([r[2] for r in rows]),
    )
    out, record = compute_trajectories(
        imu.t_ns,
        acc_channel,
        imu="wrist",
        methods=["zupt", "optimized"],
        static=(imu.t_ns, inputs["static"].astype(float)),
        phases=phases,
        orientation=(imu.t_ns, q_channel),
        alignment=alignment,
        anthropometrics=inputs["anthropometrics"],
        params=RESTS,
        gyr=(imu.t_ns, imu.gyr),
        source=source,
    )
    assert record["accelerometer"]["calibration"] == inputs["acc_rest_calibration"]  # the same estimate
    result = {}
    for stream in out:
        method = stream.topic.rsplit("/", 1)[-1]
        if method in bench:
            step = np.full((len(t_ref), 3), np.nan)
            step[np.searchsorted(t_ref, stream.t_ns)] = stream.values
            truth = np.full((len(t_ref), 3), np.nan)
            for r in reps:
                truth[r.start : r.stop] = inputs["truth_pos"][r.start : r.stop] - inputs["truth_pos"][r.start]
            result[method] = (step, bench[method], truth)
    return result


@pytest.mark.parametrize("name, subject", [("default", 40), ("stroke", 44)])
def test_the_step_gives_the_benchmarks_trajectories(name, subject, monkeypatch):
    """On two development trials the step's ZUPT and optimized trajectories are the benchmark's: every sample the
    benchmark reconstructs is reconstructed, the MAE against the truth is the same within 0.02 cm per axis and no
    sample differs by more than 0.25 cm. What differs is how the orientation filter steps over the simulated
    device's dropped samples (about 73 per trial): the orientation step runs it on a uniform grid
    (``estimate_orientation`` with ``t_ns``), the benchmark one sample per nominal period. With the step's filter
    run as the benchmark runs it, no sample differs by more than 0.05 cm (what is left: the rate from the device
    clock, the reference clock rounded to whole ns, the anchoring on the device clock; measured 0.017 / 0.034 cm)."""
    import imulog.process.orientation as orientation

    for method, (step, bench, truth) in _step_and_benchmark(name, subject).items():
        assert np.array_equal(np.isfinite(step).all(1), np.isfinite(bench).all(1)), method
        rows = np.isfinite(bench).all(1)
        assert rows.sum() > 0.5 * len(rows), method
        mae_step = np.abs(step[rows] - truth[rows]).mean(0) * 100
        mae_bench = np.abs(bench[rows] - truth[rows]).mean(0) * 100
        assert np.all(np.abs(mae_step - mae_bench) < 0.02), (method, mae_step, mae_bench)
        assert np.max(np.abs(step[rows] - bench[rows])) < 0.0025, (method, np.max(np.abs(step[rows] - bench[rows])))
    monkeypatch.setattr(orientation, "_has_gaps", lambda t_ns: False)  # the benchmark's filter: no resampling
    for method, (step, bench, _) in _step_and_benchmark(name, subject).items():
        rows = np.isfinite(bench).all(1)
        assert np.max(np.abs(step[rows] - bench[rows])) < 0.0005, (method, np.max(np.abs(step[rows] - bench[rows])))


def _run(*args) -> tuple[int, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.output


def test_the_command_line_runs_it_and_says_what_it_used(processed_r2g, repo_root, tmp_path):
    """``process trajectory --accelerometer rests`` on the converted, oriented, aligned and phased simulated trial
    of ``recordings/sim``: the record names the accelerometer, the filter re-run on it and the calibration, whose
    bias is within three of its standard deviations of the device's; raw and orientation channels are untouched;
    the trajectories differ from the recorded accelerometer's; a second run with the same option is up to date."""
    path = tmp_path / "r2g.mcap"
    shutil.copy(processed_r2g, path)
    code, text = _run("process", "trajectory", path, "--method", "zupt,optimized")
    assert code == 0, text
    with TrialReader(path) as trial:
        kept = {c.topic: c.metadata.get("sha256") for c in trial.channels if not c.topic.startswith("/derived/traj")}
        recorded = trial.read("/derived/trajectory/optimized").values
        assert "accelerometer" not in trial.metadata["imulog.trajectory"]
    code, text = _run("process", "trajectory", path, "--method", "zupt,optimized", "--accelerometer", "rests")
    assert code == 0, text
    with TrialReader(path) as trial:
        record = trial.metadata["imulog.trajectory"]
        rests = trial.read("/derived/trajectory/optimized").values
        run = trial.runs()[max(trial.runs())]
        for c in trial.channels:
            if c.topic in kept and not c.topic.startswith("/derived/viewer/traj"):
                assert c.metadata.get("sha256") == kept[c.topic], c.topic
    entry = record["accelerometer"]
    assert entry["accelerometer"] == "/imu/wrist" and entry["calibration"]["applied"]
    assert entry["orientation_filter"]["algorithm"] == "imulog.orientation.vqf_offline"
    assert abs(entry["orientation_filter"]["heading_to_channel_deg"]) < 1.0
    truth = json.loads((repo_root / "recordings" / "sim" / "r2g_s00_t00_truth.json").read_text())
    true_bias = np.asarray(truth["info"]["device_errors"]["acc_bias_mps2"])
    error = np.linalg.norm(np.asarray(entry["calibration"]["bias_mps2"]) - true_bias)
    assert error < 3 * np.linalg.norm(entry["calibration"]["bias_sd_mps2"]), (entry["calibration"], true_bias)
    assert "/imu/wrist" in run["inputs"] and run["params"]["acc_rests"]["enabled"]
    assert rests.shape == recorded.shape and np.nanmax(np.abs(rests - recorded)) > 1e-3
    code, text = _run("process", "trajectory", path, "--method", "zupt,optimized", "--accelerometer", "rests")
    assert code == 0 and "up to date" in text, text


def test_it_refuses_in_one_line_what_the_trial_cannot_give(processed_r2g, tmp_path):
    """No orientation, an orientation another program wrote, a recording longer than one window: one line each."""
    from test_trajectory_steps import _write_with_inputs

    from imulog.simulate.core import simulate
    from imulog.steps.trajectory import run_trajectory
    from imulog.steps.trajectory_windows import TrajectoryWindows

    n = 200
    with pytest.raises(ValueError, match=r"acc_rests .* needs /derived/orientation/wrist: run `imulog process orient"):
        t = np.arange(n, dtype=np.int64) * 10_000_000
        compute_trajectories(t, np.zeros((n, 3)), imu="wrist", methods=["ddi"], params=RESTS)
    path = tmp_path / "other.mcap"
    _write_with_inputs(path, simulate("r2g", subject=2, seed=0, repetitions=4))
    with pytest.raises(ValueError, match="was not written by `imulog process orientation`"):
        run_trajectory(path, methods=["zupt"], params=RESTS)
    long = tmp_path / "long.mcap"
    shutil.copy(processed_r2g, long)
    with pytest.raises(ValueError, match="runs on recordings of one trajectory window"):
        run_trajectory(long, methods=["zupt"], params=RESTS, windows=TrajectoryWindows(core_s=20.0))


def test_too_few_rests_on_a_real_recording_are_refused(shared_data, tmp_path):
    """BROAD trial 14 (real; the trajectory step's real recording in tests/test_broad_reference.py): the phases
    step finds 4 still rests, all at one orientation, so the calibration is not identifiable and the step says so
    in one line with exit 1, writing nothing."""
    pytest.importorskip("h5py")
    path = tmp_path / "broad14.mcap"
    src = shared_data / "broad" / "14_undisturbed_slow_translation_with_breaks_B.hdf5"
    for args in (("convert", src, "-o", path), ("process", "orientation", path), ("process", "phases", path)):
        code, text = _run(*args)
        assert code == 0, text
    with TrialReader(path) as trial:
        before = trial.topics()
    code, text = _run("process", "trajectory", path, "--accelerometer", "rests")
    assert code == 1, text
    assert "the accelerometer cannot be corrected from its rests: 4 still rests, fewer than 6" in text, text
    assert len(text.strip().splitlines()) == 1, text
    with TrialReader(path) as trial:
        assert trial.topics() == before
