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
