"""The information limit of a phase's boundaries (benchmarks/boundary_limit.py): the model's Jacobian, the
Cramer-Rao bound against a Monte-Carlo spread of the least-squares oracle, and the oracle's phases against the
simulator's truth."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from boundary_limit import (  # noqa: E402
    Noise,
    Phase,
    conditions_options,
    cramer_rao,
    jacobian,
    numeric_jacobian,
    oracle_errors,
    pack,
    phases_of,
    sample_times,
)

from imulog.simulate import simulate  # noqa: E402
from imulog.simulate.core import motion_plan  # noqa: E402


def _phase(onsets, durations, weights, rot_end=None) -> Phase:
    onsets, durations = np.asarray(onsets, float), np.asarray(durations, float)
    end = float(np.max(onsets + durations))
    return Phase(
        onsets_s=onsets,
        durations_s=durations,
        weights=np.asarray(weights, float) / np.sum(weights),
        dp_m=np.array([0.2, 0.1, 0.1]),
        rotvec_rad=np.radians([10.0, 60.0, -20.0]),
        rot_onset_s=0.0,
        rot_end_s=end if rot_end is None else rot_end,
        rot_onset_tied=True,
        rot_end_tied=rot_end is None,
    )


@pytest.mark.parametrize("gyro", [False, True])
def test_the_analytic_jacobian_is_the_models_derivative(gyro):
    ph = _phase([0.0, 1.8, 3.0], [3.0, 1.5, 1.6], [1.0, 0.3, 0.2], rot_end=3.5)
    noise = Noise(0.02, np.radians(0.1), 114.9)
    theta = pack(ph, gyro)
    t = sample_times(ph, noise.rate_hz, 0.3)
    J, Jn = jacobian(theta, ph, t, noise, gyro), numeric_jacobian(theta, ph, t, noise, gyro)
    assert np.max(np.abs(J - Jn)) < 1e-6 * np.max(np.abs(Jn))


@pytest.mark.parametrize(
    ("onsets", "durations", "weights", "gyro"),
    [
        ([0.0], [4.0], [1.0], False),
        ([0.0, 2.2], [4.0, 2.0], [1.0, 0.25], False),
        ([0.0, 2.2], [4.0, 2.0], [1.0, 0.25], True),
    ],
)
def test_the_cramer_rao_bound_matches_the_oracles_monte_carlo_spread(onsets, durations, weights, gyro):
    """25-cm-class slow phases at the simulator's noise with 0.1 s of tolerance far away: the least-squares oracle
    is efficient, so its spread over 150 noise draws is the bound within 20 % (the sd of a 150-draw sd is ~6 %)."""
    ph = _phase(onsets, durations, weights)
    noise = Noise(0.02, np.radians(0.1), 114.9)
    rng = np.random.default_rng(5)
    errors = np.array([oracle_errors(ph, noise, gyro, rng) for _ in range(150)])
    assert np.all(np.isfinite(errors))
    bound = np.array(cramer_rao(ph, noise, gyro))
    spread = errors.std(axis=0)
    assert spread[1:] == pytest.approx(bound[1:], rel=0.2)  # offset and duration
    if not gyro:  # with the gyroscope the onset is pinned to a few ms by the rotation: compare the scale only
        assert spread[0] == pytest.approx(bound[0], rel=0.2)
    assert abs(errors[:, 2].mean()) < 3 * bound[2] / np.sqrt(len(errors)) + 1e-3  # no bias beyond the draws'


def test_more_noise_widens_the_bound_in_proportion():
    ph = _phase([0.0, 2.2], [4.0, 2.0], [1.0, 0.25])
    a = np.array(cramer_rao(ph, Noise(0.02, np.radians(0.1), 114.9), False))
    b = np.array(cramer_rao(ph, Noise(0.04, np.radians(0.1), 114.9), False))
    assert b == pytest.approx(2 * a, rel=1e-6)


def test_the_oracles_phases_are_the_simulators_truth():
    options = conditions_options(["stroke-slow"])["stroke-slow"]
    plan = motion_plan("r2g", seed=1, subject=0, repetitions=3, **options)
    truth = simulate("r2g", seed=1, subject=0, repetitions=3, **options).truth.phases
    phases = phases_of(plan)
    assert len(phases) == len(truth) == 12
    starts = np.array([iv.start_s for iv in plan.intervals if iv.task_index >= 0])
    for (rep, label, ph), start, a, b, r, lab in zip(
        phases, starts, truth.start_ns, truth.end_ns, truth.task_index, truth.labels, strict=True
    ):
        assert (rep, label) == (int(r), lab)
        assert start == pytest.approx(a * 1e-9, abs=1e-6)
        assert start + ph.duration_s == pytest.approx(b * 1e-9, abs=1e-6)
        assert (
            len(ph.onsets_s) >= 2 and ph.rot_onset_tied
        )  # stroke-slow: 2-4 submovements, the wrist starts with the hand


def test_the_fit_from_a_methods_boundaries_finds_a_single_reach():
    """The experiment without the oracle's gifts (a start from given boundaries, k by BIC): on one 4-s reach started
    0.15 s early and 0.3 s early at its end, it picks one submovement and lands within 0.05 s."""
    from boundary_limit import fit_from

    ph = _phase([0.0], [4.0], [1.0])
    noise = Noise(0.02, np.radians(0.1), 114.9)
    on, off, dur, k = fit_from(ph, noise, True, -0.15, 3.7, np.random.default_rng(2))
    assert k == 1
    assert abs(on) < 0.05 and abs(off) < 0.05 and abs(dur) < 0.05
