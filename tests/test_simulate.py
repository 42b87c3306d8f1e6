"""Simulator: determinism, analytic consistency of the IMU signals with the true motion, clocks,
Vicon cluster geometry, phase truth, ground-truth files."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process import quaternion as Q
from imulog.simulate import load_truth, parameter_names, simulate, write_trial_files
from imulog.simulate.imu_model import EARTH_G

SHORT = {"repetitions": 3, "opening_static_s": 5.0, "post_wave_static_s": 3.0}


@pytest.fixture(scope="module")
def ideal():
    return simulate("r2g", subject=1, trial=2, seed=7, noise_free=True, **SHORT)


@pytest.fixture(scope="module")
def noisy():
    return simulate("r2g", subject=1, trial=2, seed=7, **SHORT)


def _integrate_task(sim, rep: int, zupt: bool) -> tuple[float, float]:
    """Strapdown double integration (trapezoid) of the IMU's specific force over one task with the
    true orientation, from the true initial state; with ``zupt`` the velocity is reset to zero at the
    samples the truth marks static (exactly what a segmentation of noise-free data finds).
    Returns max position (m) and velocity (m/s) errors."""
    tr = sim.truth
    imu = sim.recording.imus[0]
    sel = tr.phases.task_index == rep
    a, b = tr.phases.start_ns[sel].min() - 1e9, tr.phases.end_ns[sel].max() + 1e9
    m = (tr.imu_t_ref_ns >= a) & (tr.imu_t_ref_ns <= b)
    t = tr.imu_t_ref_ns[m] / 1e9
    acc_w = Q.rotate(tr.imu_orientation[m], imu.acc[m]) - [0.0, 0.0, EARTH_G]
    dt = np.diff(t)[:, None]
    dv = 0.5 * (acc_w[1:] + acc_w[:-1]) * dt
    static = tr.imu_static_mask[m]
    v = np.empty_like(acc_w)
    v[0] = tr.imu_velocity[m][0]
    for k in range(1, len(t)):
        v[k] = 0.0 if (zupt and static[k]) else v[k - 1] + dv[k - 1]
    p = tr.imu_position[m][0] + np.vstack([np.zeros(3), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt, axis=0)])
    return float(np.abs(p - tr.imu_position[m]).max()), float(np.abs(v - tr.imu_velocity[m]).max())


def test_deterministic_by_seed():
    a = simulate("r2g", seed=3, **SHORT)
    b = simulate("r2g", seed=3, **SHORT)
    c = simulate("r2g", seed=4, **SHORT)
    ia, ib, ic = a.recording.imus[0], b.recording.imus[0], c.recording.imus[0]
    assert np.array_equal(ia.t_ns, ib.t_ns) and np.array_equal(ia.acc, ib.acc) and np.array_equal(ia.mag, ib.mag)
    assert np.array_equal(a.recording.markers[0].pos, b.recording.markers[0].pos, equal_nan=True)
    assert np.array_equal(a.truth.position, b.truth.position)
    assert a.truth.alignment == b.truth.alignment
    assert len(ia) != len(ic) or not np.array_equal(ia.acc, ic.acc)


def test_motion_does_not_depend_on_sensor_options(ideal, noisy):
    assert np.array_equal(ideal.truth.position, noisy.truth.position)
    assert ideal.truth.phases.labels == noisy.truth.phases.labels
    assert np.array_equal(ideal.truth.phases.start_ns, noisy.truth.phases.start_ns)


def test_noise_free_integrates_back_within_1mm(ideal):
    for rep in (1, 2, 3):
        pos_err, vel_err = _integrate_task(ideal, rep, zupt=True)
        assert pos_err < 1e-3, f"task {rep}: {pos_err * 1e3:.3f} mm"
        assert vel_err < 1e-3


def test_noise_free_error_is_only_the_integration_scheme():
    # Without zero-velocity resets the trapezoid's O(dt^2) error at the minimum-jerk onsets/offsets
    # (jerk jumps there) accumulates to ~1-2 mm over a 20 s task at 115 Hz; at 1 kHz it is ~75x
    # smaller: the signals are exact, the residual is the integration scheme's.
    fast = simulate(
        "r2g", seed=7, noise_free=True, imu_rate_hz=1000.0, repetitions=1, opening_static_s=2.0, post_wave_static_s=1.0
    )
    pos_err, _ = _integrate_task(fast, 1, zupt=False)
    assert pos_err < 5e-5


def test_noise_free_gyro_is_the_body_rate_and_integrates_to_orientation(ideal):
    tr = ideal.truth
    imu = ideal.recording.imus[0]
    assert np.abs(imu.gyr - tr.imu_angular_velocity).max() < 1e-8
    # integrate the gyro (midpoint rotation vector) over the wave and the first task
    ev = tr.events
    a = ev.start_ns[ev.labels.index("wave")] - 500_000_000
    b = tr.phases.end_ns[tr.phases.task_index == 1].max()
    m = np.flatnonzero((tr.imu_t_ref_ns >= a) & (tr.imu_t_ref_ns <= b))
    q = tr.imu_orientation[m[0]]
    t = tr.imu_t_ref_ns / 1e9
    worst = 0.0
    for i, j in zip(m[:-1], m[1:], strict=True):
        q = Q.multiply(q, Q.from_rotation_vector(0.5 * (imu.gyr[i] + imu.gyr[j]) * (t[j] - t[i])))
        err = np.linalg.norm(Q.to_rotation_vector(Q.multiply(Q.conjugate(tr.imu_orientation[j]), q)))
        worst = max(worst, err)
    assert np.degrees(worst) < 0.5


def test_static_specific_force_is_gravity(ideal):
    tr = ideal.truth
    acc = ideal.recording.imus[0].acc[tr.imu_static_mask]
    assert np.allclose(np.linalg.norm(acc, axis=1), EARTH_G, atol=1e-6)
    up = Q.rotate(tr.imu_orientation[tr.imu_static_mask], acc)
    assert np.allclose(up, [0.0, 0.0, EARTH_G], atol=1e-6)


def test_clock_mapping_matches_convention(noisy):
    from imulog.process.alignment import device_to_reference

    imu = noisy.recording.imus[0]
    al = noisy.truth.alignment
    assert set(al) >= {
        "reference",
        "imu",
        "offset_ns",
        "drift_ppm",
        "t0_ns",
        "rotation_imu_to_cluster",
        "rotation_global_to_world",
        "method",
        "score",
    }
    assert al["t0_ns"] == imu.t_ns[0]
    assert np.array_equal(noisy.truth.imu_t_dev_ns, imu.t_ns)
    mapped = device_to_reference(imu.t_ns, al)
    assert np.abs(mapped - noisy.truth.imu_t_ref_ns).max() <= 1
    # device clock runs at the nominal 114.9 Hz; on the reference clock the rate carries the drift
    dev_rate = 1e9 / np.median(np.diff(imu.t_ns))
    assert dev_rate == pytest.approx(114.9, rel=1e-4)
    ref_rate = (len(imu.t_ns) - 1 + len(noisy.truth.imu_dropped_t_dev_ns)) / (
        (noisy.truth.imu_t_ref_ns[-1] - noisy.truth.imu_t_ref_ns[0]) / 1e9
    )
    assert ref_rate == pytest.approx(114.9 / (1 + al["drift_ppm"] * 1e-6), rel=2e-6)
    # the IMU records inside the Vicon span
    assert noisy.truth.imu_t_ref_ns[0] > 0 and noisy.truth.imu_t_ref_ns[-1] < noisy.truth.t_ns[-1]


def test_dropped_samples_leave_gaps(noisy):
    dropped = noisy.truth.imu_dropped_t_dev_ns
    assert len(dropped) > 0
    t = noisy.recording.imus[0].t_ns
    assert not np.isin(dropped, t).any()
    assert np.diff(t).max() > 1.5 * np.median(np.diff(t))


def test_vicon_cluster_follows_truth(ideal):
    mk = ideal.recording.markers[0]
    tr = ideal.truth
    assert mk.labels == ["O", "X", "Y", "A"]
    assert np.array_equal(mk.t_ns, tr.t_ns)
    assert np.array_equal(tr.t_ns, np.round(np.arange(len(tr.t_ns)) / 100.0 * 1e9).astype(np.int64))
    o, x, y = mk.pos[:, 0], mk.pos[:, 1], mk.pos[:, 2]
    assert np.abs(o - tr.position).max() < 1e-6
    ex = (x - o) / np.linalg.norm(x - o, axis=1, keepdims=True)
    ez = np.cross(ex, y - o)
    ez /= np.linalg.norm(ez, axis=1, keepdims=True)
    ey = np.cross(ez, ex)
    r_cluster = np.stack([ex, ey, ez], axis=2)  # columns: cluster axes in world
    q_ic = np.asarray(tr.alignment["rotation_imu_to_cluster"])
    r_expected = Q.to_rotation_matrix(Q.multiply(tr.orientation, Q.conjugate(q_ic)))
    assert np.abs(r_cluster - r_expected).max() < 1e-3  # 0.1 um marker rounding over 35-45 mm
    angle = np.degrees(np.linalg.norm(Q.to_rotation_vector(q_ic)))
    assert 0.1 < angle < 15.0


def test_vicon_noise_and_gaps(noisy, ideal):
    d = (noisy.recording.markers[0].pos - ideal.recording.markers[0].pos) * 1e3
    sd = np.nanstd(d)
    assert 0.1 < sd < 0.5  # sub-millimetre
    assert np.isnan(noisy.recording.markers[0].pos).any()
    assert not np.isnan(ideal.recording.markers[0].pos).any()


def test_phase_truth_consistent_with_kinematics(ideal):
    tr = ideal.truth
    ph = tr.phases
    assert ph.labels == ["reach", "lift", "return_bottle", "return_hand"] * 3
    assert list(ph.task_index) == [1] * 4 + [2] * 4 + [3] * 4
    assert np.all(ph.start_ns[1:] >= ph.end_ns[:-1])
    speed = np.linalg.norm(tr.velocity, axis=1)
    assert np.all(speed[tr.static_mask] == 0.0)
    inside = np.zeros(len(tr.t_ns), bool)
    for s, e in zip(ph.start_ns, ph.end_ns, strict=True):
        sel = (tr.t_ns > s) & (tr.t_ns < e)
        inside |= sel
        assert speed[sel].max() > 0.1  # a real movement inside every phase
    wave = tr.events.labels.index("wave")
    wave_sel = (tr.t_ns > tr.events.start_ns[wave]) & (tr.t_ns < tr.events.end_ns[wave])
    assert np.all(tr.static_mask[~inside & ~wave_sel])  # still between phases
    # ~4 s static between phases (thesis), longer rest between tasks
    gaps = (ph.start_ns[1:] - ph.end_ns[:-1]) / 1e9
    within = gaps[np.diff(ph.task_index) == 0]
    between = gaps[np.diff(ph.task_index) == 1]
    assert 2.0 < within.mean() < 6.0 and between.min() > within.mean()
    # the wave is fast rotation, no translation
    w = np.degrees(np.linalg.norm(tr.angular_velocity[wave_sel], axis=1))
    assert w.max() > 100.0 and np.all(speed[wave_sel] == 0.0)


def test_r2g_anthropometric_waypoints(ideal):
    tr = ideal.truth
    anth = ideal.recording.metadata["imulog.anthropometrics"]
    start = tr.position[0]
    ph = tr.phases
    end_reach = [np.searchsorted(tr.t_ns, e) for e, lab in zip(ph.end_ns, ph.labels, strict=True) if lab == "reach"]
    end_lift = [np.searchsorted(tr.t_ns, e) for e, lab in zip(ph.end_ns, ph.labels, strict=True) if lab == "lift"]
    d_reach = tr.position[end_reach] - start
    d_lift = tr.position[end_lift] - start
    assert np.allclose(d_reach[:, 0], anth["h1_m"], atol=0.04)
    assert np.allclose(d_lift[:, 1], anth["h2_m"], atol=0.04)
    assert np.allclose(d_lift[:, 2], anth["h3_m"], atol=0.04)
    assert anth["bottle_distance_m"] == pytest.approx(1.5 * anth["forearm_length_m"])


def test_residual_velocity_and_extra_submovements():
    base = simulate("r2g", seed=2, noise_free=True, **SHORT)
    drift = simulate("r2g", seed=2, noise_free=True, residual_velocity_mps=0.01, **SHORT)
    ph = drift.truth.phases
    sel = (drift.truth.t_ns > ph.end_ns[0] + 1e9) & (drift.truth.t_ns < ph.start_ns[1] - 1e9)
    assert np.linalg.norm(drift.truth.velocity[sel], axis=1).mean() > 0.005
    bph = base.truth.phases
    bsel = (base.truth.t_ns > bph.end_ns[0] + 1e9) & (base.truth.t_ns < bph.start_ns[1] - 1e9)
    assert np.all(np.linalg.norm(base.truth.velocity[bsel], axis=1) == 0.0)

    extra = simulate("r2g", seed=2, noise_free=True, extra_submovement_probability=1.0, **SHORT)
    tr = extra.truth
    for s, e in zip(tr.phases.start_ns, tr.phases.end_ns, strict=True):
        moving = ~tr.static_mask[(tr.t_ns >= s) & (tr.t_ns <= e)]
        starts = np.count_nonzero(np.diff(np.r_[0, moving.astype(int)]) == 1)
        assert starts == 2  # primary movement + corrective sub-movement


def test_imu_sensor_model_ranges_and_quantisation(noisy):
    imu = noisy.recording.imus[0]
    lsb = 0.732e-3 * 9.80665
    counts = imu.acc / lsb
    assert np.abs(counts - np.round(counts)).max() < 1e-6
    assert np.abs(imu.acc).max() <= 16 * 9.80665 + lsb
    gyr_counts = np.degrees(imu.gyr) / 0.07
    assert np.abs(gyr_counts - np.round(gyr_counts)).max() < 1e-6
    # white noise of the gyro in the opening static period ~0.1 dps
    tr = noisy.truth
    static = tr.imu_t_ref_ns < tr.events.end_ns[0] - 1e9
    sd = np.degrees(imu.gyr[static]).std(axis=0)
    assert np.all((sd > 0.05) & (sd < 0.2))
    # magnetometer: hard iron moves the static field away from the true 46 uT sphere centre
    field = np.linalg.norm(imu.mag[static].mean(axis=0))
    assert 20 < field < 80


def test_truth_file_round_trip(tmp_path, noisy):
    paths = write_trial_files(noisy, tmp_path)
    assert {"imu", "mapping", "vicon", "truth", "truth_npz", "meta"} <= set(paths)
    back = load_truth(paths["truth"])
    tr = noisy.truth
    for name in ("t_ns", "position", "orientation", "static_mask", "imu_t_ref_ns", "imu_position"):
        assert np.array_equal(getattr(back, name), getattr(tr, name))
    assert back.phases.labels == tr.phases.labels and np.array_equal(back.phases.task_index, tr.phases.task_index)
    assert back.alignment == tr.alignment
    assert load_truth(paths["truth_npz"]).protocol == "r2g"


def test_unknown_override_is_rejected():
    with pytest.raises(TypeError, match="repetitons"):
        simulate("r2g", repetitons=3)
    with pytest.raises(ValueError, match="unknown protocol"):
        simulate("walk")
    assert "repetitions" in parameter_names("r2g")["protocol"]


def test_full_r2g_trial():
    sim = simulate("r2g", seed=0)
    assert len(sim.truth.phases) == 100
    assert sim.truth.phases.task_index.max() == 25
    assert len(sim.recording.imus[0]) > 60_000
