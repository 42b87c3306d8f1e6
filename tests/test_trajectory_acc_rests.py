"""The accelerometer's bias from the trial's own rests in the trajectory pipeline (issue 31 point 2, ninth round)."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from imulog.process.trajectory_opt import DEFAULT_PARAMS


def _estimate_on(overrides: dict, acc_rests) -> tuple[dict, np.ndarray, np.ndarray]:
    """(the run's calibration record, ZUPT's MAE x/y/z cm, the device's true bias m/s^2) of a simulated trial
    (subject and seed 5, 6 repetitions) with ``acc_rests`` (None: off)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from trajectory_accuracy import evaluate_trial, simulated_inputs

    from imulog.simulate.core import simulate

    d = DEFAULT_PARAMS
    sim = simulate("r2g", subject=5, seed=5, repetitions=6, **overrides)
    true_bias = np.asarray(sim.truth.info["device_errors"]["acc_bias_mps2"])
    inputs = simulated_inputs(
        5, seed=5, repetitions=6, rests=d.rests, anchor_params=d.anchor, acc_rests=acc_rests, **overrides
    )
    records, _, _ = evaluate_trial(inputs, ("zupt",), d)
    mae = np.mean([[r[a]["mae_cm"] for a in "xyz"] for r in records["zupt"]], axis=0)
    return inputs["acc_rest_calibration"], mae, true_bias


def test_a_bias_is_found_from_the_rests_and_leaves_zupts_vertical():
    """The `uncalibrated` condition's bias class (0.3 m/s^2 per axis) on a sensor with no scale or misalignment
    error: the bias is identifiable from the drinking task's rests, found within a quarter of its size, and the
    corrected accelerometer takes the bias's leak out of ZUPT's vertical (the filter cannot tilt a bias along
    gravity away)."""
    from imulog.simulate.grid import condition

    overrides = {**condition("uncalibrated"), "scale_sd": 0.0, "misalignment_sd_deg": 0.0}
    bias_only = replace(DEFAULT_PARAMS.acc_rests, enabled=True, model="bias", max_bias_sd_mps2=0.05)
    record, mae, true_bias = _estimate_on(overrides, bias_only)
    assert record["applied"], record["reason"]
    assert record["spread_deg"] >= DEFAULT_PARAMS.acc_rests.min_spread_deg
    assert np.linalg.norm(np.asarray(record["bias_mps2"]) - true_bias) < 0.25 * np.linalg.norm(true_bias), record
    _, raw, _ = _estimate_on(overrides, None)
    assert mae[2] < 0.5 * raw[2], (mae, raw)


def test_with_the_sensors_scale_errors_the_matrix_model_knows_its_uncertainty():
    """With the `uncalibrated` condition's 2 % scale and 1 deg misalignment (both sensors) the bias-only model's
    estimate is off by many times its own standard deviation (it absorbs the scale at the drinking task's poses);
    the default model, with a sensitivity matrix, is applied, its bias error is within three of its standard
    deviations, and ZUPT's vertical loses most of the bias's leak."""
    from imulog.simulate.grid import condition

    d = DEFAULT_PARAMS.acc_rests
    record, mae, true_bias = _estimate_on(condition("uncalibrated"), replace(d, enabled=True))
    assert record["applied"], record["reason"]
    assert np.linalg.norm(np.asarray(record["bias_mps2"]) - true_bias) < 3 * np.linalg.norm(record["bias_sd_mps2"])
    _, raw, _ = _estimate_on(condition("uncalibrated"), None)
    assert mae[2] < 0.5 * raw[2], (mae, raw)
    bias_only, _, _ = _estimate_on(condition("uncalibrated"), replace(d, enabled=True, model="bias"))
    error = np.linalg.norm(np.asarray(bias_only["bias_mps2"]) - true_bias)
    assert error > 3 * np.linalg.norm(bias_only["bias_sd_mps2"]), bias_only


def test_a_corrected_start_is_trusted_as_far_as_its_closure_says():
    """``OptimizationParams.corrected_floor_m`` (issue 31 point 2, tenth round): with the accelerometer corrected from
    the trial's own rests (applied), the start's static-position trust may go below the 6-mm floor and its velocity
    trust below ``sigma_data_mps`` (0.02 m/s), both from the closure; the same trial without the calibration keeps
    both floors. With ``RotatingBiasParams.held_out`` the compensation's per-axis weights are shares (0..1)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from trajectory_accuracy import simulated_inputs

    from imulog.process.rests import true_rests
    from imulog.process.trajectory_opt import merge_overlapping, reconstruct_repetitions, repetition_windows

    d = DEFAULT_PARAMS
    params = replace(
        d,
        acc_rests=replace(d.acc_rests, enabled=True),
        rotating_bias=replace(d.rotating_bias, calibration_prior=True, held_out=True),
        optimized=replace(d.optimized, corrected_floor_m=0.002),
    )
    inputs = simulated_inputs(
        5, seed=5, repetitions=6, rests=d.rests, anchor_params=d.anchor, acc_rests=params.acc_rests
    )
    assert inputs["acc_calibration"].applied, inputs["acc_rest_calibration"]
    t = inputs["t_s"]
    static = true_rests(
        inputs["static"], inputs["acc_gate"], (len(t) - 1) / t[-1], d.rests, orientation=inputs["q_gate"]
    )
    reps, _ = merge_overlapping(repetition_windows(t, inputs["phase_bounds"], static))
    infos = {}
    for label, calibration in (("corrected", inputs["acc_calibration"]), ("uncorrected", None)):
        infos[label] = {}
        reconstruct_repetitions(
            t,
            inputs["acc_world"],
            static,
            reps,
            ("optimized",),
            anthropometrics=inputs["anthropometrics"],
            orientation=inputs["q_world"],
            params=params,
            info=infos[label],
            acc_calibration=calibration,
        )
    corrected, uncorrected = infos["corrected"], infos["uncorrected"]
    assert min(uncorrected["sigma_data_static_m"]) >= 0.006 and min(uncorrected["sigma_data_mps"]) >= 0.02
    assert min(corrected["sigma_data_static_m"]) < 0.006, corrected["sigma_data_static_m"]
    assert min(corrected["sigma_data_mps"]) < 0.02, corrected["sigma_data_mps"]
    assert min(corrected["sigma_data_static_m"]) >= 0.002
    weight = np.asarray(corrected["accelerometer_errors"]["axis_weight"])
    assert weight.shape == (3,) and np.all((weight >= 0) & (weight <= 1))
