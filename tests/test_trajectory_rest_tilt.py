"""Each rest's tilt from the accelerometer (issue 31 point 2, ``AnchorParams.rest_tilt = "accelerometer"``, an
option): an offline 6D filter's tilt still converges through a rest next to a fast rotation (by up to 3 deg over a
7-s rest on the simulated `stroke` trial of subject 44), so its mean over the rest is off; the accelerometer at rest
measures gravity's direction itself."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from imulog.process import quaternion as quat
from imulog.process.integration import AnchorParams, rest_anchored_orientation
from imulog.process.trajectory_opt import DEFAULT_PARAMS

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

RATE = 100.0


def _trial():
    """Five 3-s rests and four 1-s movements turning the hand 60 deg about its x axis and back; the filter's tilt
    (about the world's x axis) drifts from 0 to 2 deg through each rest and back to 0 through each movement; the
    accelerometer measures gravity (9.81 m/s^2) in the sensor frame with 0.02 m/s^2 noise."""
    t = np.arange(0.0, 19.0, 1.0 / RATE)
    static = np.ones(len(t), dtype=bool)
    rate_body = np.zeros((len(t), 3))
    tilt_deg = np.zeros(len(t))
    for k in range(4):
        t0 = 3.0 + 4.0 * k
        m = (t >= t0) & (t < t0 + 1.0)
        static[m] = False
        u = (t[m] - t0) / 1.0
        rate_body[m] = (1.0 if k % 2 == 0 else -1.0) * np.radians(np.outer(30.0 * u**2 * (1 - u) ** 2, [60.0, 0, 0]))
        tilt_deg[m] = 2.0 * (1.0 - u)
    for a in np.flatnonzero(np.diff(np.r_[0, static.astype(int)]) == 1):  # each rest: 0 -> 2 deg
        b = a + int(np.argmin(static[a:])) if not static[a:].all() else len(t)
        tilt_deg[a:b] = np.linspace(0.0, 2.0, b - a)
    q = np.empty((len(t), 4))
    q[0] = quat.from_euler_zyx(30.0, 5.0, -3.0)
    for i in range(1, len(t)):
        q[i] = quat.normalize(
            quat.multiply(q[i - 1], quat.from_rotation_vector(0.5 * (rate_body[i] + rate_body[i - 1]) / RATE))
        )
    q_filter = quat.multiply(quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), np.radians(tilt_deg)), q)
    rng = np.random.default_rng(0)
    acc = quat.rotate_inverse(q, np.tile([0.0, 0.0, 9.81], (len(t), 1))) + rng.normal(0.0, 0.02, (len(t), 3))
    return t, q, q_filter, rate_body, static, acc


def test_a_rests_tilt_is_the_accelerometers_not_the_filters_mean():
    t, q_true, q_filter, gyr, static, acc = _trial()
    old = rest_anchored_orientation(q_filter, gyr, t, static, AnchorParams())
    new = rest_anchored_orientation(q_filter, gyr, t, static, AnchorParams(rest_tilt="accelerometer"), acc=acc)
    tilt_old = np.degrees(quat.inclination_error(old, q_true))[static]
    tilt_new = np.degrees(quat.inclination_error(new, q_true))[static]
    assert np.median(tilt_old) > 0.8, np.median(tilt_old)  # the filter's mean over the rest: about 1 deg
    assert np.max(tilt_new) < 0.05, np.max(tilt_new)
    # and the movements between are re-integrated from the gyroscope onto those rests: within 0.05 deg too
    assert np.max(np.degrees(quat.inclination_error(new, q_true))[~static]) < 0.05


def test_the_option_needs_the_accelerometer_and_a_known_name():
    t, _, q_filter, gyr, static, acc = _trial()
    with pytest.raises(ValueError, match="accelerometer"):
        rest_anchored_orientation(q_filter, gyr, t, static, AnchorParams(rest_tilt="accelerometer"))
    with pytest.raises(ValueError, match="rest_tilt"):
        rest_anchored_orientation(q_filter, gyr, t, static, AnchorParams(rest_tilt="gravity"), acc=acc)


def test_stroke_subject_44_gets_within_1_cm():
    """The simulated `stroke` trial of subject and seed 44 (a development trial of issue 31, the one diagnosed):
    with the filter's tilt its repetitions 5 and 6 start 9-11 cm off in y (the optimized trajectory 1.96 / 1.73 /
    0.44 cm x / y / z); with the accelerometer's tilt at the rests x and y are at most 1 cm and z within 0.2 cm."""
    from trajectory_accuracy import evaluate_trial, simulated_inputs

    from imulog.simulate.grid import condition

    mae = {}
    for label, rest_tilt in (("before", "filter"), ("after", "accelerometer")):
        params = replace(DEFAULT_PARAMS, anchor=replace(DEFAULT_PARAMS.anchor, rest_tilt=rest_tilt))
        inputs = simulated_inputs(
            44, seed=44, repetitions=10, rests=params.rests, anchor_params=params.anchor, **condition("stroke")
        )
        records, _, _ = evaluate_trial(inputs, ("optimized",), params)
        mae[label] = np.mean([[r[a]["mae_cm"] for a in "xyz"] for r in records["optimized"]], axis=0)
    assert np.all(mae["before"][:2] > 1.5), mae
    assert np.all(mae["after"][:2] <= 1.0), mae
    assert abs(mae["after"][2] - mae["before"][2]) < 0.2, mae


def test_the_trajectory_step_passes_the_accelerometer_to_the_option(tmp_path):
    """The step rebuilds the accelerometer from its gravity-free input: with the option it runs and its ZUPT
    trajectory differs from the default's (a 4-repetition simulated trial, the step tests' inputs)."""
    from test_trajectory_steps import _write_with_inputs

    from imulog.archive import TrialReader
    from imulog.simulate.core import simulate
    from imulog.steps.trajectory import run_trajectory

    sim = simulate("r2g", subject=2, seed=0, repetitions=4)
    out = {}
    for rest_tilt in ("filter", "accelerometer"):
        path = tmp_path / f"{rest_tilt}.mcap"
        _write_with_inputs(path, sim)
        params = replace(DEFAULT_PARAMS, anchor=replace(DEFAULT_PARAMS.anchor, rest_tilt=rest_tilt))
        assert not run_trajectory(path, methods=["zupt"], params=params).skipped
        with TrialReader(path) as trial:
            out[rest_tilt] = trial.read("/derived/trajectory/zupt").values
    a, b = out["filter"], out["accelerometer"]
    assert a.shape == b.shape and np.isfinite(b).sum() == np.isfinite(a).sum() > 0
    assert np.nanmax(np.abs(a - b)) > 1e-3, np.nanmax(np.abs(a - b))  # m: the rests' tilt moved the trajectory
