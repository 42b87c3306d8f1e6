"""Metrics of long recordings core by core: the record of the whole-recording computation, in bounded memory."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from converters import axivity
from imulog.archive import TrialReader
from imulog.archive.streaming import write_trial_streaming
from imulog.simulate.home import HomeParams, write_home_cwa
from imulog.steps.long_metrics import DeadPeriodStitcher, MetricCores
from imulog.steps.metrics import run_metrics


def test_stitcher_equals_dead_period_intervals():
    from imulog.process.metrics.activity import dead_period_intervals

    rng = np.random.default_rng(3)
    signal = (rng.random(20_000) < 0.03).astype(float)
    signal[5000:5400] = 1.0
    whole = dead_period_intervals(signal, dead_samples=25, min_samples=3)
    stitcher = DeadPeriodStitcher(25, 3)
    for a, b in [(0, 4999), (4999, 5200), (5200, 5201), (5201, 13000), (13000, 20_000)]:
        stitcher.add(a + np.flatnonzero(signal[a:b] != 0))
    np.testing.assert_array_equal(stitcher.finish(), whole)


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    folder = tmp_path_factory.mktemp("longmetrics")
    cwa = folder / "home.cwa"
    write_home_cwa(cwa, HomeParams(days=2.5 / 24, rate_hz=25.0, seed=2, start="2024-03-04T09:40:00"))
    return write_trial_streaming(folder / "home.mcap", axivity.iter_chunks(cwa, blocks_per_chunk=300))


def test_cores_equal_the_whole(trial, tmp_path):
    whole, cored = tmp_path / "whole.mcap", tmp_path / "cored.mcap"
    shutil.copy(trial, whole)
    shutil.copy(trial, cored)
    run_metrics(whole)
    run_metrics(cored, cores=MetricCores(core_s=1500.0, overlap_s=10.0))
    with TrialReader(whole) as a, TrialReader(cored) as b:
        ra, rb = a.metadata["imulog.metrics"], b.metadata["imulog.metrics"]
        for key in (
            "arm_usage.overall_percent",
            "arm_usage.x_percent",
            "activity.method1.count",
            "activity.method2.count",
            "activity.method2.per_axis",
            "activity.method2.total_s",
            "distance.weighted_area",
            "distance.histogram_percent",
            "distance.window_median_cm",
            "distance.window_max_cm",
        ):
            assert rb[key] == pytest.approx(ra[key], rel=1e-6, abs=1e-6), key
        assert rb["activity.method1.per_axis"] == ra["activity.method1.per_axis"]
        assert [h["start"] for h in rb["by_hour"]] == [h["start"] for h in ra["by_hour"]]
        for ha, hb in zip(ra["by_hour"], rb["by_hour"], strict=True):
            for key in ("valid_s", "arm_use_percent", "activity_count", "distance_weighted_area"):
                assert hb[key] == pytest.approx(ha[key], rel=1e-6, abs=1e-6), (ha["start"], key)
        da, db = a.read("/derived/metrics/distance/ax6_4321"), b.read("/derived/metrics/distance/ax6_4321")
        np.testing.assert_array_equal(da.t_ns, db.t_ns)
        np.testing.assert_allclose(da.values, db.values, rtol=1e-9, atol=1e-9)  # cumulative-sum rounding only
        ia, ib = a.read("/derived/metrics/activity/ax6_4321"), b.read("/derived/metrics/activity/ax6_4321")
        np.testing.assert_array_equal(ia.start_ns, ib.start_ns)
        np.testing.assert_array_equal(ia.end_ns, ib.end_ns)
        assert b.runs()[max(b.runs())]["params"]["cores"] == {"core_s": 1500.0, "overlap_s": 10.0}
