"""Histogram of distance traversed (Doshi 2011 ch. 5) and smoothness indicators against analytic values."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process.metrics import (
    DistanceHistogramParams,
    VelocityPeakParams,
    average_consecutive,
    distance_histogram,
    log_dimensionless_jerk,
    normalized_jerk,
    progress_areas,
    smoothness,
    sparc,
    velocity_peaks,
    weighted_area,
)
from imulog.process.metrics.distance import windowed_distance

# ---------------------------------------------------------------- histogram of distance traversed


def _doshi_a3_loop(raw: np.ndarray, f_sample: float, m_in: float, win_in: float) -> np.ndarray:
    """Line-by-line transcription of Appendix A.3 (MATLAB, 1-based) into Python loops: dist (N, 3)."""
    a = raw.shape[0]
    m = int(round(m_in * f_sample))
    mov_avg = raw.copy()
    for i in range(m, a - m):  # MATLAB i = m+1 .. a-m
        mov_avg[i] = raw[i - m : i + m + 1].sum(axis=0) / (2 * m + 1)
    hpf = raw - mov_avg
    t_sample = 1.0 / f_sample
    win = int(round(win_in * f_sample))
    part = int(np.ceil(a / win))
    vel = np.zeros_like(raw)
    dist = np.zeros_like(raw)
    for j in range(raw.shape[1]):
        for i in range(part):
            vel[i * win, j] = 0
            dist[i * win, j] = 0
            for k in range(1, win):
                idx = i * win + k
                if idx >= a:
                    break
                if raw[idx, j] > raw[idx - 1, j]:
                    vel[idx, j] = vel[idx - 1, j] + t_sample * hpf[idx, j]
                else:
                    vel[idx, j] = vel[idx - 1, j] - t_sample * hpf[idx, j]
                dist[idx, j] = dist[idx - 1, j] + t_sample * vel[idx - 1, j]
    return dist


def test_vectorised_distance_equals_the_published_loop():
    rng = np.random.default_rng(0)
    raw = np.cumsum(rng.normal(0, 0.05, (437, 3)), axis=0)  # 43.7 s at 10 Hz: last window is partial
    ours = windowed_distance(raw, 10.0, DistanceHistogramParams())
    np.testing.assert_allclose(ours, _doshi_a3_loop(raw, 10.0, 0.5, 5.0), atol=1e-12)
    si = windowed_distance(raw, 10.0, DistanceHistogramParams(acc_unit="m/s^2"))
    np.testing.assert_allclose(si, 9.80665 * ours, atol=1e-12)


def test_histogram_of_rest_is_all_in_the_first_bin():
    acc = np.tile([0.0, 0.0, 1.0], (600, 1))
    result = distance_histogram(acc, 10.0)
    assert result.histogram_percent[0] == pytest.approx(100.0)
    assert result.histogram_percent.sum() == pytest.approx(100.0)
    assert result.weighted_area == 0.0
    assert len(result.window_distance_cm) == 12


def test_distance_restarts_at_every_window():
    rng = np.random.default_rng(1)
    acc = rng.normal(0, 0.2, (1000, 3))
    result = distance_histogram(acc, 50.0, DistanceHistogramParams(window_s=2.0))
    assert np.all(result.distance_cm[::100] == 0)
    assert np.all(result.distance_cm[1::100] == 0)  # v starts at 0, so s moves from the third sample on
    assert result.histogram_percent.sum() == pytest.approx(100.0)


def test_weighted_area_is_linear_above_the_start():
    centres = np.arange(1.0, 121.0)
    hist = np.zeros(120)
    hist[[59, 60, 61, 119]] = [10.0, 5.0, 2.0, 1.0]  # 60, 61, 62 and 120 cm
    assert weighted_area(hist, centres, 60.0) == pytest.approx(0 * 10 + 1 * 5 + 2 * 2 + 60 * 1)


def _activity_day(gain: float, seed: int, rate: float = 10.0, minutes: float = 3.0) -> np.ndarray:
    """Repetitive 1-D activity (Doshi Table 5.1 activity 1) whose acceleration scales with ``gain``."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(minutes * 60 * rate)) / rate
    period = 2.5
    phase = (t % period) / period
    burst = np.where(phase < 0.6, np.sin(2 * np.pi * phase / 0.6), 0.0)
    acc = np.column_stack([np.zeros_like(t), gain * burst, np.ones_like(t)])
    return acc + rng.normal(0, 0.01, acc.shape)


def test_eight_day_use_case_areas_rise_with_ability():
    """Doshi's 8-day trial: an arm moving more vigorously each day covers larger distances per 5 s window."""
    gains = np.linspace(3.0, 6.0, 8)
    results = [distance_histogram(_activity_day(g, seed=d), 10.0) for d, g in enumerate(gains)]
    hists = np.stack([r.histogram_percent for r in results])
    two_day = average_consecutive(hists, 2)
    assert two_day.shape == (4, 120)
    centres = results[0].bin_centres_cm
    areas = [weighted_area(h, centres, 60.0) for h in two_day]
    assert np.all(np.diff(areas) > 0)
    np.testing.assert_allclose(progress_areas(hists, centres, 2), areas)
    assert average_consecutive(hists, 4).shape == (2, 120)
    np.testing.assert_allclose(average_consecutive(hists, 8)[0], hists.mean(axis=0))


# ---------------------------------------------------------------- smoothness


def _minimum_jerk_speed(duration_s: float, amplitude_m: float, rate: float) -> np.ndarray:
    tau = np.arange(0, duration_s + 0.5 / rate, 1 / rate) / duration_s
    return amplitude_m / duration_s * 30 * tau**2 * (1 - tau) ** 2


@pytest.mark.parametrize(("duration", "amplitude"), [(1.0, 0.3), (2.5, 0.05)])
def test_minimum_jerk_reach_has_the_analytic_jerk_values(duration, amplitude):
    v = _minimum_jerk_speed(duration, amplitude, 500.0)
    # integral of jerk^2 of a 1-D minimum-jerk reach = 720 L^2 / T^5, v_peak = 1.875 L / T
    assert normalized_jerk(v, 500.0) == pytest.approx(np.sqrt(360.0), rel=2e-3)
    assert log_dimensionless_jerk(v, 500.0) == pytest.approx(-np.log(720 / 1.875**2), abs=5e-3)
    assert velocity_peaks(v) == 1


def test_sub_movements_lower_smoothness():
    rate = 200.0
    one = _minimum_jerk_speed(1.0, 0.3, rate)
    two = np.zeros(int(1.6 * rate) + 1)
    two[: len(one)] += one
    two[int(0.6 * rate) : int(0.6 * rate) + len(one)] += one  # a second sub-movement starting at 0.6 s
    assert velocity_peaks(two) == 2
    s1, s2 = smoothness(one[:, None], rate), smoothness(np.column_stack([two, 0 * two]), rate)
    assert s2.velocity_peaks == 2 and s1.velocity_peaks == 1
    assert s2.normalized_jerk > s1.normalized_jerk
    assert s2.ldlj < s1.ldlj
    assert s2.sparc < s1.sparc < 0


def test_sparc_is_amplitude_invariant_and_peaks_ignore_small_ripples():
    v = _minimum_jerk_speed(1.2, 0.2, 100.0)
    assert sparc(v, 100.0) == pytest.approx(sparc(7.0 * v, 100.0))
    rippled = v + 0.01 * v.max() * np.sin(np.linspace(0, 40 * np.pi, len(v)))
    assert velocity_peaks(rippled) == 1
    assert velocity_peaks(rippled, VelocityPeakParams(min_prominence_fraction=0.0)) > 1  # ripple maxima near the top


@pytest.mark.parametrize(
    ("trial", "separable"),
    [("05_undisturbed_slow_rotation_with_breaks_B", True), ("14_undisturbed_slow_translation_with_breaks_B", False)],
)
def test_real_broad_windows_in_motion_traverse_more_than_windows_at_rest(shared_data, trial, separable):
    """BROAD (real IMU, 286 Hz): 5 s windows inside the movement blocks vs windows inside the 10 s breaks.

    Rotations tilt gravity across the axes and every moving window beats every resting one; the slow
    translations of trial 14 accelerate so little that the noise, which the slope-sign rectification
    accumulates (Doshi 5.2.1: short windows are noise-dominated), overlaps them: only the medians differ.
    """
    import h5py

    with h5py.File(shared_data / "broad" / f"{trial}.hdf5") as f:
        rate = float(f.attrs["sampling_rate"])
        acc_g = f["imu_acc"][:] / 9.80665
        movement = f["movement"][:].astype(bool)
    result = distance_histogram(acc_g, rate)
    win = int(round(5.0 * rate))
    n = len(acc_g) // win
    blocks = movement[: n * win].reshape(n, win)
    moving, resting = (
        result.window_distance_cm[:n][blocks.all(axis=1)],
        result.window_distance_cm[:n][~blocks.any(axis=1)],
    )
    assert len(moving) >= 10 and len(resting) >= 10
    assert np.median(moving) > np.median(resting)
    if separable:
        assert moving.min() > resting.max()
