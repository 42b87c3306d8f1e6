"""imulog.batch: registry options, per-file isolation, idempotence, local processes and the CLI.

Trials are simulated R2G recordings (3 repetitions, short opening rest) written with imulog.archive.write_trial.
"""

from __future__ import annotations

import json
import shutil

import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.batch import STEP_ORDER, parse_steps, run
from imulog.batch.registry import plan_fingerprint, resolve_options
from imulog.batch.simulated import simulate_archive
from imulog.batch.verify import check_archive, derived_digests
from imulog.cli import cli

STEPS = "orientation,align,phases,trajectory,evaluate"
OPTIONS = {"phases": {"repetitions": 3}}
N_STEPS = 5


@pytest.fixture(scope="module")
def raw_archive(tmp_path_factory):
    """Three raw (unprocessed) trials; tests copy this folder before processing."""
    root = tmp_path_factory.mktemp("raw")
    simulate_archive(root, subjects=3, trials=1, repetitions=3, opening_static_s=5.0)
    return root


@pytest.fixture(scope="module")
def serial(raw_archive, tmp_path_factory):
    """The archive processed in this process (the reference for the other engines)."""
    root = tmp_path_factory.mktemp("serial") / "archive"
    shutil.copytree(raw_archive, root)
    report = run(root, STEPS, options=OPTIONS, progress=False)
    return root, report


def test_parse_steps_orders_and_rejects():
    assert parse_steps("evaluate,orientation,phases") == ["orientation", "phases", "evaluate"]
    assert parse_steps(list(STEP_ORDER)) == list(STEP_ORDER)
    with pytest.raises(ValueError, match="unknown step"):
        parse_steps("orientation,smoothing")


def test_options_resolve_to_params_objects():
    kwargs, params = resolve_options("phases", {"repetitions": "7", "threshold": "otsu", "imu": "wrist"})
    assert kwargs == {"imu": "wrist"}
    assert params.repetitions.n_repetitions == 7 and params.dynamos.threshold == "otsu"
    _, params = resolve_options("phases", {"dynamos.threshold": "0.2", "static": "gyro-norm"})
    assert params.dynamos.threshold == 0.2 and params.static == "gyro-norm"
    kwargs, _ = resolve_options("trajectory", {"methods": "zupt,kalman"})
    assert kwargs["methods"] == ["zupt", "kalman"]
    _, params = resolve_options("orientation", {"use_mag": "false", "beta": "0.1"})
    assert params.use_mag is False and params.beta == 0.1
    with pytest.raises(ValueError, match="unknown option"):
        resolve_options("phases", {"repetitons": 3})
    with pytest.raises(ValueError, match="calibration"):
        resolve_options("calibrate", {})
    # the ledger key is the resolved plan: "3" and 3 are the same plan, 4 is another
    fp = plan_fingerprint(["phases"], {"phases": {"repetitions": 3}})
    assert fp == plan_fingerprint(["phases"], {"phases": {"repetitions": "3"}})
    assert fp != plan_fingerprint(["phases"], {"phases": {"repetitions": 4}})


def test_serial_batch_processes_every_file_once(serial):
    root, report = serial
    assert report.ok and report.processed == 3 and report.failed == 0
    assert report.steps_computed == 3 * N_STEPS
    for f in report.files:
        assert [s.step for s in f.steps] == ["orientation", "align", "phases", "trajectory", "evaluate"]
        with TrialReader(f.path) as trial:
            assert len(trial.runs()) == N_STEPS
            ev = trial.metadata["imulog.evaluation"]
            # against the simulator's optical reference, ZUPT stays within a few cm (ddi drifts far more)
            zupt = ev["methods"]["zupt"]["summary"]["x"]["mae_cm"]["mean"]
            ddi = ev["methods"]["ddi"]["summary"]["x"]["mae_cm"]["mean"]
            assert zupt < 5.0 and ddi > 2 * zupt
            assert trial.metadata["imulog.timing"]["n_repetitions"] == 3
    assert check_archive(f.path for f in report.files) == {}


def test_rerun_does_no_work(serial):
    root, first = serial
    before = {f.path: derived_digests(f.path) for f in first.files}
    again = run(root, STEPS, options=OPTIONS, progress=False)
    assert again.ok and again.up_to_date == 3 and again.prechecked == 3 and again.steps_computed == 0
    # without the ledger every file is opened, and every step skips itself (same params and inputs)
    opened = run(root, STEPS, options=OPTIONS, progress=False, ledger=None)
    assert opened.up_to_date == 3 and opened.prechecked == 0
    assert opened.steps_computed == 0 and opened.steps_skipped == 3 * N_STEPS
    assert {f.path: derived_digests(f.path) for f in first.files} == before


def test_other_parameters_recompute_only_downstream(serial, tmp_path):
    root = tmp_path / "archive"
    shutil.copytree(serial[0], root)
    changed = run(root, STEPS, options={"phases": {"repetitions": 3, "static_margin_s": 0.05}}, progress=False)
    assert changed.processed == 3 and changed.prechecked == 0
    for f in changed.files:
        computed = [s.step for s in f.steps if not s.skipped]
        assert computed[0] == "phases" and "orientation" not in computed and "align" not in computed


def test_bad_files_are_reported_and_the_rest_completes(raw_archive, tmp_path):
    root = tmp_path / "archive"
    shutil.copytree(raw_archive, root)
    (root / "S00").mkdir()
    (root / "S00" / "garbage.mcap").write_bytes(b"\x89MCAP0\r\n" + b"not really" * 50)
    from imulog.simulate import simulate

    rec = simulate("r2g", subject=9, repetitions=3, opening_static_s=5.0).recording
    rec.markers = []  # an IMU-only trial cannot be aligned
    write_trial(root / "S00" / "no_markers.mcap", rec, attach_sources=False)
    result = CliRunner().invoke(cli, ["batch", str(root), "--steps", STEPS, "--repetitions", "3", "-q"])
    assert result.exit_code == 1, result.output
    assert "3 processed" in result.output and "2 failed" in result.output
    assert "garbage.mcap" in result.output and "no_markers.mcap" in result.output
    assert "align" in result.output  # the failing step is named
    report = run(root, STEPS, options=OPTIONS, progress=False)
    assert report.failed == 2 and report.up_to_date == 3 and report.steps_computed == 0
    by_name = {f.path.rsplit("/", 1)[1]: f for f in report.files}
    assert by_name["no_markers.mcap"].failed_step == "align"
    steps = by_name["no_markers.mcap"].steps
    assert [s.step for s in steps if not s.reason.startswith("not run")] == ["orientation"]  # before the failure
    after = [(s.step, s.reason) for s in steps if s.reason.startswith("not run")]  # each reads the alignment
    assert after == [(s, "not run: needs align, which failed") for s in ("phases", "trajectory", "evaluate")]
    # --fail-fast: the first file (S00/garbage.mcap) fails, the next one needing work is not started
    stopped = run(root, STEPS, options=OPTIONS, progress=False, continue_on_error=False)
    assert (stopped.failed, stopped.cancelled, stopped.up_to_date) == (1, 1, 3)
    assert not stopped.ok


def test_local_processes_match_serial(serial, raw_archive, tmp_path):
    root = tmp_path / "archive"
    shutil.copytree(raw_archive, root)
    report = run(root, STEPS, options=OPTIONS, progress=False, workers=2)
    assert report.ok and report.processed == 3 and report.engine == "processes"
    assert len({f.worker for f in report.files}) >= 1
    ref_root, _ = serial
    for f in report.files:
        rel = f.path[len(str(root)) :]
        assert derived_digests(f.path) == derived_digests(str(ref_root) + rel)


def test_cli_json_report_and_errors(serial, tmp_path):
    root, _ = serial
    out = tmp_path / "report.json"
    result = CliRunner().invoke(
        cli, ["batch", f"{root}/**/*.mcap", "--steps", STEPS, "--repetitions", "3", "-q", "--json", str(out)]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["counts"]["files"] == 3 and data["counts"]["failed"] == 0
    bad = CliRunner().invoke(cli, ["batch", str(root), "--set", "phases.nonsense=1", "-q"])
    assert bad.exit_code != 0 and "nonsense" in bad.output
    none = CliRunner().invoke(cli, ["batch", str(tmp_path / "nothing" / "*.mcap"), "-q"])
    assert none.exit_code != 0 and "no trial files" in none.output


def test_calibrate_step_with_a_calibration_file(raw_archive, tmp_path):
    import numpy as np

    from imulog.process.calibration import AxisCalibration, Calibration

    trial = tmp_path / "t.mcap"
    shutil.copy(next(raw_archive.rglob("*.mcap")), trial)
    cal_file = tmp_path / "cal.json"
    bias = np.array([0.01, -0.02, 0.005])
    cal_file.write_text(json.dumps(Calibration(gyr=AxisCalibration(bias, np.eye(3))).to_dict()))
    opts = {"calibrate": {"calibration": str(cal_file)}}
    report = run(trial, "orientation,calibrate", options=opts, progress=False)
    assert report.ok and [s.step for s in report.files[0].steps] == ["calibrate", "orientation"]
    with TrialReader(trial) as t:
        raw, cal = t.read("/imu/wrist"), t.read("/derived/calibrated/wrist")
        orientation_run = [r for r in t.runs().values() if r["step"].startswith("orientation")][-1]
    gyr = cal.values[:, [cal.columns.index(c) for c in ("gx", "gy", "gz")]]
    np.testing.assert_allclose(gyr, raw.gyr - bias, atol=1e-12)
    assert "/derived/calibrated/wrist" in orientation_run["inputs"]  # orientation used the calibrated channel
    assert run(trial, "orientation,calibrate", options=opts, progress=False).prechecked == 1
    # same file name, new content: the ledger misses and both steps recompute
    cal_file.write_text(json.dumps(Calibration(gyr=AxisCalibration(2 * bias, np.eye(3))).to_dict()))
    again = run(trial, "orientation,calibrate", options=opts, progress=False)
    assert again.prechecked == 0 and again.steps_computed == 2


def test_phases_options_apply_onto_the_trials_own_protocol(tmp_path):
    """Batch options change a trial's phase defaults; they do not reset them to R2G with 25 repetitions."""
    import dataclasses

    from imulog.archive import TrialReader, write_trial
    from imulog.batch.registry import call_step
    from imulog.simulate import simulate

    sim = simulate("r2g", seed=2, repetitions=3, opening_static_s=5.0)
    r2g = write_trial(tmp_path / "r2g.mcap", sim.recording, attach_sources=False)
    no_task = {k: v for k, v in sim.recording.metadata.items() if k != "imulog.trial"}
    other = write_trial(
        tmp_path / "other.mcap", dataclasses.replace(sim.recording, metadata=no_task), attach_sources=False
    )
    for trial in (r2g, other):
        call_step(trial, "phases", {"alpha": 0.75})
    with TrialReader(r2g) as reader:
        phases = reader.read("/derived/phases/wrist")
        assert reader.runs()[max(reader.runs())]["params"]["dynamos"]["alpha"] == 0.75
    assert len(phases) == 12 and phases.labels[:4] == ["reach", "lift", "return_bottle", "return_hand"]
    with TrialReader(other) as reader:
        assert set(reader.read("/derived/phases/wrist").labels) == {"movement"}


def test_a_list_option_takes_the_type_of_its_default_items():
    """``--set epochs.epochs_s=10,60`` gives the floats 10.0 and 60.0 (strings failed inside the step with
    "Unknown format code 'g' for object of type 'str'"); a bad item is one error naming the option; lists of
    names stay strings."""
    _, params = resolve_options("epochs", {"epochs_s": "10, 60"})
    assert params.epochs_s == (10.0, 60.0) and all(isinstance(e, float) for e in params.epochs_s)
    with pytest.raises(ValueError, match=r"^step epochs epochs_s: could not convert string to float: 'x'$"):
        resolve_options("epochs", {"epochs_s": "10,x"})
    kwargs, _ = resolve_options("trajectory", {"methods": "zupt,kalman"})
    assert kwargs["methods"] == ["zupt", "kalman"]


def test_the_trajectory_accelerometer_preset_is_the_commands(serial, tmp_path):
    """``--set trajectory.accelerometer=rests`` is ``imulog process trajectory --accelerometer rests``: the whole
    combination (before, ``trajectory.acc_rests.enabled=true`` switched on only the correction), fields given with
    it refine it, and the command finds the batch's run up to date (same parameters recorded)."""
    from imulog.batch.registry import run_params
    from imulog.process.trajectory_accelerometer import with_accelerometer
    from imulog.process.trajectory_methods import TrajectoryParams

    rests = with_accelerometer(TrajectoryParams(), "rests")
    _, params = resolve_options("trajectory", {"accelerometer": "rests"})
    assert params == rests and params != resolve_options("trajectory", {"acc_rests.enabled": "true"})[1]
    assert resolve_options("trajectory", {"accelerometer": "recorded"})[1] == TrajectoryParams()
    _, refined = resolve_options("trajectory", {"anchor.rest_tilt": "filter", "accelerometer": "rests"})
    assert refined.anchor.rest_tilt == "filter" and refined.acc_rests.enabled  # the field wins, in any order
    with pytest.raises(ValueError, match="step trajectory accelerometer: accelerometer must be one of recorded, rests"):
        resolve_options("trajectory", {"accelerometer": "raw"})

    trial = tmp_path / "one.mcap"
    shutil.copy(sorted(serial[0].rglob("*.mcap"))[0], trial)
    result = CliRunner().invoke(
        cli, ["batch", str(trial), "--steps", "trajectory", "--set", "trajectory.accelerometer=rests", "-q"]
    )
    assert result.exit_code == 0, result.output
    with TrialReader(trial) as t:
        runs = [r for r in t.runs().values() if str(r.get("step", "")).startswith("trajectory")]
    assert run_params(runs[-1])[0] == rests
    command = CliRunner().invoke(cli, ["process", "trajectory", str(trial), "--accelerometer", "rests"])
    assert command.exit_code == 0, command.output
    assert "up to date" in command.output
