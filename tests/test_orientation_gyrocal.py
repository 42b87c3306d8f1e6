"""The vqf_gyrocal backend (imulog.process.orientation_gyrocal): the gyroscope's sensitivity and misalignment,
self-calibrated over the whole trial, on simulated truth; and its standing against VQF offline on the shared BROAD
trials (the three it was tuned on; the held-out figures are in docs/orientation.md)."""

from __future__ import annotations

import numpy as np
import pytest
from test_orientation_smoother import _trial

from imulog.process.orientation import OrientationParams, estimate_orientation, orientation_errors
from imulog.process.orientation_gyrocal import GyroCalParams, integrate_gyro, vqf_gyrocal

#: a gyroscope 1 % too sensitive on x, 1 % too little on y, with cross-axis terms of 0.2-0.4 %
SENSITIVITY = np.array([[1.01, 0.003, -0.002], [-0.002, 0.99, 0.004], [0.003, -0.003, 1.005]])


def _miscalibrated(seed: int, gain: float = 1.0):
    q, gyr, acc, rate, bias = _trial(seconds=120.0, seed=seed, gain=gain)
    return q, (gyr - bias) @ SENSITIVITY.T + bias, acc, rate


@pytest.mark.parametrize(("seed", "gain"), [(1, 1.0), (2, 1.0), (1, 6.0)])
def test_recovers_sensitivity_and_beats_vqf_offline(seed, gain):
    """Slow rotations (peak 0.8 rad/s) and fast ones (gain 6: peak 4.8 rad/s)."""
    q, gyr, acc, rate = _miscalibrated(seed, gain)
    quat, m = vqf_gyrocal(gyr, acc, rate)
    # M undoes the sensitivity matrix: every entry of M S - I within 0.3 % (the errors are 0.2-1 %)
    assert np.abs(m @ SENSITIVITY - np.eye(3)).max() < 0.003
    vqf = estimate_orientation(gyr, acc, rate, params=OrientationParams(backend="vqf_offline")).quat
    e_cal = orientation_errors(quat, q)["inclination_rmse_deg"]
    e_vqf = orientation_errors(vqf, q)["inclination_rmse_deg"]
    print(f"\nseed {seed}, gain {gain}: vqf_gyrocal {e_cal:.3f} deg, vqf_offline {e_vqf:.3f} deg")
    assert e_cal < 0.5 * e_vqf


def test_a_calibrated_gyroscope_stays_calibrated():
    q, gyr, acc, rate, _ = _trial(seconds=120.0, seed=3)
    quat, m = vqf_gyrocal(gyr, acc, rate)
    assert np.abs(m - np.eye(3)).max() < 0.003
    assert orientation_errors(quat, q)["inclination_rmse_deg"] < 0.1


def test_short_recording_is_plain_vqf_offline():
    q, gyr, acc, rate, _ = _trial(seconds=20.0, seed=4)
    quat, m = vqf_gyrocal(gyr, acc, rate, params=GyroCalParams(min_duration_s=30.0))
    assert np.array_equal(m, np.eye(3))
    vqf = estimate_orientation(gyr, acc, rate, params=OrientationParams(backend="vqf_offline")).quat
    np.testing.assert_allclose(quat, vqf, atol=1e-12)


def test_integrate_gyro_matches_a_known_rotation():
    rate = 100.0
    gyr = np.tile([0.0, 0.0, np.pi / 2], (100, 1))  # 90 deg/s about z for 1 s
    q = integrate_gyro(gyr, 1.0 / rate)
    np.testing.assert_allclose(q[-1], [np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)], atol=1e-12)


def test_bad_shapes_are_a_clear_error():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        vqf_gyrocal(np.zeros((10, 3)), np.zeros((9, 3)), 100.0)


def test_9d_is_enu_through_the_step_api():
    q, gyr, acc, rate = _miscalibrated(5)
    mag = np.tile([0.0, 20.0, -40.0], (len(q), 1))  # north and down in the truth's frame
    from imulog.process import quaternion as Q

    mag_sensor = Q.rotate(Q.conjugate(q), mag)
    res = estimate_orientation(gyr, acc, rate, mag_sensor, OrientationParams(backend="vqf_gyrocal", use_mag=True))
    assert res.global_frame == "ENU"
    # the truth's frame is ENU here (field north along +y): the 9D estimate needs no heading fit
    assert np.median(np.rad2deg(Q.angle_between(res.quat, q))) < 2.0


def test_broad_tuning_trials_against_vqf_offline(shared_data):
    """The three shared trials are the ones its settings were chosen on: there it must stay ahead of VQF offline
    on the mean and within 5 % on each (the held-out verdict, where it is not, is in docs/orientation.md)."""
    h5py = pytest.importorskip("h5py")
    files = sorted((shared_data / "broad").glob("*.hdf5"))
    assert len(files) == 3
    cal, base = [], []
    for f in files:
        with h5py.File(f, "r") as h:
            d = {k: h[k][:] for k in ("imu_gyr", "imu_acc", "opt_quat", "movement")}
            rate = float(h.attrs["sampling_rate"])
        for backend, out in (("vqf_gyrocal", cal), ("vqf_offline", base)):
            r = estimate_orientation(d["imu_gyr"], d["imu_acc"], rate, params=OrientationParams(backend=backend))
            out.append(orientation_errors(r.quat, d["opt_quat"], d["movement"])["inclination_rmse_deg"])
    print(f"\nvqf_gyrocal {np.round(cal, 3)}, vqf_offline {np.round(base, 3)}")
    assert np.mean(cal) < np.mean(base)
    assert all(c <= 1.05 * b for c, b in zip(cal, base, strict=True))
