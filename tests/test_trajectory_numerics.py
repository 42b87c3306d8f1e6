"""Numerics of the trajectory methods on motions with known truth (no archive, no simulator)."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process.drift import HighpassParams, WaveletParams, highpass, wavelet_detrend, wavelet_effective_level
from imulog.process.integration import (
    DdiParams,
    ZuptParams,
    cumtrapz,
    double_integrate,
    static_runs,
    zupt,
    zupt_velocity,
)
from imulog.process.kalman import KalmanParams, kalman_track
from imulog.process.minjerk import (
    R2GWaypoints,
    minimum_jerk,
    minimum_jerk_profile,
    piecewise_minimum_jerk,
    r2g_reference,
    r2g_waypoints,
    r2g_waypoints_from_anthropometrics,
    r2g_waypoints_from_positions,
)
from imulog.process.trajectory_opt import OptimizationParams, optimize_repetition

RATE = 115.0


def minjerk_acc(t, t0, t1, p0, p1):
    """Analytic second derivative of the minimum-jerk movement (m/s^2)."""
    T = t1 - t0
    tau = np.clip((t - t0) / T, 0, 1)
    inside = (t >= t0) & (t <= t1)
    d2 = (60 * tau - 180 * tau**2 + 120 * tau**3) / T**2
    return np.where(inside, d2, 0.0)[:, None] * (np.asarray(p1) - np.asarray(p0))[None, :]


def r2g_truth(rng, waypoints=None, durations=(1.0, 1.2, 1.1, 0.9), rests=(4.0, 4.0, 4.0), lead=2.0, rate=RATE):
    """One R2G-like repetition: times (s), positions (m), analytic acceleration, phase bounds, static mask."""
    wp = (waypoints or r2g_waypoints(0.35, 0.10, 0.30)).as_array()
    bounds, t = [], lead
    for k, d in enumerate(durations):
        bounds.append((t, t + d))
        t += d + (rests[k] if k < 3 else 0.0)
    ts = np.arange(0.0, t + lead, 1.0 / rate)
    b = np.array(bounds)
    pos = piecewise_minimum_jerk(ts, b, wp)
    acc = sum(minjerk_acc(ts, *b[k], wp[k], wp[k + 1]) for k in range(4))
    static = np.ones(len(ts), bool)
    for t0, t1 in b:
        static[(ts > t0) & (ts < t1)] = False
    return ts, pos, acc, b, static


def test_cumtrapz_exact_for_constant_acceleration():
    t = np.sort(np.random.default_rng(0).uniform(0, 3, 200))  # non-uniform
    a = np.full((len(t), 2), [0.5, -2.0])
    v = cumtrapz(a, t)
    p = cumtrapz(v, t)
    np.testing.assert_allclose(v, (t - t[0])[:, None] * [0.5, -2.0], atol=1e-12)
    # trapezoid of a linear velocity is exact
    np.testing.assert_allclose(p, 0.5 * (t - t[0])[:, None] ** 2 * [0.5, -2.0], atol=1e-12)


def test_double_integration_converges_at_second_order_on_minjerk():
    errors = []
    for rate in (100.0, 200.0, 400.0):
        ts, pos, acc, _, _ = r2g_truth(None, rate=rate)
        _, p = double_integrate(acc, ts, DdiParams(remove_mean=False))
        errors.append(np.max(np.abs(p - pos)))
    assert errors[0] < 5e-3  # a few mm after ~20 s at 100 Hz, noise-free
    # trapezoidal rule: halving the step divides the error by about 4
    assert 3.0 < errors[0] / errors[1] < 5.0 and 3.0 < errors[1] / errors[2] < 5.0


def test_ddi_mean_removal_cancels_constant_offset_but_not_without():
    ts, pos, acc, _, _ = r2g_truth(None)
    biased = acc + [0.05, -0.03, 0.02]
    _, p_mean = double_integrate(biased, ts, DdiParams(remove_mean=True))
    _, p_clean = double_integrate(acc, ts, DdiParams(remove_mean=True))
    _, p_raw = double_integrate(biased, ts, DdiParams(remove_mean=False))
    np.testing.assert_allclose(p_mean, p_clean, atol=1e-12)
    assert np.max(np.abs(p_raw - pos)) > 1.0  # 0.05 m/s^2 over 19 s: metres


def test_zupt_linear_dedrift_removes_constant_bias():
    ts, pos, acc, _, static = r2g_truth(None)
    biased = acc + [0.2, -0.1, 0.15]
    v, p = zupt(biased, ts, static, ZuptParams(dedrift=True))
    assert np.all(v[static] == 0)
    _, p_clean = zupt(acc, ts, static, ZuptParams(dedrift=True))
    np.testing.assert_allclose(p, p_clean, atol=1e-9)  # a constant offset is removed exactly
    assert np.max(np.abs(p_clean - pos)) < 5e-3
    _, p_nodrift = zupt(biased, ts, static, ZuptParams(dedrift=False))
    assert np.max(np.abs(p_nodrift - pos)) > 0.02


def test_zupt_ignores_short_static_runs():
    mask = np.zeros(100, bool)
    mask[10:12] = True
    mask[50:70] = True
    assert static_runs(mask, 3).tolist() == [[50, 70]]
    acc = np.ones(100)
    v = zupt_velocity(acc, np.arange(100) / 100, mask, ZuptParams(dedrift=False, min_static_samples=3))
    assert v[11] > 0 and v[60] == 0


def test_highpass_removes_slow_drift_keeps_fast_motion():
    t = np.arange(0, 60, 1 / RATE)
    fast = 0.05 * np.sin(2 * np.pi * 2.0 * t)
    drift = 0.3 * t / 60 + 0.2 * np.sin(2 * np.pi * 0.02 * t)
    out = highpass(fast + drift, RATE, HighpassParams(cutoff_hz=0.3))
    core = slice(len(t) // 10, -len(t) // 10)
    assert np.sqrt(np.mean((out[core] - fast[core]) ** 2)) < 0.005


def test_wavelet_trend_follows_drift_and_level_is_clamped():
    t = np.arange(0, 120, 1 / RATE)  # 13800 samples: level 9 is possible for db6
    fast = 0.05 * np.sin(2 * np.pi * 1.0 * t)
    drift = 0.5 * (t / 120) ** 2
    assert wavelet_effective_level(len(t)) == 9
    out = wavelet_detrend(np.stack([fast + drift, fast], axis=1))
    core = slice(len(t) // 10, -len(t) // 10)
    assert np.sqrt(np.mean((out[core, 0] - fast[core]) ** 2)) < 0.01
    assert wavelet_effective_level(1000, WaveletParams(level=9)) < 9


def test_kalman_ar1_tracks_and_zero_velocity_updates_help():
    rng = np.random.default_rng(3)
    ts, pos, acc, _, static = r2g_truth(None)
    noisy = acc + [0.04, -0.03, 0.03] + rng.normal(0, 0.02, acc.shape)
    plain = kalman_track(noisy, ts, static, KalmanParams())
    zv = kalman_track(noisy, ts, static, KalmanParams(zero_velocity=True, smoother=True))
    err_plain = np.mean(np.abs(plain.position - pos))
    err_zv = np.mean(np.abs(zv.position - zv.position[0] - pos))
    assert err_zv < 0.01 < err_plain
    # the filtered acceleration is a denoised measurement
    assert np.sqrt(np.mean((zv.acceleration - acc) ** 2)) < np.sqrt(np.mean((noisy - acc) ** 2))
    # 1D input gives 1D output equal to that axis of the 3D filter
    kp = KalmanParams(zero_velocity=True, meas_var_m2ps4=4e-4)
    one = kalman_track(noisy[:, 0], ts, static, kp)
    three = kalman_track(noisy, ts, static, kp)
    np.testing.assert_allclose(one.position, three.position[:, 0])


def test_minimum_jerk_shape():
    tau = np.linspace(0, 1, 1001)
    s = minimum_jerk_profile(tau)
    assert s[0] == 0 and s[-1] == 1 and abs(s[500] - 0.5) < 1e-12
    v = np.gradient(s, tau)
    assert abs(v.max() - 1.875) < 1e-3  # peak speed 15/8 of the mean
    p = minimum_jerk(np.array([0.0, 1.0, 2.0]), 0.0, 2.0, [0, 0], [1, -2])
    np.testing.assert_allclose(p, [[0, 0], [0.5, -1.0], [1, -2]])


def test_r2g_waypoints_and_reference():
    wp = r2g_waypoints(0.4, 0.1, 0.3)
    assert wp.bottle_m == pytest.approx((0.4, 0.1, 0.0)) and wp.mouth_m[2] == pytest.approx(0.3)
    same = r2g_waypoints_from_anthropometrics({"h1_m": 0.4, "h2_m": 0.1, "mouth_height_m": 0.3})
    assert same == wp
    with pytest.raises(KeyError, match="h3"):
        r2g_waypoints_from_anthropometrics({"h1_m": 0.4, "h2_m": 0.1})
    ts, pos, _, b, _ = r2g_truth(None, waypoints=wp)
    ref = r2g_reference(ts, b, wp)
    np.testing.assert_allclose(ref, pos)
    measured = r2g_waypoints_from_positions(pos, ts, b)
    np.testing.assert_allclose(measured.bottle_m, wp.bottle_m, atol=1e-6)
    np.testing.assert_allclose(measured.mouth_m, wp.mouth_m, atol=1e-6)


def test_optimization_fixed_point_and_constraints():
    # symmetric phases: the truth has zero cost in every term, so it is the optimum
    ts, pos, _, b, static = r2g_truth(None, durations=(1.0, 1.2, 1.2, 1.0))
    res = optimize_repetition(ts, pos, pos, b, static)
    np.testing.assert_allclose(res.position, pos, atol=1e-9)
    # a drifting initial estimate: the constraint holds exactly and the error falls
    drift = np.outer((ts - ts[0]) / (ts[-1] - ts[0]), [0.05, -0.04, 0.03])
    wp = R2GWaypoints(bottle_m=(0.36, 0.11, 0.0), mouth_m=(0.1, 0.09, 0.31))  # 1-2 cm off the truth
    ref = r2g_reference(ts, b, wp)
    res = optimize_repetition(ts, pos + drift, ref, b, static, OptimizationParams(return_to_start=True))  # the thesis's
    np.testing.assert_allclose(res.position[[0, -1]], 0.0, atol=1e-9)
    assert np.mean(np.abs(res.position - pos)) < 0.5 * np.mean(np.abs(drift))
    # per axis: z only (the table's height); x and y end where the data and the reference put them
    res = optimize_repetition(ts, pos + drift, ref, b, static, OptimizationParams(return_to_start=(False, False, True)))
    np.testing.assert_allclose(res.position[0], 0.0, atol=1e-9)
    assert abs(res.position[-1, 2]) < 1e-9 and np.all(np.abs(res.position[-1, :2]) > 1e-4)
    assert np.mean(np.abs(res.position - pos)) < 0.5 * np.mean(np.abs(drift))


def _rotation_z_then_x(yaw, roll):
    cy, sy, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(roll), np.sin(roll)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ rx


def test_rotating_bias_is_estimated_from_zupt_closure():
    """A sensor-frame bias and scale error turn with the sensor; the closure of every movement recovers their
    effect (mean removal per rest and linear de-drift cannot)."""
    from imulog.process.integration import RotatingBiasParams, compensate_rotating_bias, estimate_rotating_bias

    rng = np.random.default_rng(7)
    wp = r2g_waypoints(0.3, 0.15, 0.4)
    segments = []
    for _ in range(6):
        ts, pos, acc, b, static = r2g_truth(None, waypoints=wp, durations=tuple(rng.uniform(0.9, 1.4, 4)))
        segments.append((ts, pos, acc, b, static))
    t = np.concatenate([s[0] + 25.0 * i for i, s in enumerate(segments)])
    pos = np.concatenate([s[1] for s in segments])
    acc = np.concatenate([s[2] for s in segments])
    static = np.concatenate([s[4] for s in segments])
    bounds = np.concatenate([s[3] + 25.0 * i for i, s in enumerate(segments)])
    # orientation: each phase turns the sensor between three poses (min-jerk in yaw and roll)
    poses = np.array([[0.0, 0.0], [0.4, -1.3], [0.8, -1.8], [0.4, -1.3], [0.0, 0.0]])
    angles = np.concatenate([piecewise_minimum_jerk(s[0], s[3], poses) for s in segments])
    rot = np.stack([_rotation_z_then_x(y, r) for y, r in angles])
    g = np.array([0.0, 0.0, 9.81])
    bias = np.array([0.06, -0.08, 0.05])
    matrix = np.array([[0.006, 0.004, 0.0], [0.0, -0.004, 0.003], [0.002, 0.0, 0.005]])
    f_sensor = np.einsum("nji,nj->ni", rot, acc + g)  # R^T (a + g)
    measured = f_sensor + bias + f_sensor @ matrix.T
    acc_global = np.einsum("nij,nj->ni", rot, measured) - g
    errors = estimate_rotating_bias(acc_global, rot, t, static, RotatingBiasParams())
    fixed = compensate_rotating_bias(acc_global, rot, t, static, errors)
    # with three poses bias and matrix are not separable, but their effect during movements is recovered
    moving = ~static
    rms_raw = np.sqrt(np.mean((acc_global - acc)[moving] ** 2))
    rms_fixed = np.sqrt(np.mean((fixed - acc)[moving] ** 2))
    assert rms_raw > 0.03 and rms_fixed < 0.01  # m/s^2; the rest: E acting on the motion itself
    err_raw, err_fixed = [], []
    for b in bounds.reshape(-1, 4, 2):
        sl = (t >= b[0, 0] - 1.0) & (t <= b[-1, 1] + 1.0)
        for a_in, out in ((acc_global, err_raw), (fixed, err_fixed)):
            p = zupt(a_in[sl], t[sl], static[sl])[1]
            out.append(np.mean(np.abs(p - (pos[sl] - pos[sl][0]))))
    assert np.mean(err_fixed) < 0.2 * np.mean(err_raw)
    assert np.mean(err_fixed) < 0.003  # below 3 mm once the errors are compensated


def _turning_drinking_trial(rng: np.random.Generator, repetitions: int):
    """Drinking movements 25 s apart whose sensor turns with the hand (yaw then roll, piecewise minimum jerk):
    (t s, true global acceleration m/s^2, static mask, sensor-to-global rotations, true specific force in the
    sensor frame m/s^2, gravity m/s^2)."""
    wp = r2g_waypoints(0.3, 0.15, 0.4)
    segments = [r2g_truth(None, waypoints=wp, durations=tuple(rng.uniform(0.9, 1.4, 4))) for _ in range(repetitions)]
    t = np.concatenate([s[0] + 25.0 * i for i, s in enumerate(segments)])
    acc = np.concatenate([s[2] for s in segments])
    static = np.concatenate([s[4] for s in segments])
    poses = np.array([[0.0, 0.0], [0.4, -1.3], [0.8, -1.8], [0.4, -1.3], [0.0, 0.0]])
    angles = np.concatenate([piecewise_minimum_jerk(s[0], s[3], poses) for s in segments])
    rot = np.stack([_rotation_z_then_x(y, r) for y, r in angles])
    g = np.array([0.0, 0.0, 9.81])
    return t, acc, static, rot, np.einsum("nji,nj->ni", rot, acc + g), g


def test_rotating_bias_fit_leaves_out_a_movement_it_cannot_close():
    """One movement with an error the sensor model has no term for (a world-frame 0.5 m/s^2 push, like an
    orientation error during a long swing) dominates the plain least squares; ``outlier_factor`` refits
    without it and recovers the sensor errors' effect on the other movements."""
    from imulog.process.integration import RotatingBiasParams, compensate_rotating_bias, estimate_rotating_bias
    from imulog.process.rest_runs import movement_runs

    t, acc, static, rot, f_sensor, g = _turning_drinking_trial(np.random.default_rng(7), 6)
    measured = f_sensor + np.array([0.06, -0.08, 0.05]) + f_sensor @ np.diag([0.006, -0.004, 0.005]).T
    acc_global = np.einsum("nij,nj->ni", rot, measured) - g
    runs = [(s, e) for s, e in movement_runs(static) if s > 0 and e < len(t)]
    s0, e0 = runs[5]
    acc_global[s0:e0, 1] += 0.5  # the movement the model cannot close
    others = ~static
    others[s0:e0] = False
    rms = {}
    for factor in (None, 3.0):
        params = RotatingBiasParams(outlier_factor=factor)
        errors = estimate_rotating_bias(acc_global, rot, t, static, params)
        fixed = compensate_rotating_bias(acc_global, rot, t, static, errors, params)
        rms[factor] = float(np.sqrt(np.mean((fixed - acc)[others] ** 2)))
    assert rms[3.0] < 0.01 < rms[None]  # m/s^2 on the movements the sensor model describes


def _rotating_part_removed(acc_global, rot, t, static, errors) -> float:
    """RMS (m/s^2) over the movements of what a compensation removes beyond each rest's mean (removed either way)."""
    from imulog.process.integration import AccelerometerErrors, compensate_rotating_bias

    rests_only = compensate_rotating_bias(
        acc_global, rot, t, static, AccelerometerErrors(np.zeros(3), np.zeros((3, 3)))
    )
    fixed = compensate_rotating_bias(acc_global, rot, t, static, errors)
    return float(np.sqrt(np.mean((rests_only - fixed)[~static] ** 2)))


def test_rotating_bias_compensation_is_shrunk_by_its_own_noise():
    """``RotatingBiasParams.shrink``: per global axis, the compensation is applied as far as it stands out of its
    own uncertainty (James-Stein). Real sensor errors stand out (weight near 1, the same compensation); an
    estimate fitted to noise alone is about its own standard error and is mostly left out."""
    from imulog.process.integration import (
        RotatingBiasParams,
        estimate_rotating_bias,
    )

    rng = np.random.default_rng(11)
    t, acc, static, rot, f_sensor, g = _turning_drinking_trial(rng, 8)
    noise = 0.05 * rng.standard_normal(acc.shape)  # m/s^2, white
    cases = (([0.06, -0.08, 0.05], [0.006, -0.004, 0.005], True), ([0.0] * 3, [0.0] * 3, False))
    for bias, scale, expect_signal in cases:
        measured = f_sensor + np.array(bias) + f_sensor @ np.diag(scale).T
        acc_global = np.einsum("nij,nj->ni", rot, measured) - g + noise
        plain = estimate_rotating_bias(acc_global, rot, t, static, RotatingBiasParams())
        shrunk = estimate_rotating_bias(acc_global, rot, t, static, RotatingBiasParams(shrink=True))
        assert plain.axis_weight is None and np.allclose(plain.axis_z, shrunk.axis_z)
        removed = {
            name: _rotating_part_removed(acc_global, rot, t, static, errors)
            for name, errors in (("plain", plain), ("shrunk", shrunk))
        }
        if expect_signal:
            assert np.all(shrunk.axis_z > 3) and np.all(shrunk.axis_weight > 1 - 1 / 9), shrunk.axis_z
            assert removed["shrunk"] == pytest.approx(removed["plain"], rel=0.1)
        else:
            assert np.all(shrunk.axis_z < 3), shrunk.axis_z
            assert removed["shrunk"] < 0.5 * removed["plain"], (removed, shrunk.axis_z)


def test_rotating_bias_prior_from_the_rest_calibration():
    """``prior_cov`` (``RotatingBiasParams.calibration_prior``: the rest calibration's posterior): with a prior
    a million times broader than the errors, the plain least squares' compensation; with a prior as tight as a good
    calibration's and nothing left to fit, most of the noise the plain fit turns into a compensation is left out;
    with a broad prior real sensor errors are still recovered as the plain fit recovers them."""
    from imulog.process.integration import (
        RotatingBiasParams,
        compensate_rotating_bias,
        estimate_rotating_bias,
    )

    rng = np.random.default_rng(13)
    t, acc, static, rot, f_sensor, g = _turning_drinking_trial(rng, 8)
    noise = 0.05 * rng.standard_normal(acc.shape)  # m/s^2, white
    moving = ~static
    tight = np.diag(np.concatenate([np.full(3, 0.005), np.full(9, 0.0005)]) ** 2)  # (m/s^2)^2, dimensionless
    broad = np.diag(np.concatenate([np.full(3, 0.3), np.full(9, 0.01)]) ** 2)
    params = RotatingBiasParams()
    for bias, scale, prior_cov, same in (
        ([0.0] * 3, [0.0] * 3, tight, False),
        ([0.06, -0.08, 0.05], [0.006, -0.004, 0.005], broad, True),
    ):
        measured = f_sensor + np.array(bias) + f_sensor @ np.diag(scale).T
        acc_global = np.einsum("nij,nj->ni", rot, measured) - g + noise
        plain = estimate_rotating_bias(acc_global, rot, t, static, params)
        none = estimate_rotating_bias(acc_global, rot, t, static, params, np.eye(12) * 1e6)
        same_effect = compensate_rotating_bias(acc_global, rot, t, static, none) - compensate_rotating_bias(
            acc_global, rot, t, static, plain
        )
        assert np.max(np.abs(same_effect)) < 1e-4  # m/s^2 (bias and matrix are not separable at three poses)
        prior = estimate_rotating_bias(acc_global, rot, t, static, params, prior_cov)
        assert np.all(prior.bias_se_mps2 <= plain.bias_se_mps2 + 1e-12)
        removed, error = {}, {}  # m/s^2 RMS during movements
        for name, errors in (("plain", plain), ("prior", prior)):
            removed[name] = _rotating_part_removed(acc_global, rot, t, static, errors)
            fixed = compensate_rotating_bias(acc_global, rot, t, static, errors)
            error[name] = np.sqrt(np.mean((fixed - noise - acc)[moving] ** 2))
        if same:
            assert removed["prior"] == pytest.approx(removed["plain"], rel=0.1), removed
            assert error["prior"] < 0.01, error
        else:
            assert removed["prior"] < 0.5 * removed["plain"], removed


def test_rotating_bias_held_out_weight_keeps_what_predicts_left_out_movements():
    """``RotatingBiasParams.held_out`` (:func:`held_out_weight`): per global axis, the compensation is applied as far
    as a fit without each movement predicts that movement's closure. Real sensor errors (a bias and scale turning
    with the hand) are predicted on every axis and mostly kept; a closure error that is not the sensor's (each
    movement's own vertical push, as a tilt or a velocity at the rests gives) is not predicted, and the compensation
    the plain fit makes of it is mostly left out."""
    from imulog.process.integration import RotatingBiasParams, estimate_rotating_bias
    from imulog.process.rest_runs import movement_runs

    rng = np.random.default_rng(13)
    t, acc, static, rot, f_sensor, g = _turning_drinking_trial(rng, 8)
    noise = 0.05 * rng.standard_normal(acc.shape)  # m/s^2, white
    measured = f_sensor + np.array([0.06, -0.08, 0.05]) + f_sensor @ np.diag([0.006, -0.004, 0.005]).T
    sensor = np.einsum("nij,nj->ni", rot, measured) - g + noise
    world = acc + noise
    for s, e in movement_runs(static):
        world[s:e, 2] += rng.normal(0.0, 0.05)  # m/s^2 over the whole movement, not a sensor error
    held = RotatingBiasParams(held_out=True)
    for acc_global, kept in ((sensor, True), (world, False)):
        errors = estimate_rotating_bias(acc_global, rot, t, static, held)
        plain = estimate_rotating_bias(acc_global, rot, t, static, RotatingBiasParams())
        assert errors.axis_weight is not None and np.all((errors.axis_weight >= 0) & (errors.axis_weight <= 1))
        removed = _rotating_part_removed(acc_global, rot, t, static, errors)
        removed_plain = _rotating_part_removed(acc_global, rot, t, static, plain)
        if kept:
            assert np.all(errors.axis_weight > 0.5), errors.axis_weight
            assert removed == pytest.approx(removed_plain, rel=0.15)
        else:
            assert np.all(errors.axis_weight < 0.25), errors.axis_weight
            assert removed < 0.3 * removed_plain, (removed, removed_plain)


def test_held_out_weight_without_enough_movements_keeps_everything():
    """Fewer movements than two per unknown (plus the one left out): nothing to judge, weight 1 on every axis."""
    from imulog.process.integration import held_out_weight

    rng = np.random.default_rng(3)
    assert np.array_equal(held_out_weight(rng.normal(size=(8, 3, 12)), rng.normal(size=(8, 3))), np.ones(3))
    assert np.all(held_out_weight(rng.normal(size=(40, 3, 12)), rng.normal(size=(40, 3))) < 0.5)
