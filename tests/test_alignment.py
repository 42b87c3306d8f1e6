"""IMU-to-Vicon alignment against synthetic trials with known clock, drift and frames.

The synthetic trial is built here from closed-form motion (independent of the code under test): a
smooth sensor orientation q_s2w(t) and cluster-origin path p(t) defined on the reference clock; the
IMU samples on its own device clock t_dev with t_ref = t_dev + offset + drift*(t_dev - t0); the
gyroscope is the exact body rate (numerical derivative of the closed form), the accelerometer the
specific force; markers O, X, Y, A sit on the cluster frame q_c2w = q_s2w * q_i2c^-1.
"""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process import alignment as al
from imulog.process import quaternion as Q
from imulog.process.orientation import estimate_orientation

NS = 1_000_000_000
DEVICE_START_S = 1000.0  # the device clock starts far from the reference clock
LOCAL = {"O": [0.0, 0.0, 0.0], "X": [0.06, 0.0, 0.0], "Y": [0.0, 0.05, 0.0], "A": [0.05, 0.04, 0.01]}


def _smooth_step(x):
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0, 1))


def orientation_at(t_s, seed=0):
    """Sensor-to-world orientation: 10 s static, then random smooth motion with a 5 s rest every 40 s."""
    rng = np.random.default_rng(seed)
    freqs = rng.uniform(0.15, 0.9, size=(3, 4))
    amps = rng.uniform(0.2, 0.8, size=(3, 4))
    phase = rng.uniform(0, 2 * np.pi, size=(3, 4))
    t = np.asarray(t_s, dtype=np.float64)
    rv = np.stack([np.sum(amps[k] * np.sin(2 * np.pi * freqs[k] * t[:, None] + phase[k]), axis=1) for k in range(3)], 1)
    p = (t - 10) % 40
    env = np.where(t < 10, 0.0, _smooth_step(p / 2) * _smooth_step((35 - p) / 2))
    base = Q.from_rotation_vector(np.array([0.3, -0.2, 1.0]))
    return Q.multiply(Q.from_rotation_vector(rv * env[:, None]), base)


def body_rate(t_s, seed=0, h=1e-4):
    q0 = orientation_at(np.asarray(t_s) - h, seed)
    q1 = orientation_at(np.asarray(t_s) + h, seed)
    return Q.to_rotation_vector(Q.multiply(Q.conjugate(q0), q1)) / (2 * h)


def position_at(t_s):
    t = np.asarray(t_s, dtype=np.float64)
    return np.stack([0.3 * np.sin(0.2 * t), 0.2 * np.cos(0.13 * t), 1.0 + 0.1 * np.sin(0.31 * t)], axis=1)


def make_trial(
    duration_s=300.0, offset_s=2.345678, drift_ppm=0.0, imu_rate=115.0, vicon_rate=100.0, seed=0, noise=True, gaps=True
):
    rng = np.random.default_rng(seed + 100)
    q_i2c = Q.from_rotation_vector(np.deg2rad([7.0, -12.0, 95.0]))
    t0_ns = int((DEVICE_START_S + 5) * NS)
    offset_ns = int(round((offset_s - DEVICE_START_S) * NS))
    t_dev = np.round(np.arange(int((duration_s + 20) * imu_rate)) * NS / imu_rate).astype(np.int64) + int(
        DEVICE_START_S * NS
    )
    t_ref = t_dev + offset_ns + np.round(drift_ppm * 1e-6 * (t_dev - t0_ns)).astype(np.int64)
    keep = (t_ref > -5 * NS) & (t_ref < (duration_s + 5) * NS)
    t_dev, t_ref = t_dev[keep], t_ref[keep]
    ts = t_ref / NS
    q_s2w = orientation_at(ts, seed)
    gyr = body_rate(ts, seed)
    h = 1e-3
    a_w = (position_at(ts + h) - 2 * position_at(ts) + position_at(ts - h)) / h**2
    acc = Q.rotate(Q.conjugate(q_s2w), a_w + [0, 0, 9.81])
    if noise:
        gyr = gyr + rng.normal(0, 0.003, gyr.shape) + np.array([0.004, -0.003, 0.002])
        acc = acc + rng.normal(0, 0.03, acc.shape)
    t_vic = np.round(np.arange(int(duration_s * vicon_rate)) * NS / vicon_rate).astype(np.int64)
    q_c2w = Q.multiply(orientation_at(t_vic / NS, seed), Q.conjugate(q_i2c))
    origin = position_at(t_vic / NS)
    labels = list(LOCAL)
    pos = np.stack([origin + Q.rotate(q_c2w, np.array(LOCAL[m])) for m in labels], axis=1)
    if noise:
        pos = pos + rng.normal(0, 0.0003, pos.shape)
    if gaps:
        pos[1000:1005, 1] = np.nan  # 50 ms gap in X: interpolated
        pos[5000:5100, 3] = np.nan  # 1 s gap in A: stays missing
    truth = {
        "offset_ns": offset_ns,
        "drift_ppm": drift_ppm,
        "t0_ns": t0_ns,
        "q_i2c": q_i2c,
        "q_s2w": q_s2w,
        "t_ref": t_ref,
    }
    return {
        "t_dev": t_dev,
        "gyr": gyr,
        "acc": acc,
        "t_vic": t_vic,
        "labels": labels,
        "pos": pos,
        "q_c2w": q_c2w,
        "truth": truth,
    }


@pytest.fixture(scope="module")
def trial():
    return make_trial()


@pytest.fixture(scope="module")
def drift_trial():
    return make_trial(duration_s=420.0, drift_ppm=50.0, offset_s=-1.2345, seed=3)


# --------------------------------------------------------------------------------------------


def test_device_to_reference_formula():
    a = {"offset_ns": 1_500_000_000, "drift_ppm": 20.0, "t0_ns": 10 * NS}
    t = np.array([10 * NS, 110 * NS], dtype=np.int64)
    out = al.device_to_reference(t, a)
    assert out.dtype == np.int64
    # 100 s after t0 at 20 ppm is 2 ms
    assert out.tolist() == [11_500_000_000, 111_500_000_000 + 2_000_000]
    assert np.array_equal(al.reference_to_device(out, a), t)
    # records read back from MCAP metadata may hold strings
    assert al.device_to_reference(np.int64(5), {"offset_ns": "7", "drift_ppm": "0", "t0_ns": "0"}) == 12


def test_oxy_frame_matches_thesis_construction(trial):
    pos = make_trial(noise=False, gaps=False)["pos"]
    r = al.cluster_frame_oxy(pos[:, 0], pos[:, 1], pos[:, 2])
    q = Q.from_rotation_matrix(r)
    assert np.max(np.rad2deg(Q.angle_between(q, trial["q_c2w"]))) < 1e-6
    assert np.allclose(np.linalg.det(r), 1.0)


def test_svd_cluster_fit_any_three_markers(trial):
    clean = make_trial(noise=False, gaps=False)
    pos = clean["pos"].copy()
    pos[200:300, 0] = np.nan  # O hidden: three markers left
    local = np.array([LOCAL[m] for m in clean["labels"]])
    r, origin = al.cluster_frame_svd(pos, local)
    err = np.rad2deg(Q.angle_between(Q.from_rotation_matrix(r), clean["q_c2w"]))
    assert err.max() < 1e-6
    # origin = cluster-frame origin of the local coordinates (marker O)
    assert np.nanmax(np.abs(origin - clean["pos"][:, 0])) < 1e-9
    # without local coordinates: orientation relative to the first complete frame
    r2, _ = al.cluster_frame_svd(pos)
    rel = Q.multiply(Q.from_rotation_matrix(r2), Q.conjugate(Q.from_rotation_matrix(r2[0])))
    rel_true = Q.multiply(clean["q_c2w"], Q.conjugate(clean["q_c2w"][0]))
    assert np.rad2deg(Q.angle_between(rel, rel_true)).max() < 1e-3
    pos[400, :2] = np.nan  # two markers left: no pose
    r3, _ = al.cluster_frame_svd(pos, local)
    assert np.isnan(r3[400]).all() and np.isfinite(r3[401]).all()


def test_lowpass_gap_handling():
    rate = 100.0
    t = np.arange(2000) / rate
    x = np.stack([np.sin(2 * np.pi * 0.5 * t), np.cos(2 * np.pi * 0.3 * t), t * 0.01], axis=1)
    noisy = x + np.random.default_rng(0).normal(0, 0.002, x.shape)
    noisy[100:105] = np.nan  # short: interpolated
    noisy[1000:1100] = np.nan  # long: kept missing
    out, missing = al.lowpass_markers(noisy, rate)
    assert not missing[100:105].any() and np.isfinite(out[100:105]).all()
    assert missing[1000:1100].all() and np.isnan(out[1000:1100]).all()
    assert not np.any(out[np.isnan(out).any(axis=1) == False] == 0.0)  # noqa: E712 - never zero-filled
    inner = np.r_[50:950, 1150:1950]
    raw_rms = np.sqrt(np.nanmean((noisy[inner] - x[inner]) ** 2))
    assert np.sqrt(np.mean((out[inner] - x[inner]) ** 2)) < 0.5 * raw_rms  # noise removed, 0.5 Hz kept
    # high-frequency content (20 Hz) is removed
    hf = x + 0.01 * np.sin(2 * np.pi * 20 * t)[:, None]
    out2, _ = al.lowpass_markers(hf, rate)
    assert np.max(np.abs(out2[100:-100] - x[100:-100])) < 0.001


def test_angular_velocity_from_rotations_matches_body_rate(trial):
    clean = make_trial(noise=False, gaps=False)
    r = Q.to_rotation_matrix(clean["q_c2w"])
    w = al.angular_velocity_from_rotations(r, 100.0)
    q_i2c = clean["truth"]["q_i2c"]
    true_local = Q.rotate(q_i2c, body_rate(clean["t_vic"] / NS))
    err = np.linalg.norm(w - true_local, axis=1)
    assert np.percentile(err[1:-1], 99) < 0.02  # rad/s, central difference at 100 Hz
    # thesis eq. 2.9: |w| = acos((tr dR - 1) / 2) / dt for consecutive samples
    d_r = np.einsum("nji,njk->nik", r[:-1], r[1:])
    mag = np.arccos(np.clip((np.trace(d_r, axis1=1, axis2=2) - 1) / 2, -1, 1)) * 100.0
    mid = 0.5 * (np.linalg.norm(w[:-1], axis=1) + np.linalg.norm(w[1:], axis=1))
    assert np.percentile(np.abs(mag - mid), 99) < 0.02


def _run(tr, params):
    ck = al.cluster_kinematics(tr["t_vic"], tr["labels"], tr["pos"], 100.0, params)
    ori = estimate_orientation(tr["gyr"], tr["acc"], 115.0)
    res = al.align(tr["t_dev"], tr["gyr"], ck, params, q_imu_s2g=ori.quat)
    return res, ori


@pytest.mark.parametrize("cluster", ["oxy", "svd"])
def test_lag_and_rotation_recovered(trial, cluster):
    params = al.AlignmentParams(cluster=cluster)
    res, ori = _run(trial, params)
    truth = trial["truth"]
    est = al.device_to_reference(trial["t_dev"], res)
    # lag within one Vicon sample (10 ms) everywhere
    assert np.max(np.abs(est - truth["t_ref"])) < 10_000_000
    err_rot = np.rad2deg(Q.angle_between(res["rotation_imu_to_cluster"], truth["q_i2c"]))
    assert err_rot < 1.0
    assert res["score"] > 0.8
    # orientation error against truth, on the reference clock and in the world frame
    q_world = Q.multiply(res["rotation_global_to_world"], ori.quat)
    rms = np.rad2deg(np.sqrt(np.mean(Q.angle_between(q_world, truth["q_s2w"]) ** 2)))
    print(
        f"\n[{cluster}] lag error max {np.max(np.abs(est - truth['t_ref'])) / 1e6:.3f} ms, "
        f"IMU-to-cluster {err_rot:.3f} deg, orientation RMSE vs truth {rms:.2f} deg"
    )
    assert rms < 3.0


def test_drift_recovered(drift_trial):
    params = al.AlignmentParams(drift=True)
    res, _ = _run(drift_trial, params)
    truth = drift_trial["truth"]
    assert abs(res["drift_ppm"] - truth["drift_ppm"]) < 10.0
    est = al.device_to_reference(drift_trial["t_dev"], res)
    assert np.max(np.abs(est - truth["t_ref"])) < 10_000_000
    # without drift estimation, the end of the recording is off by about 50 ppm * 400 s = 20 ms
    res0, _ = _run(drift_trial, al.AlignmentParams(drift=False))
    est0 = al.device_to_reference(drift_trial["t_dev"], res0)
    assert np.max(np.abs(est0 - truth["t_ref"])) > np.max(np.abs(est - truth["t_ref"]))


def test_lag_configurable_window(trial):
    ck = al.cluster_kinematics(trial["t_vic"], trial["labels"], trial["pos"], 100.0)
    wn = np.linalg.norm(trial["gyr"], axis=1)
    lag = al.estimate_lag(
        trial["t_dev"], wn, ck.t_ns, np.linalg.norm(ck.omega_local_rad_s, axis=1), window_start_s=100, window_s=60
    )
    assert abs(lag.offset_ns - trial["truth"]["offset_ns"]) < 10_000_000


def test_missing_marker_is_a_clear_error(trial):
    with pytest.raises(ValueError, match="marker"):
        al.cluster_kinematics(
            trial["t_vic"], ["P", "Q", "R", "S"], trial["pos"], 100.0, al.AlignmentParams(cluster="oxy")
        )


# --------------------------------------------------------------------------------------------
# resampling 115 -> 100 Hz


def test_resample_is_anti_aliased():
    from imulog.process.resample import resample_signal, uniform_grid

    t_src = uniform_grid(0, 20 * NS, 115.0)
    ts = t_src / NS
    slow = np.sin(2 * np.pi * 2.0 * ts)
    alias = 0.5 * np.sin(2 * np.pi * 55.0 * ts)  # above the 50 Hz Nyquist of 100 Hz: would fold to 45 Hz
    t_dst = uniform_grid(NS, 19 * NS, 100.0)
    out = resample_signal(t_src, np.stack([slow + alias, slow], axis=1), t_dst)
    truth = np.sin(2 * np.pi * 2.0 * t_dst / NS)
    plain = np.interp(t_dst, t_src, slow + alias)
    assert np.sqrt(np.mean((out[:, 0] - truth) ** 2)) < 0.05
    assert np.sqrt(np.mean((plain - truth) ** 2)) > 0.2  # what MATLAB-style interp1 would keep
    assert np.max(np.abs(out[:, 1] - truth)) < 0.01
    # outside the source span: NaN, not extrapolated
    assert np.isnan(resample_signal(t_src, slow, np.array([-NS, 21 * NS]))).all()


def test_resample_quaternions_follow_rotation():
    from imulog.process.resample import resample_quaternions, uniform_grid

    t_src = uniform_grid(0, 30 * NS, 115.0)
    q_src = orientation_at(t_src / NS)
    q_src[::7] *= -1  # sign flips must not matter
    t_dst = uniform_grid(NS, 29 * NS, 100.0)
    out = resample_quaternions(t_src, q_src, t_dst)
    err = np.rad2deg(Q.angle_between(out, orientation_at(t_dst / NS)))
    assert np.allclose(np.linalg.norm(out, axis=1), 1.0)
    assert np.percentile(err, 99) < 0.2


def test_lag_without_overlap_is_a_clear_error():
    """A device recording of 3 s against a 20 s reference window: no lag overlaps half the window; a clear
    error instead of the argmax of an all -inf correlation (which returned an arbitrary offset)."""
    t = np.arange(0, 30 * 200) * 5_000_000
    w = np.abs(np.sin(np.arange(len(t)) / 50.0))
    with pytest.raises(ValueError, match="--max-lag"):
        al.estimate_lag(t[:600], w[:600], t, w, window_s=20.0, max_lag_s=5.0)
    est = al.estimate_lag(t + 2 * 10**9, w, t, w, window_s=120.0, max_lag_s=5.0)  # window > recording
    assert abs(est.offset_ns + 2 * 10**9) < 5_000_000
