"""`imulog demo` end to end: simulate -> convert -> every step -> evaluate -> view, on a short trial."""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.simulate import load_truth


def test_demo_runs_every_step_and_matches_truth(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    result = CliRunner().invoke(cli, ["demo", "-o", str(out), "--repetitions", "3", "--no-open"])
    assert result.exit_code == 0, result.output
    # every command the demo ran is printed so that a user can replay it
    assert "$ imulog process orientation" in result.output and "$ imulog view" in result.output
    assert (out / "trial.rrd").stat().st_size > 0

    truth = load_truth(next((out / "raw").glob("*_truth.json")))
    with TrialReader(out / "trial.mcap") as trial:
        topics = set(trial.topics())
        phases = trial.read("/derived/phases/wrist")
        metadata = trial.metadata
    for topic in (
        "/imu/wrist",
        "/markers/vicon",
        "/derived/orientation/wrist",
        "/derived/vicon/cluster_pose",
        "/derived/static/wrist",
        "/derived/trajectory/zupt",
    ):
        assert topic in topics
    assert {"imulog.alignment", "imulog.timing", "imulog.evaluation", "imulog.metrics"} <= set(metadata)
    # 3 repetitions x 4 phases, labelled as the truth, each boundary within 0.2 s of it
    assert len(phases) == len(truth.phases) == 12
    assert phases.labels == truth.phases.labels
    assert abs(phases.start_ns - truth.phases.start_ns).max() < 0.2e9
    assert abs(phases.end_ns - truth.phases.end_ns).max() < 0.2e9


def test_demo_refuses_to_wipe_a_foreign_folder(tmp_path: Path) -> None:
    (tmp_path / "precious.txt").write_text("keep me")
    result = CliRunner().invoke(cli, ["demo", "-o", str(tmp_path), "--no-view"])
    assert result.exit_code != 0
    assert f"{tmp_path} exists; add --overwrite to replace it" in result.output  # the overwrite rule first
    result = CliRunner().invoke(cli, ["demo", "-o", str(tmp_path), "--no-view", "--overwrite"])
    assert result.exit_code != 0
    assert "does not hold an earlier demo" in result.output  # ... and --overwrite never removes another folder
    assert (tmp_path / "precious.txt").read_text() == "keep me"
