"""Phase boundaries that follow the hand (imulog.process.segmentation.hand): constructed IMU signals with exact
onsets and offsets, where the wrist stops rotating before the hand stops moving."""

from __future__ import annotations

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.segmentation.boundaries import refine_phase_boundaries
from imulog.process.segmentation.hand import HandParams, fill_gaps, refine_with_accelerometer
from imulog.simulate.motion import MotionPlan, submovement_law

RATE = 100.0
G = np.array([0.0, 0.0, 9.81])


def _imu(plan: MotionPlan, t_end: float, rng, acc_noise=0.02, gyr_noise=0.002, acc_bias=(0.2, -0.1, 0.3)):
    t = np.arange(0.0, t_end, 1.0 / RATE)
    k = plan.evaluate(t)
    acc = quat.rotate_inverse(k.orientation, k.acceleration + G) + np.asarray(acc_bias)
    gyr = k.omega + np.array([0.01, -0.02, 0.015])
    return t, acc + rng.normal(0, acc_noise, acc.shape), gyr + rng.normal(0, gyr_noise, gyr.shape)


def _trial(rng, rotation_end: float):
    """Three 2-s reaches separated by 4-s rests; the wrist turns 60 deg over [0, rotation_end] of each."""
    plan = MotionPlan(np.zeros(3), np.array([1.0, 0, 0, 0]))
    truth = []
    for k in range(3):
        plan.wait(4.0)
        target = plan.p + np.array([0.25, 0.1 * (-1) ** k, 0.05])
        q1 = quat.multiply(plan.q, quat.from_rotation_vector(np.radians([0.0, 20.0, 60.0 * (-1) ** k])))
        rot = submovement_law(2.0, [0.0], [2.0 * rotation_end], [1.0])
        t0, t1 = plan.move(2.0, target, q1, rot_law=rot)
        truth.append((t0, t1))
    plan.wait(4.0)
    return plan, np.array(truth)


def _gyro_phases(gyr, truth, rotation_end):
    """Gyroscope-refined phases from boundaries 0.15 s inside the rotation (as DynAMoS + event correction
    leave them)."""
    s = np.round((truth[:, 0] + 0.15) * RATE).astype(int)
    e = np.round((truth[:, 0] + 2.0 * rotation_end - 0.15) * RATE).astype(int)
    return refine_phase_boundaries(gyr, RATE, s, e)


def test_offset_follows_the_hand_when_the_rotation_ends_first():
    rng = np.random.default_rng(3)
    plan, truth = _trial(rng, rotation_end=0.6)
    t, acc, gyr = _imu(plan, plan.t, rng)
    gs, ge = _gyro_phases(gyr, truth, 0.6)
    hs, he = refine_with_accelerometer(acc, gyr, RATE, gs, ge)
    gyro_offset = t[ge - 1] - truth[:, 1]
    hand_offset = t[he - 1] - truth[:, 1]
    assert np.all(gyro_offset < -0.5)  # the wrist stops at 60 % of the 2-s phase
    assert np.all(np.abs(hand_offset) < 0.05), hand_offset
    assert np.all(np.abs(t[hs] - truth[:, 0]) < 0.05)
    off = refine_with_accelerometer(acc, gyr, RATE, gs, ge, HandParams(enabled=False))
    assert np.array_equal(off[0], gs) and np.array_equal(off[1], ge)


def test_boundaries_stay_when_rotation_and_translation_end_together():
    rng = np.random.default_rng(4)
    plan, truth = _trial(rng, rotation_end=1.0)
    t, acc, gyr = _imu(plan, plan.t, rng)
    gs, ge = _gyro_phases(gyr, truth, 1.0)
    hs, he = refine_with_accelerometer(acc, gyr, RATE, gs, ge)
    assert np.all(np.abs(t[he - 1] - truth[:, 1]) < 0.05) and np.all(np.abs(t[hs] - truth[:, 0]) < 0.05)
    assert np.all(he >= ge) and np.all(hs <= gs)  # only ever outward
    assert np.all(he - ge <= 5) and np.all(gs - hs <= 5)


def test_missing_samples_are_bridged_not_read_as_a_jump():
    rng = np.random.default_rng(5)
    plan, truth = _trial(rng, rotation_end=0.6)
    t, acc, gyr = _imu(plan, plan.t, rng)
    gs, ge = _gyro_phases(gyr, truth, 0.6)
    holed = acc.copy()
    for k in range(3):  # 3 missing samples in each rest, 1 s after the phase
        i = int((truth[k, 1] + 1.0) * RATE)
        holed[i : i + 3] = np.nan
    ref = refine_with_accelerometer(acc, gyr, RATE, gs, ge)
    got = refine_with_accelerometer(holed, gyr, RATE, gs, ge)
    assert np.abs(got[1] - ref[1]).max() <= 2 and np.abs(got[0] - ref[0]).max() <= 2
    assert np.isfinite(fill_gaps(holed)).all()


def test_a_slow_last_submovement_after_a_pause_stays_in_the_phase():
    """Issue 31: a stroke-like phase whose small, slow last submovement follows a pause after the wrist stopped
    turning (gravity dominated the old continuation level, so the phase ended ~0.8 s early)."""
    rng = np.random.default_rng(6)
    plan = MotionPlan(np.zeros(3), np.array([1.0, 0, 0, 0]))
    truth = []
    for k in range(3):
        plan.wait(4.0)
        target = plan.p + np.array([0.25, 0.1 * (-1) ** k, 0.05])
        q1 = quat.multiply(plan.q, quat.from_rotation_vector(np.radians([0.0, 20.0, 60.0 * (-1) ** k])))
        # primary 2 s, pause 0.3 s, then a 0.7-s submovement carrying 30 % of the way; the wrist turns with the
        # primary only
        law = submovement_law(3.0, [0.0, 2.3], [2.0, 0.7], [1.0, 0.3])
        rot = submovement_law(3.0, [0.0], [2.0], [1.0])
        t0, t1 = plan.move(3.0, target, q1, law=law, rot_law=rot)
        truth.append((t0, t1))
    plan.wait(4.0)
    truth = np.array(truth)
    t, acc, gyr = _imu(plan, plan.t, rng)
    s = np.round((truth[:, 0] + 0.15) * RATE).astype(int)
    e = np.round((truth[:, 0] + 2.0 - 0.15) * RATE).astype(int)
    gs, ge = refine_phase_boundaries(gyr, RATE, s, e)
    assert np.all(t[ge - 1] - truth[:, 1] < -0.8)  # the gyroscope sees only the first 2 s
    hs, he = refine_with_accelerometer(acc, gyr, RATE, gs, ge)
    assert np.all(np.abs(t[he - 1] - truth[:, 1]) < 0.1), t[he - 1] - truth[:, 1]
    assert np.all(np.abs(t[hs] - truth[:, 0]) < 0.05)


def _paused_trial(seed: int, pause_s: float = 0.5, last_s: float = 2.6, weight: float = 0.7):
    """Three phases whose wrist turns with a 3-s primary submovement only; the hand stops for ``pause_s``, then a
    last submovement of ``last_s`` (weight ``weight`` against the primary's 1) carries it on. Returns the sample
    times, the true (onset, offset) (s), the IMU signals and the gyroscope-refined phases."""
    rng = np.random.default_rng(seed)
    plan = MotionPlan(np.zeros(3), np.array([1.0, 0, 0, 0]))
    truth = []
    dur = 3.0 + pause_s + last_s
    for k in range(3):
        plan.wait(5.0)
        target = plan.p + np.array([0.25, 0.15 * (-1) ** k, 0.05])
        q1 = quat.multiply(plan.q, quat.from_rotation_vector(np.radians([0.0, 20.0, 60.0 * (-1) ** k])))
        law = submovement_law(dur, [0.0, 3.0 + pause_s], [3.0, last_s], [1.0, weight])
        rot = submovement_law(dur, [0.0], [3.0], [1.0])
        truth.append(plan.move(dur, target, q1, law=law, rot_law=rot))
    plan.wait(5.0)
    truth = np.array(truth)
    t, acc, gyr = _imu(plan, plan.t, rng)
    s = np.round((truth[:, 0] + 0.15) * RATE).astype(int)
    e = np.round((truth[:, 0] + 3.0 - 0.15) * RATE).astype(int)
    return t, truth, acc, gyr, refine_phase_boundaries(gyr, RATE, s, e)


def test_a_last_submovement_resumed_after_a_pause_faster_than_the_cruise_speed_stays_in_the_phase():
    """Issue 31 point 1 (stroke-curved, e.g. seeds 32 / subject 8 and 142 / 106 of the grid): the hand stops for
    0.5 s after the wrist stopped turning, then a last, slow submovement (about 12 cm in 2.6 s: 9 cm/s peak,
    about 0.1 m/s^2, under the 3 acceleration levels a continuation after a pause needed) carries it on, ending
    3.1 s after the wrist stopped, beyond ``max_shift_s``. It is the phase's: it resumes faster than the cruise
    speed (a rest's drift at 1-2 cm/s stays under it; ``test_segmentation_boundaries.py``) and settles before the
    rest window. On 5 seeds x 3 phases the default ends 14 within 0.1 s (seed 15's first phase 0.8 s early);
    without either rule 6-7 phases end 0.8-3.1 s early."""
    ok = {"default": 0, "resume_cruise": 0, "settled_beyond_shift": 0}
    for seed in range(11, 16):
        t, truth, acc, gyr, (gs, ge) = _paused_trial(seed)
        assert np.all(t[ge - 1] - truth[:, 1] < -2.9)  # the gyroscope sees the primary only
        for name, params in (
            ("default", HandParams()),
            ("resume_cruise", HandParams(resume_cruise=False)),
            ("settled_beyond_shift", HandParams(settled_beyond_shift=False)),
        ):
            _, he = refine_with_accelerometer(acc, gyr, RATE, gs, ge, params)
            ok[name] += int(np.sum(np.abs(t[he - 1] - truth[:, 1]) < 0.1))
    assert ok["default"] >= 14, ok
    assert ok["resume_cruise"] <= 10 and ok["settled_beyond_shift"] <= 10, ok


def test_the_gyroscope_noise_floor_option_at_50_hz():
    """Issue 31's ninth round: at 50 Hz the gyroscope refinement's descent ends about a sample into the rest at
    each end (grid ``rate-50hz``, seed 150 subject 110: 92.5 % of durations within 0.1 s, every phase outside it
    with its onset 0.03-0.07 s early and its offset 0.03-0.08 s late, set by the gyroscope). Step 10
    (``HandParams.gyro_floor``, an option) trims the boundaries no step moved to the rest's noise floor."""
    import sys
    from dataclasses import replace
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from segmentation_accuracy import score

    from imulog.process.segmentation.pipeline import PhaseParams
    from imulog.process.segmentation.repetitions import RepetitionParams
    from imulog.simulate import simulate

    base = PhaseParams(repetitions=RepetitionParams(n_repetitions=10))
    floor = replace(base, hand=replace(base.hand, gyro_floor=True))
    sim = simulate("r2g", seed=150, subject=110, repetitions=10, imu_rate_hz=50.0)
    before, after = score(sim, base), score(sim, floor)
    # the diagnosed trial: 92.5 % by default at issue 31's ninth round
    assert after["duration_within_0_1_s"] >= max(0.975, before["duration_within_0_1_s"]) and after["correct"] == 1.0
    assert after["onset_mae_s"] < before["onset_mae_s"]
    assert abs(after["mean_duration_error_s"]) < abs(before["mean_duration_error_s"])
