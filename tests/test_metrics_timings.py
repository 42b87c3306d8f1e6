"""Phase durations (R2G) and peg times (NHPT) from labelled intervals."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.model import Intervals
from imulog.process.metrics import NhptParams, compare_durations, nhpt_timings, phase_summary, phase_table
from imulog.process.metrics.timings import R2G_PHASES, repetition_durations


def _r2g_intervals(seed: int, reps: int = 25) -> tuple[Intervals, np.ndarray]:
    """Back-to-back R2G phases with random durations (s); returns the Intervals and the (reps, 4) durations."""
    rng = np.random.default_rng(seed)
    durations = rng.uniform(0.4, 2.0, (reps, 4))
    pauses = rng.uniform(0.5, 3.0, reps)
    starts, ends, labels, task = [], [], [], []
    t = 1_000_000_000
    for r in range(reps):
        t += int(pauses[r] * 1e9)
        for k, label in enumerate(R2G_PHASES):
            d = int(round(durations[r, k] * 1e9))
            starts.append(t)
            ends.append(t + d)
            labels.append(label)
            task.append(r + 1)
            t += d
    return Intervals("/derived/phases/wrist", np.array(starts), np.array(ends), labels, np.array(task)), durations


def test_phase_durations_reproduce_the_constructed_durations():
    phases, durations = _r2g_intervals(0)
    table = phase_table(phases)
    for k, label in enumerate(R2G_PHASES):
        np.testing.assert_allclose(table.durations(label), durations[:, k], atol=1e-9)
    summary = phase_summary(phases)
    assert list(summary) == list(R2G_PHASES)
    assert summary["lift"]["n"] == 25
    assert summary["lift"]["mean_s"] == pytest.approx(durations[:, 1].mean())
    assert summary["reach"]["std_s"] == pytest.approx(durations[:, 0].std())
    reps = repetition_durations(phases)
    assert sorted(reps) == list(range(1, 26))
    np.testing.assert_allclose([reps[i + 1] for i in range(25)], durations.sum(axis=1), atol=1e-8)


def test_compare_durations_pairs_by_repetition_and_label():
    truth, _ = _r2g_intervals(1)
    rng = np.random.default_rng(2)
    jitter = rng.integers(-40_000_000, 40_000_000, (len(truth), 2))  # +-40 ms on each boundary
    keep = np.ones(len(truth), bool)
    keep[5] = False  # the segmentation missed one phase
    est = Intervals(
        truth.topic,
        (truth.start_ns + jitter[:, 0])[keep],
        np.maximum(truth.end_ns + jitter[:, 1], truth.start_ns + jitter[:, 0])[keep],
        [lab for lab, k in zip(truth.labels, keep, strict=True) if k],
        truth.task_index[keep],
    )
    cmp = compare_durations(est, truth)
    assert len(cmp.keys) == len(truth) - 1
    assert cmp.missing == [(int(truth.task_index[5]), truth.labels[5])]
    assert cmp.extra == []
    assert cmp.max_abs_error_s <= 0.08
    expected = (jitter[:, 1] - jitter[:, 0])[keep] / 1e9
    np.testing.assert_allclose(np.sort(cmp.error_s), np.sort(expected), atol=1e-9)


def test_nhpt_peg_times():
    # 9 pegs: to_container 0.5 s, pause 0.2 s, place 1.0 + 0.1 k s, pause 0.3 s; then 9 removals and return_hand
    starts, ends, labels, task = [], [], [], []
    t, pick, place = 2.0, [], []

    def move(label, seconds, peg):
        nonlocal t
        starts.append(t), ends.append(t + seconds), labels.append(label), task.append(peg)
        t += seconds

    for k in range(9):
        move("to_container", 0.5, k + 1)
        pick.append(t - 2.0)
        t += 0.2
        move("place", 1.0 + 0.1 * k, k + 1)
        place.append(t - 2.0)
        t += 0.3
    for k in range(9):
        move("to_hole", 0.8, k + 1)
        t += 0.2
        move("remove", 0.9, k + 1)
        t += 0.2
    test_end = ends[-1] - 2.0
    move("return_hand", 1.0, 9)
    iv = Intervals(
        "/derived/phases/wrist", np.round(np.array(starts) * 1e9), np.round(np.array(ends) * 1e9), labels, task
    )
    result = nhpt_timings(iv)
    np.testing.assert_allclose(result.pickup_s, pick, atol=1e-9)
    np.testing.assert_allclose(result.place_s, place, atol=1e-9)
    np.testing.assert_allclose(result.transport_s, 0.2 + 1.0 + 0.1 * np.arange(9), atol=1e-9)
    np.testing.assert_allclose(result.place_movement_s, 1.0 + 0.1 * np.arange(9), atol=1e-9)
    np.testing.assert_allclose(result.return_s, 0.3 + 0.5, atol=1e-9)
    assert result.test_time_s == pytest.approx(test_end)
    assert result.as_dict()["n_pegs"] == 9
    with pytest.raises(ValueError, match="grasp"):
        nhpt_timings(iv, NhptParams(pickup_movement="grasp"))


def test_nhpt_times_of_the_simulated_test_are_the_zero_velocity_pauses():
    """Simulated NHPT: every pick-up and placement time is when the true hand speed drops to zero."""
    simulate = pytest.importorskip("imulog.simulate.core").simulate
    sim = simulate("nhpt", subject=2, seed=4)
    truth = sim.truth
    result = nhpt_timings(truth.phases)
    assert len(result.pickup_s) == 9 and len(result.place_s) == 9
    t0 = phase_table(truth.phases).start_ns.min()
    speed = np.linalg.norm(truth.velocity, axis=1)
    still = speed < 1e-6
    for event_s in np.concatenate([result.pickup_s, result.place_s]):
        i = np.searchsorted(truth.t_ns, t0 + int(round(event_s * 1e9)))  # first 10 ms grid point at/after the event
        assert still[i : i + 5].all()  # the hand rests for the pause (>= 50 ms)...
        assert speed[i - 3] > 0  # ...right after moving
    assert np.all(result.transport_s > result.place_movement_s)  # the grasp pause comes before the transport
    assert result.test_time_s > result.place_s[-1]
