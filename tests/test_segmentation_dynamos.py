"""DynAMoS building blocks, the double-threshold detector and template matching on constructed signals."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process.segmentation.double_threshold import DoubleThresholdParams, double_threshold
from imulog.process.segmentation.dynamos import (
    DynamosParams,
    dynamos,
    lowpass_norm,
    otsu_threshold,
    postprocess,
    runs,
    threshold_value,
)
from imulog.process.segmentation.repetitions import best_subset, features, split_repetitions
from imulog.process.segmentation.template import build_template, match_template, normalised_xcorr

RATE = 100.0


def bump(n: int) -> np.ndarray:
    """Minimum-jerk speed profile of n samples (peak 1.875 at mid-point)."""
    tau = np.linspace(0, 1, n)
    return 30 * tau**2 * (1 - tau) ** 2


def test_runs_are_half_open():
    s, e = runs(np.array([0, 1, 1, 0, 1, 0, 0, 1], bool))
    assert s.tolist() == [1, 4, 7] and e.tolist() == [3, 5, 8]


def test_lowpass_removes_high_frequency_keeps_slow_rotation():
    t = np.arange(0, 20, 1 / RATE)
    slow = np.c_[np.sin(2 * np.pi * 0.3 * t), np.zeros_like(t), np.zeros_like(t)]
    fast = 0.5 * np.c_[np.zeros_like(t), np.sin(2 * np.pi * 10 * t), np.zeros_like(t)]
    norm = lowpass_norm(slow + fast, RATE, 1.5)
    core = slice(200, -200)
    np.testing.assert_allclose(norm[core], np.abs(slow[core, 0]), atol=0.02)


def test_otsu_separates_two_populations():
    rng = np.random.default_rng(1)
    values = np.r_[rng.normal(0.05, 0.01, 5000), rng.normal(1.0, 0.1, 2000)]
    thr = otsu_threshold(values)
    assert 0.1 < thr < 0.85
    assert threshold_value(values, "otsu") == thr
    assert threshold_value(values, 0.11) == pytest.approx(0.11 * values.max())
    with pytest.raises(ValueError):
        threshold_value(values, "median")


def test_short_movement_merges_with_closest_neighbour_only_when_in_range():
    norm = np.ones(1000)
    # durations 100, 100, 100, 30 (close to the 4th), 60: median 100, lo 80, hi 140
    start = np.array([0, 200, 400, 600, 635])
    end = np.array([100, 300, 500, 630, 700])
    s, e = postprocess(start, end, norm, 0.8, 1.4)
    # 600-630 (30) closest to 635-700: merged 600-700 (100) lies in [alpha M, beta M]
    assert s.tolist() == [0, 200, 400, 600] and e.tolist() == [100, 300, 500, 700]


def test_merge_refused_when_merged_duration_too_long_then_other_neighbour_tried():
    norm = np.ones(2000)
    # short one (20) at 410 is closest to the next (gap 5) but merging gives 170 > 140; previous: 100+gap
    start = np.array([0, 200, 300, 410, 435, 800])
    end = np.array([100, 300 - 5, 390, 430, 580, 900])
    s, e = postprocess(start, end, norm, 0.8, 1.4)
    assert (300, 430) in list(zip(s.tolist(), e.tolist(), strict=True))  # merged with the previous instead


def test_long_movement_splits_at_lowest_acceptable_minimum():
    n = 1000
    norm = np.ones(n)
    start = np.array([0, 150, 300, 450])
    end = np.array([100, 250, 400, 650])  # last one: 200 samples > 1.4 * 100
    norm[470] = 0.5  # lowest minimum, but the first part would be 20 samples: refused
    norm[550] = 0.6  # accepted: 100 + 100
    norm[600] = 0.7
    s, e = postprocess(start, end, norm, 0.8, 1.4)
    assert s.tolist() == [0, 150, 300, 450, 550] and e.tolist() == [100, 250, 400, 550, 650]


def test_dynamos_finds_separated_movements_and_splits_fused_pair():
    sig = np.zeros(3000)
    for a in (200, 700, 1200, 1700):
        sig[a : a + 150] = bump(150)
    sig[2200:2350] = bump(150)  # two movements with only a shallow dip between them
    sig[2340:2490] += bump(150)
    gyr = np.c_[sig, 0.2 * sig, np.zeros_like(sig)]
    seg = dynamos(gyr, RATE, DynamosParams(refine_boundaries=False))
    assert len(seg) == 6
    assert 2300 < seg.start[5] < 2400  # the fused pair was split near its dip
    refined = dynamos(gyr, RATE)
    assert np.all(refined.start <= seg.start) and np.all(refined.end >= seg.end)
    assert abs(refined.start[0] - 200) < abs(seg.start[0] - 200)


def test_repetition_split_and_event_selection():
    norm = np.zeros(4000)
    for rep in range(3):
        for k in range(2):
            a = 200 + rep * 1200 + k * 300
            norm[a : a + 100] = 1.0
    s, e = split_repetitions(norm, 3)
    assert s.tolist() == [200, 1400, 2600] and e.tolist() == [600, 1800, 3000]
    # 4-of-6 selection: the reference matches events 0, 2, 3, 5
    start = np.array([0, 150, 200, 400, 600, 700])
    end = np.array([100, 170, 300, 500, 640, 800])
    height = np.array([1.0, 0.3, 2.0, 2.0, 0.3, 1.0])
    trace = np.zeros(1000)
    for a, b, h in zip(start, end, height, strict=True):
        trace[a:b] = h
    d, h, _ = features(start, end, trace, RATE)
    ref = (np.array([1.0, 1.0, 1.0, 1.0]), np.array([1.0, 2.0, 2.0, 1.0]), np.array([1.0, 1.0, 2.0]))
    assert best_subset(d, h, start, end, RATE, ref, 4, 14) == (0, 2, 3, 5)


def test_double_threshold_detects_movements_and_ignores_noise():
    rng = np.random.default_rng(3)
    sig = rng.normal(0, 0.01, (4000, 3))
    truth = [(500, 650), (1500, 1700), (3000, 3120)]
    for a, b in truth:
        sig[a:b, 0] += 2.0 * bump(b - a)
    sig[2500:2510, 1] += 0.05  # tiny blip: below T1, not a movement
    s, e = double_threshold(sig, RATE, DoubleThresholdParams())
    assert len(s) == 3
    for (a, b), ds, de in zip(truth, s, e, strict=True):
        assert abs(ds - a) < 0.15 * RATE and abs(de - b) < 0.15 * RATE
    with pytest.raises(ValueError):
        double_threshold(sig, RATE, DoubleThresholdParams(t1=0.01, t2=0.1))


def test_template_matching_recovers_repeated_shape():
    rng = np.random.default_rng(4)
    shape = np.r_[np.zeros(20), bump(60), -0.5 * bump(30), np.zeros(20)]
    sig = rng.normal(0, 0.02, 5000)
    onsets = [300, 1100, 1900, 2700, 3600, 4400]
    for a in onsets:
        sig[a : a + len(shape)] += shape
    template = build_template(sig, np.array(onsets[:3]), np.array(onsets[:3]) + len(shape))
    assert normalised_xcorr(sig, template).max() > 0.95
    s, e, r = match_template(sig, template, marks=(20, 110))
    assert len(s) == len(onsets)
    np.testing.assert_array_less(np.abs(s - (np.array(onsets) + 20)), 3)
    assert np.all(e - s == 90) and np.all(r > 0.9)
