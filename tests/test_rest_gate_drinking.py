"""Issue 32's last criterion: on the simulated drinking trials the accelerometer's rest gate makes no trajectory
method worse, repetition by repetition (the paired comparison of ``benchmarks/rest_gate_paired.py``).

Subject 1 of the ``stroke`` condition holds the repetition that was worse with the gate (repetition 1: the
phases step marked a 0.8 s translation at up to 23 cm/s as static; its wrong reset cancelled drift by chance,
and the gate refused it). The phases step now keeps a cruising hand out of the static mask, so the gate and the
mask agree there; with a mask from the angular rate alone the gate removes most false rests."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

METHODS = ("zupt", "kalman", "zupt_bias", "optimized")


@pytest.mark.parametrize("condition", ["stroke", "pauses"])
def test_the_gate_makes_no_method_worse_on_drinking_trials(condition):
    from rest_gate_paired import paired_errors

    pairs = paired_errors(condition, range(1, 2), 8, METHODS)
    for m, (off, on, keys) in pairs.items():
        assert len(keys) >= 6, (m, keys)
        d = on - off  # MAE per axis (cm), gate on - gate off, per repetition
        assert np.all(d.mean(axis=0) <= 1e-3), (condition, m, d.mean(axis=0))
        worse = [keys[i] for i in np.flatnonzero(d.sum(axis=1) > 0.05)]
        assert not worse, (condition, m, worse, d)


def test_with_a_still_gyroscope_mask_the_gate_removes_false_rests_and_helps_zupt():
    """The angular rate alone calls every gyroscope-still translation a rest: the gate must make ZUPT better on
    average on each axis (it removes those resets), not just leave it alone."""
    from rest_gate_paired import paired_errors

    off, on, keys = paired_errors("stroke", range(2, 4), 8, ("zupt",), static="gyro-norm")["zupt"]
    assert len(keys) >= 12
    assert np.all(on.mean(axis=0) < off.mean(axis=0)), (off.mean(axis=0), on.mean(axis=0))
