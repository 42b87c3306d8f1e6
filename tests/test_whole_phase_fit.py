"""The whole-phase fit of issue 31 point 1's thirteenth round (benchmarks/phase_fit.py, an experiment, not part of
the method): the greedy decomposition recovers known overlapping submovements, the rotation angle as a regressor
absorbs gravity leaking through a sensor's scale error, and the evidence against given boundaries is small when
they are right and large when the last submovement is cut off."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from phase_fit import basis, decompose, fit_times, mj_derivatives  # noqa: E402

RATE = 20.0  # Hz: the benchmark's block means
SD = 0.02 / np.sqrt(6.0)  # m/s^2: the simulator's accelerometer noise per 114.9-Hz sample, as a 20-Hz block mean
ONSETS = np.array([0.0, 1.6])  # s
DURATIONS = np.array([3.0, 2.6])  # s: the phase ends at 4.2 s, its second submovement overlapping the first
AMPLITUDES = np.array([[0.20, 0.05, 0.02], [0.06, 0.02, 0.01]])  # m


def phase(leak: float = 0.0, seed: int = 0):
    """A two-submovement phase (0-4.2 s) with 1 s of rest before and 1.5 s after, in white noise: times (s),
    acceleration (N, 3, m/s^2), velocity (N, 3, m/s), the rotation angle (N, 3, rad) and the leak it causes."""
    t = np.arange(-1.0, 5.7, 1.0 / RATE)
    a = basis(t, ONSETS, DURATIONS, 2) @ AMPLITUDES
    theta = np.column_stack([1.2 * mj_derivatives((t - 0.2) / 1.5)[0].cumsum() / (RATE * 1.5), 0 * t, 0 * t])
    a = a + leak * 9.81 * theta[:, [0]] * np.array([0.0, 0.0, 1.0])  # a scale error of the rotation's axis
    a = a + np.random.default_rng(seed).normal(scale=SD, size=a.shape)
    v = np.cumsum(a, axis=0) / RATE
    return t, a, v, theta


def test_the_minimum_jerk_derivatives_integrate_to_each_other():
    tau = np.linspace(-0.2, 1.2, 14001)
    d1, d2, d3 = mj_derivatives(tau)
    h = tau[1] - tau[0]
    assert np.allclose(np.cumsum(d2) * h, d1, atol=2e-3)
    assert np.allclose(np.cumsum(d3) * h, d2, atol=2e-2)
    assert abs(np.sum(d1) * h - 1.0) < 1e-3  # the profile runs 0 -> 1


def test_the_decomposition_recovers_two_overlapping_submovements():
    t, a, v, _ = phase()
    dec = decompose(t, a, v)
    assert dec.k == 2
    assert abs(dec.onset_s - 0.0) < 0.05
    assert abs(dec.offset_s - 4.2) < 0.05
    assert np.allclose(np.sort(dec.onsets_s), ONSETS, atol=0.1)


def test_the_rotation_angle_absorbs_gravity_leaking_through_a_scale_error():
    t, a, v, theta = phase(leak=0.01)  # 1 % of a 1.2-rad rotation over 1.5 s: 0.12 m/s^2, about the movement's size
    with_angle = fit_times(t, a, ONSETS, DURATIONS, 2, extra=theta)
    without = fit_times(t, a, ONSETS, DURATIONS, 2)
    assert np.sqrt(with_angle.sse / with_angle.n) < 1.3 * SD  # at the noise
    assert np.sqrt(without.sse / without.n) > 1.5 * SD  # the model alone cannot explain it
    assert abs(with_angle.offset_s - 4.2) < 0.05


def test_the_evidence_is_small_for_right_boundaries_and_large_for_a_cut_off_last_submovement():
    t, a, v, _ = phase(seed=3)
    free = fit_times(t, a, ONSETS, DURATIONS, 2)
    right = fit_times(t, a, ONSETS, DURATIONS, 2, fixed_onset_s=0.0, fixed_offset_s=4.2)
    early = fit_times(t, a, ONSETS, DURATIONS, 2, fixed_onset_s=0.0, fixed_offset_s=3.6)
    assert free.n * np.log(right.sse / free.sse) < 10.0  # a chi-square of 2 degrees of freedom, far out
    assert free.n * np.log(early.sse / free.sse) > 50.0
