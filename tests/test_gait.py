"""Stride-level evaluation (imulog.process.gait) on the real gaitmap foot recording and on constructed strides."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from imulog.process.gait import StrideParams, heading_rotation, stride_errors, strides_from_rests
from imulog.process.integration import ZuptParams, zupt
from imulog.process.orientation import estimate_orientation, gravity_free_acceleration

RATE_IMU, RATE_MOCAP = 204.8, 100.0


def test_strides_run_mid_stance_to_mid_stance_and_skip_standing():
    rate = 100.0
    static = np.zeros(1000, dtype=bool)
    for a, b in [(0, 300), (400, 440), (500, 540), (600, 640), (900, 1000)]:
        static[a:b] = True
    st = strides_from_rests(static, rate, StrideParams(min_stride_s=0.5, max_rest_s=1.0))
    # the rests of 3 s and 1 s at the ends are standing: only the two strides between walking rests remain
    assert st.tolist() == [[419, 519], [519, 619]]


def test_heading_rotation_recovers_a_known_yaw():
    rng = np.random.default_rng(0)
    ref = rng.normal(size=(50, 2))
    yaw = np.radians(37.0)
    est = ref @ np.array([[np.cos(yaw), np.sin(yaw)], [-np.sin(yaw), np.cos(yaw)]]).T  # rotated by -37 deg
    rot = heading_rotation(est, ref)
    np.testing.assert_allclose(est @ rot.T, ref, atol=1e-12)


def test_stride_errors_are_zero_for_the_reference_itself_and_refuse_no_strides():
    t = np.arange(500) / 100.0
    ref = np.column_stack([t, 0.1 * np.sin(t), 0.05 * np.abs(np.sin(3 * t))])
    st = np.array([[0, 100], [100, 220], [220, 400]])
    r = stride_errors(ref, ref, t, st)
    assert r["count"] == 3 and max(r["mean_abs_cm"].values()) < 1e-9 and r["length_error_cm"] < 1e-9
    with pytest.raises(ValueError, match="no strides"):
        stride_errors(ref, ref, t, np.zeros((0, 2), dtype=int))


@pytest.mark.parametrize("foot", ["left", "right"])
def test_gaitmap_zupt_per_stride(shared_data, foot):
    """ZUPT per stride against the mean of the foot's three markers: the figures docs/gait.md publishes."""
    root = shared_data / "gaitmap_foot"
    imu = pd.read_csv(root / "imu_sample.csv", header=[0, 1], index_col=0)[f"{foot}_sensor"]
    mocap = pd.read_csv(root / "mocap_sample.csv", header=[0, 1], index_col=0)
    acc = imu[["acc_x", "acc_y", "acc_z"]].to_numpy(float)
    gyr = np.radians(imu[["gyr_x", "gyr_y", "gyr_z"]].to_numpy(float))
    t = np.arange(len(acc)) / RATE_IMU
    est = estimate_orientation(gyr, acc, RATE_IMU)
    acc_g = gravity_free_acceleration(est.quat, acc, est.static)
    k = int(round(0.05 * RATE_IMU))
    static = np.convolve(np.linalg.norm(gyr, axis=1) < 0.6, np.ones(k) / k, mode="same") > 0.999
    _, pos = zupt(acc_g, t, static, ZuptParams())
    side = foot[0].upper()
    markers = np.mean([mocap[f"{side}_{m}"][["x", "y", "z"]].to_numpy(float) for m in ("FCC", "TOE", "FM5")], axis=0)
    t_m = np.arange(len(markers)) / RATE_MOCAP
    ref = np.column_stack([np.interp(t, t_m, markers[:, j] / 1000.0) for j in range(3)])
    r = stride_errors(pos, ref, t, strides_from_rests(static, RATE_IMU))
    print(f"\n{foot}: {r['count']} strides, MAE x/y/z " + "/".join(f"{r['mean_abs_cm'][a]:.2f}" for a in "xyz"))
    assert r["count"] >= 28  # the sample holds about 30 strides per foot
    assert 1.0 < r["stride_time_s"] < 1.3
    assert max(r["mean_abs_cm"].values()) < 4.0
    assert r["length_error_cm"] < 6.0


def test_walking_period_finds_the_stride_and_not_a_drinking_task(shared_data):
    from imulog.process.gait import walking_period
    from imulog.simulate import simulate
    from imulog.steps.common import mean_rate_hz

    imu = pd.read_csv(shared_data / "gaitmap_foot" / "imu_sample.csv", header=[0, 1], index_col=0)["left_sensor"]
    period, strength = walking_period(np.radians(imu[["gyr_x", "gyr_y", "gyr_z"]].to_numpy(float)), RATE_IMU)
    assert 1.0 < period < 1.3 and strength > 0.5
    drink = simulate("r2g", seed=0).recording.imus[0]
    assert walking_period(drink.gyr, mean_rate_hz(drink.t_ns))[1] < 0.5


def test_lever_arm_of_a_point_on_a_turning_body():
    from imulog.process import quaternion as Q
    from imulog.process.gait import lever_arm

    rate, n = 100.0, 3000
    t = np.arange(n) / rate
    q = Q.from_rotation_vector(np.column_stack([0.6 * np.sin(2.1 * t), 0.4 * np.sin(1.3 * t + 1), 0.3 * np.sin(t)]))
    origin = np.column_stack([0.3 * np.sin(0.9 * t), 0.2 * np.cos(1.7 * t), 0.05 * np.sin(3 * t)])
    r_true = np.array([0.12, -0.03, 0.05])
    p = origin + Q.rotate(q, np.tile(r_true, (n, 1)))
    a = np.gradient(np.gradient(p, 1 / rate, axis=0), 1 / rate, axis=0) + [0, 0, 9.80665]
    r, _ = lever_arm(Q.rotate_inverse(q, a), q, origin, q, rate)  # sensor axes on the body's
    np.testing.assert_allclose(r, r_true, atol=2e-3)


def test_evaluate_walks_per_stride_by_default(shared_data, tmp_path):
    """The real gaitmap trial: `imulog process align` then `imulog evaluate` with no options find the walking
    by the gyroscope, each foot's own cluster, and give the per-stride errors docs/gait.md publishes."""
    from click.testing import CliRunner

    from imulog.archive import TrialReader
    from imulog.cli import cli

    root = shared_data / "gaitmap_foot"
    path = tmp_path / "gait.mcap"
    run = CliRunner()
    assert (
        run.invoke(
            cli, ["convert", str(root / "imu_sample.csv"), str(root / "mocap_sample.csv"), "-o", str(path)]
        ).exit_code
        == 0
    )
    assert run.invoke(cli, ["process", "align", str(path), "--no-resample"]).exit_code == 0
    res = run.invoke(cli, ["evaluate", str(path)])
    assert res.exit_code == 0, res.output
    assert "walking (gyroscope period" in res.output
    with TrialReader(path) as trial:
        rec = trial.metadata["imulog.evaluation"]
    assert rec["kind"] == "strides" and set(rec["feet"]) == {"left_sensor", "right_sensor"}
    for foot, r in rec["feet"].items():
        side = foot[0].upper()
        assert all(m.startswith(f"{side}_") for m in r["markers"])
        m = r["mean_abs_cm"]
        print(
            f"\n{foot}: {r['count']} strides, x/y/z {m['x']:.2f}/{m['y']:.2f}/{m['z']:.2f} cm, "
            f"length {r['length_error_cm']:.2f} cm, lever arm {r['lever_arm_m']} m"
        )
        assert r["count"] >= 28 and 1.0 < r["stride_time_s"] < 1.3
        assert max(m.values()) <= 3.0  # issue 27: at most 3 cm per axis, mean over strides, on both feet
        assert r["length_error_cm"] < 6.0
