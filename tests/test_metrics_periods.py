"""Daily-life summaries: metrics per wall-clock hour and day of a long wrist recording."""

from __future__ import annotations

from datetime import datetime

import numpy as np
import pytest

from imulog.model import ImuStream
from imulog.process.metrics.periods import wall_clock_origin_ns
from imulog.steps.metrics import compute_metrics

G = 9.80665


def _recording(hours: float, rate: float, active_hours: list[tuple[float, float]], seed: int = 0) -> ImuStream:
    """Still wrist with bursts of movement during ``active_hours`` (start, end in hours from the first sample)."""
    rng = np.random.default_rng(seed)
    n = int(hours * 3600 * rate)
    t = np.arange(n, dtype=np.int64) * int(round(1e9 / rate))
    acc = np.tile([0.0, 0.0, G], (n, 1)) + rng.normal(0, 0.002 * G, (n, 3))
    h = t / 3.6e12
    for a, b in active_hours:
        on = (h >= a) & (h < b)
        s = t[on] / 1e9
        acc[on, 0] += 0.4 * G * np.sin(2 * np.pi * 0.7 * s) * (np.sin(2 * np.pi * s / 20.0) > 0)
    return ImuStream("wrist", t, acc=acc, gyr=np.zeros((n, 3)))


def test_origin_at_the_wall_clock_boundary():
    origin, when = wall_clock_origin_ns(10**12, "2024-03-01T10:30:15+01:00", 3600.0)
    assert origin == 10**12 - int(1815e9)
    assert when == datetime.fromisoformat("2024-03-01T10:00:00+01:00")
    origin, when = wall_clock_origin_ns(0, "2024-03-01T10:30:00", 86400.0)  # naive local time: local midnight
    assert origin == -int(37800e9) and when.isoformat() == "2024-03-01T00:00:00"
    assert wall_clock_origin_ns(5, None, 3600.0) == (5, None)


def test_hourly_summaries_follow_the_wall_clock():
    imu = _recording(3.0, 10.0, [(1.0, 1.5)])
    _, record = compute_metrics(imu, start_time="2024-03-01T10:30:00+01:00")
    hours = record["by_hour"]
    assert [h["start"] for h in hours] == [f"2024-03-01T{k}:00:00+01:00" for k in (10, 11, 12, 13)]
    assert hours[0]["valid_s"] == pytest.approx(1800, abs=1)  # the recording starts at 10:30
    assert hours[1]["valid_s"] == pytest.approx(3600, abs=1)
    # movement from 11:30 to 12:00: only the 11:00 hour shows arm use and activities
    use = [h["arm_use_percent"] for h in hours]
    assert use[1] > 5 * max(use[0], use[2], use[3])
    counts = [h["activity_count"] for h in hours]
    assert counts[1] > 0 and counts[1] == max(counts)
    assert sum(counts) == record["activity.method2.count"]
    assert hours[1]["distance_weighted_area"] >= max(h["distance_weighted_area"] for h in hours)
    assert "by_day" not in record  # shorter than a day


def test_daily_summaries_and_no_start_time():
    imu = _recording(30.0, 1.0, [(2.0, 3.0), (26.0, 28.0)])
    _, record = compute_metrics(imu, start_time="2024-03-01T22:00:00")
    days = record["by_day"]
    assert [d["start"][:10] for d in days] == ["2024-03-01", "2024-03-02", "2024-03-03"]
    assert days[0]["valid_s"] == pytest.approx(2 * 3600, abs=2)  # 22:00 to midnight
    assert days[1]["valid_s"] == pytest.approx(24 * 3600, abs=2)
    assert len(record["by_hour"]) == 30
    # without a start time: periods start at the first sample, unlabelled
    _, plain = compute_metrics(imu)
    assert plain["by_day"][0]["start"] == "" and plain["by_day"][0]["start_ns"] == 0
    assert len(plain["by_day"]) == 2


def test_info_and_viewer_show_the_periods(tmp_path):
    from click.testing import CliRunner

    from imulog.archive import TrialReader, write_trial
    from imulog.cli import cli
    from imulog.model import Recording
    from imulog.steps.metrics import run_metrics
    from imulog.view.report import metrics_markdown

    imu = _recording(2.5, 5.0, [(0.5, 1.0)])
    trial = write_trial(
        tmp_path / "home.mcap",
        Recording(imus=[imu], metadata={"imulog.trial": {"start_time": "2024-05-02T09:15:00+02:00"}}),
    )
    run_metrics(trial)
    out = CliRunner().invoke(cli, ["info", str(trial)])
    assert out.exit_code == 0, out.output
    lines = out.output.splitlines()
    k = lines.index("daily life (per hour, from imulog.metrics):")
    assert lines[k + 2].split()[0] == "2024-05-02T09:00:00+02:00" and lines[k + 3].split()[0].startswith(
        "2024-05-02T10"
    )
    with TrialReader(trial) as reader:
        record = reader.metadata["imulog.metrics"]
    assert len(record["by_hour"]) == 3
    text = metrics_markdown(record)
    assert "## per hour" in text and "| 2024-05-02T10:00:00+02:00 | 1.00 |" in text
