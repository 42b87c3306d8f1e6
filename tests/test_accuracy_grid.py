"""A fast slice of the accuracy grid (issue 19) with its targets as assertions; the whole grid is in
``benchmarks/segmentation_accuracy.py --grid all`` and ``benchmarks/trajectory_accuracy.py --grid all``
(docs/accuracy.md). Seeds and subjects here were not used while developing the methods (0 and 1 were)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

SEG_CONDITIONS = ["rotation-early", "combined", "pauses", "rate-50hz"]


@pytest.fixture(scope="module")
def segmentation_rows():
    from segmentation_accuracy import GRID_METHODS, grid_rows

    methods = {k: GRID_METHODS[k] for k in ("hand (default)", "gyroscope only")}
    return grid_rows(SEG_CONDITIONS, range(7, 8), range(3, 4), 6, methods)


def test_phase_boundaries_follow_the_hand_over_the_grid_slice(segmentation_rows):
    hand = [r for r in segmentation_rows if r["method"] == "hand (default)"]
    assert len(hand) == len(SEG_CONDITIONS)
    assert np.mean([r["within_0_1_s"] for r in hand]) >= 0.95
    for r in hand:
        assert r["correct"] >= 0.95, r
        assert r["onset_mae_s"] < 0.08 and r["offset_mae_s"] < 0.08, r
        assert r["within_0_1_s"] >= 0.9, r


def test_gyroscope_only_boundaries_end_early_when_the_rotation_ends_first(segmentation_rows):
    """The failure of issue 19 reproduces on the grid: without the accelerometer a phase ends when the wrist
    stops rotating, while the hand still moves."""
    by = {(r["condition"], r["method"]): r for r in segmentation_rows}
    for name in ("rotation-early", "combined"):
        gyro, hand = by[(name, "gyroscope only")], by[(name, "hand (default)")]
        assert gyro["mean_duration_error_s"] < -0.1 and gyro["within_0_1_s"] < 0.5
        assert abs(hand["mean_duration_error_s"]) < 0.05


@pytest.fixture(scope="module")
def trajectory_mae():
    from trajectory_accuracy import grid_rows

    rows = grid_rows(["default", "combined"], range(5, 6), 5)
    return {(r["condition"], r["method"]): np.array(r["mae_cm"]) for r in rows}


@pytest.mark.xfail(
    strict=True,
    reason="issue 31 point 2, the 'below ZUPT' half: with the heading through rests (default since 2026-12-07) "
    "ZUPT itself is at 0.32 cm in x on default subject 5 and the optimized trajectory at 0.37 cm "
    "(docs/accuracy.md); its start zupt_bias is at 0.47 cm and the trust already at its 6-mm floor, so no trust "
    "rule brings it back (benchmarks/trajectory_start.py); strict, so it is reported when it passes again",
)
def test_optimized_trajectory_better_than_zupt(trajectory_mae):
    """The grid target on a slice: the optimized trajectory never worse than ZUPT on any axis."""
    mae = trajectory_mae
    for name in ("default", "combined"):
        assert np.all(mae[(name, "optimized")] <= mae[(name, "zupt")]), mae


def test_the_excess_over_zupt_comes_from_the_start_not_the_trust():
    """Why the test above fails (issue 31 point 2, docs/accuracy.md): on `default` subject 5 the optimisation
    already trusts its start at the 6-mm floor on every axis and its start, ``zupt_bias``, is above ZUPT in x, so
    the optimized x lies between them; no rule for the trust alone can bring it below ZUPT."""
    from trajectory_accuracy import simulated_inputs
    from trajectory_start import FLOOR_M, trial_row

    from imulog.process.trajectory_opt import DEFAULT_PARAMS
    from imulog.simulate.grid import condition

    inputs = simulated_inputs(5, seed=5, repetitions=5, rests=DEFAULT_PARAMS.rests, **condition("default"))
    row = trial_row(inputs)
    m = row["mae"]
    assert np.all(row["sigma_m"] <= FLOOR_M + 1e-9), row
    assert m["zupt_bias"][0] > m["optimized"][0] > m["zupt"][0], m


def test_optimized_trajectory_within_1_cm(trajectory_mae):
    """The grid target on a slice: optimized <= 1.0 cm per axis on average over the conditions. The combined
    condition alone was ~1.1 cm in y (docs/accuracy.md), hence its looser bound."""
    mae = trajectory_mae
    assert np.all(mae[("default", "optimized")] <= 1.0), mae
    assert np.all(mae[("combined", "optimized")] <= 1.3), mae
    mean = (mae[("default", "optimized")] + mae[("combined", "optimized")]) / 2
    assert np.all(mean <= 1.0), mae
