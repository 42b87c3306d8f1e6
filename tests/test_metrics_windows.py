"""Metrics of long recordings core by core: the record of the whole-recording computation, in bounded memory."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from imulog.converters import axivity

from imulog.archive import TrialReader
from imulog.archive.streaming import write_trial_streaming
from imulog.simulate.home import HomeParams, write_home_cwa
from imulog.steps.metrics import run_metrics
from imulog.steps.metrics_windows import DeadPeriodStitcher
from imulog.steps.windows import WindowParams


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
    run_metrics(whole, windows=WindowParams(core_s=86400.0))  # one window: the whole recording at once
    run_metrics(cored, windows=WindowParams(core_s=1500.0, margin_s=10.0))
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
        # cumulative-sum rounding (below 1e-9 cm), then counts on a 2**-10 cm grid (docs/schemas.md): a value that
        # falls on a half step can round to the next grid point, never further
        np.testing.assert_array_equal(np.isnan(da.values), np.isnan(db.values))
        assert np.nanmax(np.abs(da.values - db.values)) <= 2.0**-10
        ia, ib = a.read("/derived/metrics/activity/ax6_4321"), b.read("/derived/metrics/activity/ax6_4321")
        np.testing.assert_array_equal(ia.start_ns, ib.start_ns)
        np.testing.assert_array_equal(ia.end_ns, ib.end_ns)
        assert b.runs()[max(b.runs())]["params"]["windows"] == {"core_s": 1500.0, "margin_s": 10.0}


def test_one_window_equals_the_published_functions_on_the_whole():
    """A lab-length recording is one window: the record equals Doshi's functions applied to the whole signal
    (what the step computed before it had windows), with a long gap and a bridged one in it."""
    from imulog.model import ImuStream
    from imulog.process.gaps import prepare
    from imulog.process.metrics import (
        ArmUsageParams,
        acc_to_g,
        activity_count_dead_period,
        activity_count_sign,
        arm_usage,
        distance_histogram,
    )
    from imulog.process.metrics.distance import histogram_percent
    from imulog.steps.metrics import MetricsParams, compute_metrics

    rate, n = 100.0, 60_000
    rng = np.random.default_rng(5)
    k = np.arange(n)
    acc = np.column_stack([np.sin(k / 40.0) * (k % 3000 < 1500), np.cos(k / 70.0), np.full(n, 9.81)])
    acc = acc + rng.normal(0, 0.05, (n, 3))
    acc[20_000:20_003] = np.nan  # bridged
    acc[40_000:40_500] = np.nan  # a long gap
    t = (k * 1e7).astype(np.int64) + 1_700_000_000 * 10**9
    imu = ImuStream(name="wrist", t_ns=t, acc=acc, gyr=np.zeros((n, 3)))
    p = MetricsParams()
    streams, record = compute_metrics(imu, p)
    (acc_g,), report = prepare([acc_to_g(acc)], None)
    usage = arm_usage(acc_g, ArmUsageParams(p.noise_level_g, p.arm_usage_rate_hz), t_ns=t)
    m1 = activity_count_sign(acc_g)
    m2 = activity_count_dead_period(acc_g, p.activity(rate))
    dist = distance_histogram(acc_g, rate, p.distance())
    unknown = ~np.isfinite(acc_g).all(axis=1)
    d_cm = np.where(unknown, np.nan, dist.distance_cm)
    assert record["arm_usage.overall_percent"] == pytest.approx(usage.overall_percent, abs=1e-4)
    assert record["arm_usage.x_percent"] == pytest.approx(usage.per_axis_percent[0], abs=1e-4)
    assert record["activity.method1.count"] == m1.count
    assert record["activity.method1.per_axis"] == m1.per_axis.tolist()
    assert record["activity.method2.count"] == m2.count and record["activity.method2.per_axis"] == m2.per_axis.tolist()
    hist = histogram_percent(d_cm, p.distance())
    assert record["distance.histogram_percent"] == pytest.approx(hist, abs=1e-4)
    assert record["distance.window_median_cm"] == pytest.approx(np.median(dist.window_distance_cm), abs=1e-4)
    assert record["gaps.missing_samples"] == report.missing == 503 and record["gaps.runs"] == [
        list(r) for r in report.runs
    ]
    activity, distance = streams
    np.testing.assert_allclose(distance.values[:, 0], d_cm, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(activity.start_ns, t[m2.intervals[:, 0]])
    assert "computed" not in record  # one window
