"""R2G phases on simulated trials: exactly 100 phases, >= 97 % correct, onset/offset MAE < 0.08 s.

Trials come from :mod:`imulog.simulate` (several seeds and subjects, corrective sub-movements and residual
static velocity) and from an independent minimum-jerk gyroscope generator written here (other durations,
rests, noise and no calibration wave), so that the methods are not fitted to one generator.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from imulog.process.segmentation.pipeline import PhaseParams, segment_phases
from imulog.process.segmentation.repetitions import RepetitionParams, burst_mask

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from segmentation_accuracy import score  # noqa: E402

simulate = pytest.importorskip("imulog.simulate").simulate


@pytest.mark.parametrize(
    ("seed", "subject", "extra"),
    [(11, 0, 0.2), (12, 3, 0.2), (13, 5, 0.3), (14, 1, 0.0)],
)
def test_dynamos_on_simulated_r2g(seed, subject, extra):
    sim = simulate("r2g", seed=seed, subject=subject, extra_submovement_probability=extra, residual_velocity_mps=0.01)
    result = score(sim, PhaseParams())
    assert result["n_phases"] == 100
    assert result["correct"] >= 0.97
    assert result["mae_s"] < 0.08


def test_double_threshold_on_simulated_r2g_gives_100_phases():
    sim = simulate("r2g", seed=21, subject=2, extra_submovement_probability=0.2, residual_velocity_mps=0.01)
    result = score(sim, PhaseParams(method="double-threshold"))
    assert result["n_phases"] == 100
    assert result["correct"] >= 0.95


def _bump(n: int) -> np.ndarray:
    tau = np.linspace(0, 1, n)
    return 30 * tau**2 * (1 - tau) ** 2


def independent_trial(seed: int, rate: float = 100.0, n_rep: int = 25):
    """Gyroscope (rad/s) of 25 x 4 minimum-jerk rotations with small fidgets and wandering static velocity."""
    rng = np.random.default_rng(seed)
    durations = np.array([1.0, 1.3, 1.1, 0.9]) * rng.uniform(0.8, 1.25)
    angles = np.array([0.8, 1.4, 1.2, 0.9])
    axes = np.array([[0, 0.3, 1], [1, 0.2, 0.1], [-1, -0.2, -0.1], [0, -0.3, -1]], float)
    t, truth, fidgets = 3.0, [], []
    for r in range(n_rep):
        for p in range(4):
            d = durations[p] * rng.uniform(0.85, 1.15)
            truth.append((t, t + d, r + 1, p))
            rest = rng.uniform(2.5, 4.5) if p < 3 else rng.uniform(6.0, 9.0)
            if rng.random() < 0.15:  # a small fidget in the middle of the rest
                a = t + d + rng.uniform(1.0, rest - 1.5)
                fidgets.append((a, a + rng.uniform(0.3, 0.6)))
            t += d + rest
    n = int((t + 3) * rate)
    gyr = np.zeros((n, 3))
    for a, b, _, p in truth:
        i0, i1 = int(round(a * rate)), int(round(b * rate))
        axis = axes[p] + rng.normal(0, 0.15, 3)
        gyr[i0:i1] += np.outer(
            _bump(i1 - i0) / (b - a) * angles[p] * rng.uniform(0.7, 1.3), axis / np.linalg.norm(axis)
        )
    for a, b in fidgets:
        i0, i1 = int(round(a * rate)), int(round(b * rate))
        axis = rng.normal(size=3)
        gyr[i0:i1] += np.outer(_bump(i1 - i0) / (b - a) * rng.uniform(0.05, 0.15), axis / np.linalg.norm(axis))
    from scipy.signal import butter, sosfiltfilt

    wander = sosfiltfilt(butter(2, 0.5, fs=rate, output="sos"), rng.normal(size=(n, 3)), axis=0)
    gyr += 0.02 * wander / wander.std() + rng.normal(0, 0.01, (n, 3)) + rng.normal(0, 0.005, 3)
    return gyr, rate, np.array(truth)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_dynamos_on_independent_minimum_jerk_trials(seed):
    gyr, rate, truth = independent_trial(seed)
    ph = segment_phases(gyr, rate).phases
    assert len(ph) == 100
    assert np.all(np.bincount(ph.repetition)[1:] == 4)
    assert ph.labels[:4] == ["reach", "lift", "return_bottle", "return_hand"]
    s, e = ph.start / rate, (ph.end - 1) / rate
    correct, errors = 0, []
    for i in range(len(ph)):
        a, b = truth[(truth[:, 2] == ph.repetition[i]) & (truth[:, 3] == ph.phase[i])][0, :2]
        inter = max(0.0, min(b, e[i]) - max(a, s[i]))
        if inter / (max(b, e[i]) - min(a, s[i])) > 0.5:
            correct += 1
            errors += [abs(s[i] - a), abs(e[i] - b)]
    assert correct >= 97
    assert np.mean(errors) < 0.08


def _phases_against_truth(sim, n_rep: int):
    """Detected phases of a simulated R2G trial, checked against ``sim.truth`` (phases and the wave event)."""
    imu = sim.recording.imus[0]
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) * 1e-9)
    ph = segment_phases(imu.gyr, rate, PhaseParams(repetitions=RepetitionParams(n_repetitions=n_rep))).phases
    truth, events = sim.truth.phases, sim.truth.events
    t_ref = np.asarray(sim.truth.imu_t_ref_ns, dtype=np.int64)
    wave_end = events.end_ns[list(events.labels).index("wave")]
    assert len(ph) == 4 * n_rep == len(truth)
    assert list(ph.labels) == list(truth.labels)
    assert ph.repetition.tolist() == np.asarray(truth.task_index).tolist()
    assert t_ref[ph.start[0]] > wave_end  # repetition 1 is not inside the calibration wave
    det_s, det_e = t_ref[ph.start], t_ref[ph.end - 1]
    inter = np.minimum(det_e, truth.end_ns) - np.maximum(det_s, truth.start_ns)
    union = np.maximum(det_e, truth.end_ns) - np.minimum(det_s, truth.start_ns)
    assert np.all(inter / union > 0.5)


SUB = {"extra_submovement_probability": 0.2, "residual_velocity_mps": 0.01}


@pytest.mark.parametrize(
    ("n_rep", "seed", "subject", "trial", "options"),
    [
        (5, 0, 2, 2, {}),  # the batch engineer's report (simulate_archive demo trial S02_T2)
        (5, 1, 1, 2, {}),  # wave raised the median height: repetition 1's lift/return were "minor"
        (2, 0, 3, 2, {}),  # more wave movements than task movements
        (25, 1, 5, 1, {}),  # also with the full protocol: repetition 1 was a cheap group inside the wave
        (3, 1, 1, 1, SUB),  # no repetition with exactly 4 movements: reference from the major ones
        (3, 0, 1, 2, SUB),  # a small corrective sub-movement was kept as a phase, a true phase dropped
        (3, 7, 3, 1, SUB),  # slow subject: a 0.7 rad/s lift is "minor", the majors cannot fill 3 groups
    ],
)
def test_few_repetitions_match_the_truth_and_skip_the_wave(n_rep, seed, subject, trial, options):
    sim = simulate("r2g", subject=subject, trial=trial, seed=seed, repetitions=n_rep, **options)
    _phases_against_truth(sim, n_rep)


def test_burst_mask_marks_runs_of_contiguous_movements_only():
    rate = 100.0
    # a wave: 6 movements 0.6 s long with 0.01 s gaps; then one repetition: 4 movements 1 s long, 3 s pauses,
    # the second followed after 0.05 s by a corrective sub-movement (a run of 2 is not a burst)
    wave = [(1000 + 61 * k, 1060 + 61 * k) for k in range(6)]
    task = [(2000, 2100), (2400, 2500), (2505, 2540), (2840, 2940), (3240, 3340)]
    start, end = np.array([*wave, *task]).T
    mask = burst_mask(start, end, rate, gap_s=0.2, min_movements=5)
    assert mask.tolist() == [True] * 6 + [False] * 5
    assert not burst_mask(start, end, rate, min_movements=7).any()
    assert not burst_mask(start, end, rate, min_movements=0).any()
