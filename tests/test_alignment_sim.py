"""Alignment and orientation against the simulator's ground truth (imulog.simulate, R2G protocol).

The simulated IMU has noise, bias, scale and misalignment errors, dropped samples and a drifting
clock; the Vicon markers have noise and gaps. Truth: ``truth.alignment`` (offset, drift, rotations)
and ``truth.imu_t_ref_ns`` (exact reference time of every IMU sample).
"""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process import alignment as al
from imulog.process import quaternion as Q
from imulog.process.orientation import estimate_orientation
from imulog.process.resample import resample_quaternions
from imulog.simulate import simulate
from imulog.steps.common import mean_rate_hz as rate_hz

VICON_SAMPLE_NS = 10_000_000


@pytest.fixture(scope="module", params=[0, 1])
def sim(request):
    return simulate("r2g", seed=request.param)


def test_simulated_r2g_alignment(sim):
    imu, mk, truth = sim.recording.imus[0], sim.recording.markers[0], sim.truth
    ck = al.cluster_kinematics(mk.t_ns, mk.labels, mk.pos, rate_hz(mk.t_ns))
    ori = estimate_orientation(imu.gyr, imu.acc, rate_hz(imu.t_ns), t_ns=imu.t_ns)
    res = al.align(imu.t_ns, imu.gyr, ck, al.AlignmentParams(drift=True), q_imu_s2g=ori.quat)
    est = al.device_to_reference(imu.t_ns, res)
    lag_err = np.abs(est - truth.imu_t_ref_ns)
    assert lag_err.max() < VICON_SAMPLE_NS
    assert abs(res["drift_ppm"] - truth.alignment["drift_ppm"]) < 10.0
    rot_err = np.rad2deg(Q.angle_between(res["rotation_imu_to_cluster"], truth.alignment["rotation_imu_to_cluster"]))
    assert rot_err < 1.0
    # orientation in the world frame on the reference clock against the simulator's truth
    q_world = Q.multiply(res["rotation_global_to_world"], resample_quaternions(est, ori.quat, truth.t_ns))
    err = np.rad2deg(Q.angle_between(q_world, truth.orientation))
    rms = float(np.sqrt(np.nanmean(err**2)))
    print(
        f"\nseed lag error max {lag_err.max() / 1e6:.2f} ms, drift {res['drift_ppm']:.1f} ppm "
        f"(true {truth.alignment['drift_ppm']:.1f}), IMU-to-cluster {rot_err:.2f} deg, "
        f"orientation RMSE vs truth {rms:.2f} deg"
    )
    assert rms < 3.0


def test_without_drift_estimation_the_end_slips(sim):
    """The simulated clock drifts (tens of ppm): a single-window offset is off by more at the end."""
    imu, mk, truth = sim.recording.imus[0], sim.recording.markers[0], sim.truth
    ck = al.cluster_kinematics(mk.t_ns, mk.labels, mk.pos, rate_hz(mk.t_ns))
    res = al.align(imu.t_ns, imu.gyr, ck, al.AlignmentParams(drift=False))
    err = np.abs(al.device_to_reference(imu.t_ns, res) - truth.imu_t_ref_ns)
    assert abs(res["drift_ppm"]) == 0.0
    assert err[-100:].mean() > err[:100].mean()


def test_noise_free_rotation_is_exact():
    sim = simulate("r2g", seed=2, noise_free=True, repetitions=5)
    imu, mk, truth = sim.recording.imus[0], sim.recording.markers[0], sim.truth
    ck = al.cluster_kinematics(mk.t_ns, mk.labels, mk.pos, rate_hz(mk.t_ns))
    res = al.align(imu.t_ns, imu.gyr, ck, al.AlignmentParams(window_s=60.0))
    rot_err = np.rad2deg(Q.angle_between(res["rotation_imu_to_cluster"], truth.alignment["rotation_imu_to_cluster"]))
    assert rot_err < 0.05


def test_dropped_samples_filtered_on_a_uniform_grid(sim):
    """The simulated IMU drops samples; filtering with the real time stamps beats assuming a fixed rate."""
    from imulog.process.orientation import orientation_errors

    imu, truth = sim.recording.imus[0], sim.truth
    d = np.diff(imu.t_ns)
    assert np.any(d > 1.5 * np.median(d))  # there are dropped samples
    q_true = resample_quaternions(truth.t_ns, truth.orientation, truth.imu_t_ref_ns)
    ok = np.all(np.isfinite(q_true), axis=1)
    fixed = estimate_orientation(imu.gyr, imu.acc, rate_hz(imu.t_ns))
    timed = estimate_orientation(imu.gyr, imu.acc, rate_hz(imu.t_ns), t_ns=imu.t_ns)
    e_fixed = orientation_errors(fixed.quat[ok], q_true[ok])
    e_timed = orientation_errors(timed.quat[ok], q_true[ok])
    print(
        f"\nheading-free RMSE: fixed rate {e_fixed['heading_free_rmse_deg']:.2f} deg, "
        f"uniform grid {e_timed['heading_free_rmse_deg']:.2f} deg"
    )
    assert e_timed["heading_free_rmse_deg"] < e_fixed["heading_free_rmse_deg"]
    assert len(timed.quat) == len(imu.t_ns) and len(timed.static) == len(imu.t_ns)
