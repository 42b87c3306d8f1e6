"""The accelerometer's bias and scale from a trial's own rests (issue 31 point 2, ninth round)."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process import quaternion as quat
from imulog.process.acc_rest_calibration import AccRestParams, estimate, fit

G = 9.80665
RATE = 100.0


def _rests_at(poses_deg: list[tuple[float, float, float]], bias, scale, gyr_bias=(0.0, 0.0, 0.0), seed: int = 0):
    """A recording (acc, gyr, t, static) that rests 2 s at each sensor-to-world pose (yaw, pitch, roll deg) in turn,
    turning between them in 1 s at a constant body rate; the accelerometer reads ``scale * R^T g + bias`` plus
    0.02 m/s^2 white noise, the gyroscope the body rate plus ``gyr_bias`` and 0.002 rad/s noise."""
    rng = np.random.default_rng(seed)
    up = np.array([0.0, 0.0, G])
    qs = [quat.from_euler_zyx(*p) for p in poses_deg]
    acc, gyr, static = [], [], []
    for k, q in enumerate(qs):
        n = int(2 * RATE)
        acc.append(np.tile(np.asarray(scale) * quat.rotate_inverse(q, up), (n, 1)))
        gyr.append(np.zeros((n, 3)))
        static.append(np.ones(n, dtype=bool))
        if k + 1 < len(qs):
            n = int(RATE)
            rate = quat.to_rotation_vector(quat.multiply(quat.conjugate(q), qs[k + 1]))  # body frame, over 1 s
            steps = np.arange(n)[:, None] / RATE
            q_t = quat.multiply(np.tile(q, (n, 1)), quat.from_rotation_vector(steps * rate))
            acc.append(np.asarray(scale) * quat.rotate_inverse(q_t, np.tile(up, (n, 1))) + 0.5)  # moving: not used
            gyr.append(np.tile(rate, (n, 1)))
            static.append(np.zeros(n, dtype=bool))
    acc = np.vstack(acc) + np.asarray(bias) + rng.normal(0.0, 0.02, (sum(len(a) for a in static), 3))
    gyr = np.vstack(gyr) + np.asarray(gyr_bias) + rng.normal(0.0, 0.002, acc.shape)
    static = np.concatenate(static)
    return acc, gyr, np.arange(len(static)) / RATE, static


# a drinking trial's wrist at home, at the bottle and at the mouth, over three repetitions
DRINK = [(0.0, 0.0, 0.0), (20.0, -10.0, 60.0), (40.0, -50.0, 80.0), (20.0, -10.0, 60.0)] * 3 + [(0.0, 0.0, 0.0)]


def test_bias_recovered_from_rests_at_several_orientations():
    bias = np.array([0.25, -0.3, 0.15])
    acc, gyr, t, static = _rests_at(DRINK, bias, np.ones(3), gyr_bias=(0.02, -0.03, 0.01))
    est = estimate(acc, gyr, t, static, AccRestParams(enabled=True, model="bias", max_bias_sd_mps2=0.05))
    assert est.applied, est.reason
    assert est.rests == len(DRINK)
    assert np.linalg.norm(est.bias_mps2 - bias) < 0.02  # of a 0.42 m/s^2 bias
    assert np.all(est.bias_sd_mps2 < 0.05)
    # the estimate's error within its reported uncertainty (3 standard deviations per axis)
    assert np.all(np.abs(est.bias_mps2 - bias) < 3 * est.bias_sd_mps2 + 0.005)
    corrected = est.apply(acc[static])
    assert np.abs(np.linalg.norm(corrected, axis=1).mean() - G) < 0.01


def test_bias_and_scale_recovered_with_the_scale():
    bias = np.array([-0.2, 0.1, 0.3])
    scale = np.array([1.02, 0.985, 1.01])
    poses = [(0, 0, 0), (0, 90, 0), (0, 0, 90), (0, 180, 0), (0, 0, -90), (0, -90, 0), (0, 0, 0)]
    acc, gyr, t, static = _rests_at([tuple(map(float, p)) for p in poses], bias, scale)
    est = estimate(
        acc, gyr, t, static, AccRestParams(enabled=True, model="scale", scale_prior=0.02, max_bias_sd_mps2=0.1)
    )
    assert est.applied, est.reason
    assert np.abs(np.diag(est.matrix) - scale).max() < 0.003
    assert np.linalg.norm(est.bias_mps2 - bias) < 0.03
    # without the scale, a bias alone cannot explain these readings as well
    only_bias = estimate(acc, gyr, t, static, AccRestParams(enabled=True, model="bias", max_bias_sd_mps2=0.1))
    assert np.linalg.norm(only_bias.bias_mps2 - bias) > np.linalg.norm(est.bias_mps2 - bias)


def test_not_identifiable_from_rests_at_one_orientation():
    acc, gyr, t, static = _rests_at([(0.0, -10.0, 60.0)] * 8, [0.3, 0.0, 0.0], np.ones(3))
    est = estimate(acc, gyr, t, static, AccRestParams(enabled=True, model="bias", max_bias_sd_mps2=0.05))
    assert not est.applied
    assert "spread" in est.reason and "deg" in est.reason
    assert np.array_equal(est.apply(acc), acc)  # nothing is corrected
    assert est.as_dict()["applied"] is False


def test_too_few_rests_and_a_weak_estimate_are_refused():
    acc, gyr, t, static = _rests_at(DRINK[:3], [0.3, 0.0, 0.0], np.ones(3))
    est = estimate(acc, gyr, t, static, AccRestParams(enabled=True, model="bias", max_bias_sd_mps2=0.05))
    assert not est.applied and "fewer than 6" in est.reason
    # the same rests at several orientations but an uncertainty limit no estimate meets
    acc, gyr, t, static = _rests_at(DRINK, [0.3, 0.0, 0.0], np.ones(3))
    est = estimate(acc, gyr, t, static, AccRestParams(enabled=True, model="bias", max_bias_sd_mps2=1e-4))
    assert not est.applied and "standard deviation" in est.reason


def test_a_moving_rest_is_left_out():
    acc, gyr, t, static = _rests_at(DRINK, [0.1, 0.1, 0.1], np.ones(3))
    first = np.flatnonzero(static)[:200]
    acc[first] += np.sin(np.arange(200) / 5.0)[:, None] * np.array([0.5, 0.0, 0.0])  # a hand that is not still
    est = estimate(acc, gyr, t, static, AccRestParams(enabled=True, model="bias", max_bias_sd_mps2=0.05))
    assert est.rests == len(DRINK) - 1


def test_fit_without_links_still_reads_the_magnitude():
    """Without the gyroscope's links only gravity's magnitude ties the rests: a bias along the mean direction is
    seen, one across it is left to the prior."""
    poses = [(0.0, p, r) for p, r in [(0, 0), (-10, 60), (-50, 80), (-10, 60), (0, 0), (-30, 30)]]
    up = np.array([0.0, 0.0, G])
    means = np.array([quat.rotate_inverse(quat.from_euler_zyx(*p), up) for p in poses]) + np.array([0.0, 0.0, 0.2])
    est = fit(means, np.full(len(means), 0.005), [], AccRestParams(enabled=True, model="bias", max_bias_sd_mps2=1.0))
    assert est.bias_mps2[2] == pytest.approx(0.2, abs=0.08)


def test_the_matrix_model_needs_poses_that_vary():
    """A sensitivity matrix (2 % scale, 1 deg misalignment) and a bias. At three poses repeated exactly (home,
    bottle, mouth) the default model (bias and matrix under their priors) cannot tell the bias from the matrix
    (standard deviation above the 0.1 m/s^2 limit): not applied. At poses that vary between ten repetitions, as a
    hand's do (10 deg per angle), it is applied, the bias's error is within three of its standard deviations, and
    the corrected readings point nearer gravity than the raw ones on average over the rests."""
    rng = np.random.default_rng(3)
    off = np.radians(1.0) * rng.normal(size=(3, 3)) * ~np.eye(3, dtype=bool)
    matrix = np.eye(3) + np.diag([0.02, -0.015, 0.01]) + off
    bias = np.array([0.2, -0.25, 0.1])

    def through_matrix(poses):
        acc, gyr, t, static = _rests_at(poses, bias, np.ones(3))
        return (acc - bias) @ matrix.T + bias, gyr, t, static

    fixed_poses = estimate(*through_matrix(DRINK), AccRestParams(enabled=True))
    assert not fixed_poses.applied and "bias standard deviation" in fixed_poses.reason
    base = [(0.0, 0.0, 0.0), (20.0, -10.0, 60.0), (40.0, -50.0, 80.0), (20.0, -10.0, 60.0)]
    poses = [tuple(np.add(p, rng.normal(0.0, 10.0, 3))) for _ in range(10) for p in base] + [(0.0, 0.0, 0.0)]
    est = estimate(*through_matrix(poses), AccRestParams(enabled=True))
    assert est.applied, est.reason
    assert np.all(np.abs(est.bias_mps2 - bias) < 3 * est.bias_sd_mps2)
    up = np.array([0.0, 0.0, 1.0])

    def angle(v: np.ndarray, true_dir: np.ndarray) -> float:
        return float(np.degrees(np.arccos(np.clip(v @ true_dir / np.linalg.norm(v), -1, 1))))

    before, after = [], []
    for pose in poses:
        true_dir = quat.rotate_inverse(quat.from_euler_zyx(*pose), up)
        raw = (G * true_dir) @ matrix.T + bias
        before.append(angle(raw, true_dir))
        after.append(angle(est.apply(raw[None, :])[0], true_dir))
    assert np.mean(after) < 0.6 * np.mean(before), (np.mean(before), np.mean(after))


def test_the_joint_covariance_knows_the_error_along_gravity_best():
    """``AccRestCalibration.covariance`` (the rotating-bias fit's prior with ``calibration_prior``): its bias block
    is the reported bias standard deviations, the matrix's diagonal the reported ones, and the leftover error along
    gravity at a rest the trial visited (``u^T (db + g dM u)``, m/s^2) is known several times better than the bias
    along the same direction alone: the correlations the diagonal prior drops."""
    rng = np.random.default_rng(3)
    off = np.radians(1.0) * rng.normal(size=(3, 3)) * ~np.eye(3, dtype=bool)
    matrix = np.eye(3) + np.diag([0.02, -0.015, 0.01]) + off
    bias = np.array([0.2, -0.25, 0.1])
    base = [(0.0, 0.0, 0.0), (20.0, -10.0, 60.0), (40.0, -50.0, 80.0), (20.0, -10.0, 60.0)]
    poses = [tuple(np.add(p, rng.normal(0.0, 10.0, 3))) for _ in range(10) for p in base] + [(0.0, 0.0, 0.0)]
    acc, gyr, t, static = _rests_at(poses, bias, np.ones(3))
    est = estimate((acc - bias) @ matrix.T + bias, gyr, t, static, AccRestParams(enabled=True))
    assert est.applied, est.reason
    cov = est.covariance
    assert cov.shape == (12, 12)
    assert np.allclose(np.sqrt(np.diag(cov)[:3]), est.bias_sd_mps2)
    assert np.allclose(np.sqrt(np.diag(cov)[3:].reshape(3, 3)), est.matrix_sd)
    ratios = []
    for pose in base[:3]:
        u = quat.rotate_inverse(quat.from_euler_zyx(*pose), np.array([0.0, 0.0, 1.0]))
        row = np.concatenate([u, G * np.outer(u, u).ravel()])  # d(u^T (b + g M u)) / d(b, M row by row)
        ratios.append(np.sqrt(row @ cov @ row) / np.sqrt(u @ cov[:3, :3] @ u))
    assert max(ratios) < 0.5, ratios
    bias_only = estimate(acc, gyr, t, static, AccRestParams(enabled=True, model="bias"))
    assert np.allclose(np.diag(bias_only.covariance)[3:].reshape(3, 3), bias_only.matrix_sd**2)
