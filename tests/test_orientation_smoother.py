"""The RTS orientation smoother (imulog.process.orientation_smoother): exact where its model holds, and measured
against VQF offline on the shared BROAD trials (where it is not the default, docs/orientation.md)."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process import quaternion as Q
from imulog.process.orientation import OrientationParams, estimate_orientation, orientation_errors
from imulog.process.orientation_smoother import SmootherParams, rest_mask, smooth_orientation


def _trial(seconds: float = 60.0, rate: float = 200.0, seed: int = 1, gain: float = 1.0):
    """Rotations with 3-s rests every 20 s (peak rates ``gain`` x 0.8/0.6/0.5 rad/s), a constant gyroscope bias,
    white noise on both sensors."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    t = np.arange(n) / rate
    w = gain * np.stack(
        [
            0.8 * np.sin(2 * np.pi * 0.13 * t),
            0.6 * np.sin(2 * np.pi * 0.21 * t + 1),
            0.5 * np.sin(2 * np.pi * 0.07 * t),
        ],
        axis=1,
    )
    w[(t % 20) < 3] = 0.0
    q = np.empty((n, 4))
    q[0] = Q.IDENTITY
    for k in range(1, n):  # the rate at k carries k-1 to k
        q[k] = Q.multiply(q[k - 1 : k], Q.from_rotation_vector(w[k : k + 1] / rate))[0]
    acc = Q.rotate(Q.conjugate(q), np.tile([0.0, 0.0, 9.81], (n, 1))) + rng.normal(0, 0.05, (n, 3))
    bias = np.array([0.01, -0.02, 0.015])
    gyr = w + bias + rng.normal(0, 0.005, (n, 3))
    return q, gyr, acc, rate, bias


def test_smoother_recovers_bias_and_beats_its_own_forward_pass():
    q, gyr, acc, rate, bias = _trial()
    qs, b = smooth_orientation(gyr, acc, rate)
    qf, _ = smooth_orientation(gyr, acc, rate, SmootherParams(backward=False))
    np.testing.assert_allclose(b[len(b) // 2], bias, atol=2e-3)
    smooth = orientation_errors(qs, q)["inclination_rmse_deg"]
    forward = orientation_errors(qf, q)["inclination_rmse_deg"]
    assert smooth < 0.8 * forward
    assert smooth < 0.3
    assert np.allclose(np.linalg.norm(qs, axis=1), 1.0)


def test_rest_needs_both_sensors_still():
    rate = 100.0
    gyr = np.zeros((1000, 3))
    acc = np.tile([0.0, 0.0, 9.81], (1000, 1))
    acc[400:600, 0] += 2.0 * np.sin(np.linspace(0, 20, 200))  # translation with the gyroscope still
    rest = rest_mask(gyr, acc, rate, SmootherParams())
    assert rest[:300].all() and not rest[450:550].any()


def test_smoother_rejects_bad_shapes_and_magnetometer():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        smooth_orientation(np.zeros((10, 3)), np.zeros((9, 3)), 100.0)
    with pytest.raises(ValueError, match="6D only"):
        estimate_orientation(
            np.zeros((10, 3)), np.ones((10, 3)), 100.0, np.ones((10, 3)), OrientationParams("rts", use_mag=True)
        )


def test_broad_smoother_against_vqf_offline(shared_data):
    """What docs/orientation.md publishes: on the shared BROAD trials the smoother is within 1.5x VQF offline's
    inclination RMSE (it is not better, so vqf_offline stays the default)."""
    h5py = pytest.importorskip("h5py")
    files = sorted((shared_data / "broad").glob("*.hdf5"))
    assert files
    for f in files:
        with h5py.File(f, "r") as h:
            d = {k: h[k][:] for k in ("imu_gyr", "imu_acc", "opt_quat", "movement")}
            rate = float(h.attrs["sampling_rate"])
        ok = d["movement"].astype(bool)
        rts = estimate_orientation(d["imu_gyr"], d["imu_acc"], rate, params=OrientationParams(backend="rts"))
        vqf = estimate_orientation(d["imu_gyr"], d["imu_acc"], rate, params=OrientationParams(backend="vqf_offline"))
        e_rts = orientation_errors(rts.quat, d["opt_quat"], ok)["inclination_rmse_deg"]
        e_vqf = orientation_errors(vqf.quat, d["opt_quat"], ok)["inclination_rmse_deg"]
        print(f"\n{f.name}: rts {e_rts:.3f} deg, vqf_offline {e_vqf:.3f} deg")
        assert e_rts < 1.5 * e_vqf
