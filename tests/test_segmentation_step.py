"""The ``phases`` step and ``imulog process phases`` on a simulated trial written to MCAP."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.process.segmentation.pipeline import PhaseParams
from imulog.process.segmentation.repetitions import RepetitionParams
from imulog.steps.phases import compute_phases, pick_imu

simulate = pytest.importorskip("imulog.simulate").simulate

N_REP = 5


@pytest.fixture(scope="module")
def sim():
    return simulate("r2g", seed=5, subject=1, repetitions=N_REP, extra_submovement_probability=0.2)


def test_compute_phases_in_memory_on_reference_clock(sim):
    imu = sim.recording.imus[0]
    params = PhaseParams(repetitions=RepetitionParams(n_repetitions=N_REP))
    streams, timing = compute_phases(imu.t_ns, imu.gyr, "wrist", params, sim.truth.alignment)
    movements, phases, static = streams
    assert movements.topic == "/derived/movements/wrist" and phases.topic == "/derived/phases/wrist"
    assert len(phases) == 4 * N_REP and timing["n_phases"] == 4 * N_REP
    assert phases.labels[:4] == ["reach", "lift", "return_bottle", "return_hand"]
    assert phases.task_index.tolist() == [r for r in range(1, N_REP + 1) for _ in range(4)]
    # with the true alignment the phases are on the reference clock: compare with the truth directly
    truth = sim.truth.phases
    assert np.mean(np.abs(np.r_[phases.start_ns - truth.start_ns, phases.end_ns - truth.end_ns])) * 1e-9 < 0.08
    assert timing["clock"] == "reference"
    assert static.columns == ["static"] and len(static) == len(imu.t_ns)
    np.testing.assert_array_equal(static.t_ns, imu.t_ns)
    # static where the truth says the IMU is not rotating nor moving, for most samples
    agree = np.mean((static.values[:, 0] > 0.5) == sim.truth.imu_static_mask)
    assert agree > 0.9
    row = timing["phases"][1]
    assert row["label"] == "lift" and row["repetition"] == 1
    assert row["duration_s"] == pytest.approx((phases.end_ns[1] - phases.start_ns[1]) * 1e-9, abs=1e-3)
    peak = np.linalg.norm(imu.gyr, axis=1)[(imu.t_ns >= 0)].max()
    assert 0 < row["peak_angular_velocity_rad_s"] <= peak


def test_pick_imu_errors_name_the_channels():
    assert pick_imu(["/imu/wrist", "/markers/vicon"], None) == "wrist"
    with pytest.raises(ValueError, match="/imu/ankle"):
        pick_imu(["/imu/wrist"], "ankle")
    with pytest.raises(ValueError, match="a, b"):
        pick_imu(["/imu/a", "/imu/b"], None)


def test_cli_process_phases_appends_and_is_idempotent(sim, tmp_path):
    archive = pytest.importorskip("imulog.archive")
    from imulog.cli import cli

    path = tmp_path / "trial.mcap"
    archive.write_trial(path, sim.recording, attach_sources=False)
    runner = CliRunner()
    args = ["process", "phases", str(path), "--repetitions", str(N_REP)]
    first = runner.invoke(cli, args)
    assert first.exit_code == 0, first.output
    assert "20 phases in 5 repetitions" in first.output and "return_hand" in first.output
    with archive.TrialReader(path) as trial:
        topics = trial.topics()
        assert {"/derived/movements/wrist", "/derived/phases/wrist", "/derived/static/wrist"} <= set(topics)
        phases = trial.read("/derived/phases/wrist")
        timing = trial.metadata["imulog.timing"]
    assert len(phases) == 20 and phases.task_index.max() == N_REP
    assert timing["n_phases"] == 20 and len(timing["phases"]) == 20
    second = runner.invoke(cli, args)
    assert second.exit_code == 0 and "unchanged" in second.output
    bad = runner.invoke(cli, ["process", "phases", str(path), "--imu", "ankle"])
    assert bad.exit_code != 0 and "/imu/ankle" in bad.output
    bad = runner.invoke(cli, ["process", "phases", str(path), "--threshold", "2"])
    assert bad.exit_code != 0


def test_protocol_follows_the_trial_record(sim, tmp_path):
    """R2G phases only for a trial whose record says task r2g; any other trial gets its movements as phases."""
    from imulog.archive import TrialReader, write_trial
    from imulog.cli import cli

    r2g_trial, unknown_trial = tmp_path / "r2g.mcap", tmp_path / "unknown.mcap"
    write_trial(r2g_trial, sim.recording, attach_sources=False)
    metadata = {k: v for k, v in sim.recording.metadata.items() if k != "imulog.trial"}
    stripped = dataclasses.replace(sim.recording, metadata=metadata)
    write_trial(unknown_trial, stripped, attach_sources=False)

    runner = CliRunner()
    for trial in (r2g_trial, unknown_trial):
        result = runner.invoke(cli, ["process", "phases", str(trial), "--quiet"])
        assert result.exit_code == 0, result.output
    with TrialReader(r2g_trial) as r:
        phases = r.read("/derived/phases/wrist")
        assert r.metadata["imulog.timing"]["protocol"] == "r2g"
    # the record's repetition count (5, not the protocol's usual 25) is used without being told
    assert len(phases) == 4 * N_REP and set(phases.labels) == {"reach", "lift", "return_bottle", "return_hand"}
    with TrialReader(unknown_trial) as r:
        phases, movements = r.read("/derived/phases/wrist"), r.read("/derived/movements/wrist")
        assert r.metadata["imulog.timing"]["protocol"] == "movements"
    assert set(phases.labels) == {"movement"} and len(phases) == len(movements)
    assert phases.task_index.tolist() == list(range(1, len(phases) + 1))

    # the user can still ask for R2G phases explicitly
    result = runner.invoke(cli, ["process", "phases", str(unknown_trial), "--protocol", "r2g", "--repetitions", "5"])
    assert result.exit_code == 0, result.output
    with TrialReader(unknown_trial) as r:
        assert len(r.read("/derived/phases/wrist")) == 4 * N_REP


def test_damaged_trial_is_a_one_line_error(sim, tmp_path):
    from imulog.archive import write_trial
    from imulog.cli import cli

    trial = tmp_path / "t.mcap"
    write_trial(trial, sim.recording, attach_sources=False)
    data = trial.read_bytes()
    trial.write_bytes(data[: len(data) // 2])
    result = CliRunner().invoke(cli, ["process", "phases", str(trial)])
    assert result.exit_code != 0
    assert "Traceback" not in result.output and str(trial) in result.output
    assert len(result.output.strip().splitlines()) == 1
