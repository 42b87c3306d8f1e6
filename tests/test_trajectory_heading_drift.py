"""The optimisation's heading-drift correction (issue 31 point 2): a 6D orientation filter's heading drifts with
a gyroscope bias about the vertical, which turns every later repetition's initial estimate; the correction finds
that drift from the repetitions' static positions against the reference and removes it before optimising."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from truth_repetitions import true_repetitions

from imulog.process.trajectory_opt import DEFAULT_PARAMS, heading_drift, rotate_about_z, trial_waypoints
from imulog.simulate import simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


@pytest.fixture(scope="module")
def true_trial():
    sim = simulate("r2g", subject=3, seed=4, repetitions=8, noise_free=True)
    t, rel, static, reps = true_repetitions(sim)
    wp = trial_waypoints(sim.recording.metadata["imulog.anthropometrics"], t, rel, reps)  # as the pipeline does
    return t, rel, static, reps, wp


def test_a_linear_heading_drift_is_found_and_no_drift_is_left_alone(true_trial):
    """The true trajectory turned by a drift from -25 to +40 deg over the trial: each repetition's angle is
    found within what 1-cm waypoint jitter on a ~30 cm reach allows; the untouched trajectory gets exactly 0."""
    t, rel, static, reps, wp = true_trial
    sigma = DEFAULT_PARAMS.optimized.sigma_ref_static_m
    assert np.all(heading_drift(t, rel, static, reps, wp, sigma) == 0.0)
    mid = np.array([t[r.start : r.stop].mean() for r in reps])
    drift = np.radians(-25.0 + 65.0 * (mid - mid[0]) / (mid[-1] - mid[0]))
    turned = rel.copy()
    for r, a in zip(reps, drift, strict=True):
        turned[r.start : r.stop] = rotate_about_z(rel[r.start : r.stop], -a)
    found = heading_drift(t, turned, static, reps, wp, sigma)
    assert np.degrees(np.max(np.abs(found - drift))) < 4.0, np.degrees(found - drift)
    assert np.corrcoef(found, drift)[0, 1] > 0.99


def test_heading_drift_brings_a_drifting_trial_within_1_cm_of_the_truth():
    """A trial whose 3 deg/s gyroscope bias (0.5 deg/s warm-up drift) turns the 6D heading by tens of degrees
    over the trial (ZUPT 7-8 cm in x and y): before the correction the optimized trajectory misses the issue's
    target (1.35 / 1.01 cm in x / y), with it every axis is at most 1.0 cm and below ZUPT. Subject 6 was one of
    the three development trials of this condition (subjects 3 and 4 improve too but stay just above 1 cm in y
    or z); the held-out figures are in docs/accuracy.md."""
    from trajectory_accuracy import evaluate_trial, simulated_inputs

    # the heading of the filter at every rest (AnchorParams.heading="filter"): with the gyroscope's heading
    # through rests (the default since) this trial's heading hardly drifts and both are within 1 cm
    params = replace(DEFAULT_PARAMS, anchor=replace(DEFAULT_PARAMS.anchor, heading="filter"))
    inputs = simulated_inputs(
        6,
        seed=6,
        repetitions=8,
        rests=params.rests,
        anchor_params=params.anchor,
        gyr_bias_sd_dps=3.0,
        gyr_bias_drift_dps=0.5,
    )
    off = replace(params, optimized=replace(params.optimized, heading_drift=False))
    mae = {}
    for label, p, methods in (("before", off, ("zupt", "optimized")), ("after", params, ("optimized",))):
        records, _, _ = evaluate_trial(inputs, methods, p)
        for m in methods:
            mae["zupt" if m == "zupt" else label] = np.mean([[r[a]["mae_cm"] for a in "xyz"] for r in records[m]], 0)
    assert np.any(mae["before"] > 1.0), mae
    assert np.all(mae["after"] <= 1.0), mae
    assert np.all(mae["after"] < mae["zupt"]), mae
    assert np.all(mae["after"][:2] < mae["before"][:2]), mae
