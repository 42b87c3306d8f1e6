"""Arm usage and activity counts (Doshi 2011 ch. 4) on constructed signals, synthetic ADL and real BROAD data."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from imulog.process.metrics import (
    ActivityCountParams,
    ArmUsageParams,
    acc_to_g,
    activity_count_dead_period,
    activity_count_sign,
    adc_to_g,
    arm_usage,
    dead_period_intervals,
    estimate_noise_floor,
    estimate_noise_level,
)

# ---------------------------------------------------------------- synthetic ADL with known activities


def synthetic_adl(rate_hz: float, n_activities: int, seed: int, noise_g: float = 0.004, static_s: float = 600.0):
    """Wrist accelerometer (g) at rest between ``n_activities`` reach-and-tilt movements; 10-bit ADC quantised.

    Each activity tilts the forearm by 20-40 deg and back (gravity moves between axes, as in any real reach) and
    adds a linear acceleration; rests last 2.5-6 s. Returns (acc_g (N, 3), truth [start, end) sample indices,
    a static recording of ``static_s`` seconds of the same sensor, as Doshi's noise characterisation).
    """
    rng = np.random.default_rng(seed)

    def rest(seconds: float) -> np.ndarray:
        return np.tile([0.0, 0.0, 1.0], (int(seconds * rate_hz), 1))

    parts = [rest(rng.uniform(3, 6))]
    truth = []
    for _ in range(n_activities):
        duration = rng.uniform(1.5, 3.0)
        n = int(duration * rate_hz)
        tau = np.linspace(0, 1, n)
        angle = np.deg2rad(rng.uniform(20, 40)) * np.sin(np.pi * tau) ** 2
        amplitude = rng.uniform(0.2, 0.4)
        lin = amplitude / duration**2 * (60 * tau - 180 * tau**2 + 120 * tau**3) / 9.80665 * np.sin(2 * np.pi * tau)
        start = sum(len(p) for p in parts)
        parts.append(np.column_stack([np.sin(angle) + lin, 0.5 * lin, np.cos(angle)]))
        truth.append((start, start + n))
        parts.append(rest(rng.uniform(2.5, 6)))
    acc = np.concatenate(parts) + rng.normal(0, noise_g, (sum(len(p) for p in parts), 3))
    static = rest(static_s) + rng.normal(0, noise_g, (int(static_s * rate_hz), 3))
    return adc_to_g(np.round(512 + 256 * acc)), np.array(truth), adc_to_g(np.round(512 + 256 * static))


def _iou(a: tuple[int, int], b: tuple[int, int]) -> float:
    inter = max(0, min(a[1], b[1]) - max(a[0], b[0]))
    return inter / (max(a[1], b[1]) - min(a[0], b[0]))


# ---------------------------------------------------------------- arm usage


def test_adc_conversion_follows_doshi_421():
    assert adc_to_g(np.array([512, 768, 256])).tolist() == [0.0, 1.0, -1.0]


def test_arm_usage_counts_changes_above_noise_level():
    n = 200
    acc = np.zeros((n, 3))
    x_changes = np.arange(10, 110, 10)  # 10 changes of 0.05 g on x
    y_changes = np.array([20, 30, 40, 150, 160])  # 5 on y, 3 of them on the same samples as x
    for i in x_changes:
        acc[i:, 0] += 0.05
    for i in y_changes:
        acc[i:, 1] -= 0.03
    acc[:, 2] += 0.01 * (np.arange(n) % 2)  # z toggles by 0.01 g every sample: below the 0.022 g noise level
    result = arm_usage(acc)
    np.testing.assert_allclose(result.per_axis_percent, 100 * np.array([10, 5, 0]) / n)
    assert result.overall_percent == pytest.approx(100 * len(set(x_changes) | set(y_changes)) / n)
    assert arm_usage(acc, ArmUsageParams(noise_level_g=0.005)).per_axis_percent[2] == pytest.approx(100 * (n - 1) / n)


def test_noise_level_from_static_recording_gives_zero_usage_at_rest():
    rng = np.random.default_rng(3)
    static = np.array([0, 0, 1.0]) + rng.normal(0, 0.006, (18000, 3))  # Doshi: 30 min at 10 Hz
    level = estimate_noise_level(static)
    np.testing.assert_allclose(level.std, 0.006, rtol=0.05)
    np.testing.assert_allclose(level.diff_std, 0.006 * np.sqrt(2), rtol=0.05)
    assert arm_usage(static, ArmUsageParams(level.threshold_g("diff_peak"))).overall_percent == 0.0
    # a second recording of the same sensor at rest: a few outliers at most
    other = np.array([0, 0, 1.0]) + rng.normal(0, 0.006, (6000, 3))
    assert arm_usage(other, ArmUsageParams(level.threshold_g("diff_peak"))).overall_percent < 0.5
    with pytest.raises(ValueError):
        level.threshold_g("max")


def test_arm_usage_of_synthetic_adl_covers_the_activities():
    acc, truth, _ = synthetic_adl(10.0, 8, seed=1)
    active = arm_usage(acc).active_any
    inside = np.zeros(len(acc), bool)
    for s, e in truth:
        inside[s:e] = True
    # quantised noise of 0.004 g std rarely crosses 0.022 g between samples at rest; the tilts always do
    assert active[~inside].mean() < 0.02
    assert active[inside].mean() > 0.5


# ---------------------------------------------------------------- activity counts


def test_dead_period_rule_splits_at_exactly_dead_zeros():
    sig = np.zeros(40)
    sig[5:10] = 1
    sig[17:22] = 1  # 7 zeros between the bursts (samples 10..16)
    assert dead_period_intervals(sig, 7).tolist() == [[5, 10], [17, 22]]
    assert dead_period_intervals(sig, 8).tolist() == [[5, 22]]
    assert dead_period_intervals(np.zeros(10), 3).shape == (0, 2)
    sig[30] = 1  # a one-sample spike after a dead period: an activity unless shorter ones are dropped
    assert dead_period_intervals(sig, 7).tolist() == [[5, 10], [17, 22], [30, 31]]
    assert dead_period_intervals(sig, 7, min_samples=2).tolist() == [[5, 10], [17, 22]]


def test_method1_counts_sign_changes_about_the_mean():
    rate, f, periods = 50.0, 0.5, 6
    t = np.arange(int(periods / f * rate)) / rate
    acc = np.column_stack([np.cos(2 * np.pi * f * t), np.zeros_like(t), np.ones_like(t)])
    result = activity_count_sign(acc)
    assert result.per_axis.tolist() == [2 * periods, 0, 0]
    assert result.count == 2 * periods
    assert len(result.intervals) == result.count
    assert result.intervals[-1, 1] == len(t)


@pytest.mark.parametrize(("rate_hz", "seed"), [(10.0, 0), (10.0, 1), (115.0, 2), (115.0, 3)])
def test_method2_counts_synthetic_adl_activities(rate_hz, seed):
    n_act = 6 + seed
    acc, truth, static = synthetic_adl(rate_hz, n_act, seed=seed)
    params = ActivityCountParams.for_rate(rate_hz, noise_floor_g=0.0)
    floor = estimate_noise_floor(static, params)
    result = activity_count_dead_period(acc, ActivityCountParams.for_rate(rate_hz, noise_floor_g=floor))
    assert result.count == n_act
    for detected, true in zip(result.intervals, truth, strict=True):
        assert _iou(tuple(detected), tuple(true)) > 0.5
    # method 1 is fooled by noise about the mean, as Doshi reports (Fig. 4.5)
    assert activity_count_sign(acc).count > 3 * n_act


def test_method2_published_parameters_at_10_hz():
    p = ActivityCountParams.for_rate(10.0)
    assert (p.m_samples, p.dead_samples, p.noise_floor_g) == (5, 10, 0.09)
    assert ActivityCountParams.for_rate(115.0).m_samples == 58
    with pytest.raises(ValueError):
        ActivityCountParams(m_samples=0)


# ---------------------------------------------------------------- real data: BROAD trials with three 10 s breaks


@pytest.mark.parametrize(
    "trial", ["05_undisturbed_slow_rotation_with_breaks_B", "14_undisturbed_slow_translation_with_breaks_B"]
)
def test_method2_finds_the_four_movement_blocks_of_broad(shared_data, trial):
    with h5py.File(shared_data / "broad" / f"{trial}.hdf5") as f:
        rate = float(f.attrs["sampling_rate"])
        acc = acc_to_g(f["imu_acc"][:])
        movement = f["movement"][:].astype(bool)
    edges = np.diff(np.concatenate([[0], movement.astype(int), [0]]))
    truth = np.column_stack([np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)])
    assert len(truth) == 4
    static = acc[: truth[0, 0]]  # the sensor lies still before the first movement
    floor = estimate_noise_floor(static, ActivityCountParams.for_rate(rate, noise_floor_g=0))
    # dead period 5 s: shorter than the 10 s breaks, longer than pauses within a movement block
    result = activity_count_dead_period(acc, ActivityCountParams.for_rate(rate, dead_s=5.0, noise_floor_g=floor))
    assert result.count == 4
    for (d0, d1), (t0, t1) in zip(result.intervals, truth, strict=True):
        overlap = max(0, min(d1, t1) - max(d0, t0))
        assert overlap >= 0.95 * (t1 - t0)  # the movement block is found...
        assert overlap >= 0.8 * (d1 - d0)  # ...and mostly only it (trial 14 has a bump 3.4 s after block 3)
    # arm usage with the static diff-peak as noise level: none at rest before the first movement
    level = estimate_noise_level(static).threshold_g("diff_peak")
    usage = arm_usage(acc, ArmUsageParams(level))
    assert usage.active_any[: truth[0, 0]].sum() == 0
    assert usage.active_any[movement].mean() > 10 * max(usage.active_any[~movement].mean(), 1e-4)
