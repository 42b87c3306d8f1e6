"""Step 7's acceleration flank with the rest's level known to the rest window's precision (issue 31 point 1,
thirteenth round, the devices' noise: ``HandParams.flank_rest_level``, ``flanks.flank_zero(rest_samples=)``, an
option)."""

from __future__ import annotations

import numpy as np
import pytest
from hand_options import simulated_phases

from imulog.process.segmentation.flanks import flank_zero
from imulog.process.segmentation.hand import HandParams

OPTION = HandParams(flank_rest_level=True)


def _ramp(t0: float, n: int = 260) -> tuple[np.ndarray, np.ndarray]:
    """Sample numbers and a gravity-free acceleration (m/s^2) rising linearly from rest at sample ``t0``."""
    x = np.arange(n, dtype=float)
    a = np.zeros((n, 3))
    a[:, 0] = np.minimum(0.004 * np.maximum(x - t0, 0.0), 0.3)
    return x, a


def test_a_clean_flank_keeps_its_start_and_a_dip_at_its_foot_no_longer_moves_it_out():
    x, a = _ramp(120.0)
    first = int(np.flatnonzero(a[:, 0] > 0.05)[0])  # where the level (0.05 m/s^2) is crossed
    args = (first, 0.05, 0.15, 69, 34, 5, None)  # level, top, span, back, smoothing as step 7 at 114 Hz
    assert flank_zero(a, *args) == pytest.approx(120.0, abs=0.1)
    assert flank_zero(a, *args, 57) == pytest.approx(flank_zero(a, *args), abs=0.01)  # nothing to change
    bump = 0.03 * np.exp(-0.5 * ((x - 104.0) / 4.0) ** 2)  # a low-passed noise excursion 16 samples before it
    dip, rise = a.copy(), a.copy()
    dip[:, 0] -= bump
    rise[:, 0] += bump
    assert flank_zero(dip, *args) < 115.0  # the dip read as the rest's level: the start 5.6 samples early
    assert abs(flank_zero(dip, *args, 57) - 120.0) < 1.0  # the rest window's level: within a sample
    assert abs(flank_zero(rise, *args, 57) - 120.0) < abs(flank_zero(rise, *args) - 120.0)


def _phases(cond: str, seed: int, subject: int):
    truth, default, options, t = simulated_phases(cond, seed, subject, {"option": OPTION})
    return truth, default, options["option"], t


def _index(phases, repetition: int, label: str) -> int:
    """Index of a phase (detected: ``repetition``; the truth: ``task_index``) by its repetition and label."""
    number = phases.repetition if hasattr(phases, "repetition") else phases.task_index
    return int(np.flatnonzero((number == repetition) & (np.asarray(phases.labels) == label))[0])


def test_at_the_devices_noise_the_rest_level_moves_step_7s_boundaries_toward_the_truth():
    """stroke-device-noise (the median real device's noise), development trials: 111/80's ninth reach started
    0.25 s early by default (the flank's line hinged on a dip of the low-passed noise) and 31/8's fourth
    return_bottle ended 0.12 s late; with the rest's level both are within 0.03 s."""
    truth, default, option, t = _phases("stroke-device-noise", 111, 80)
    i, j = _index(default, 9, "reach"), _index(truth, 9, "reach")
    assert option.start[i] != default.start[i]
    assert t[default.start[i]] - truth.start_ns[j] * 1e-9 < -0.2
    assert abs(t[option.start[i]] - truth.start_ns[j] * 1e-9) < 0.03
    truth, default, option, t = _phases("stroke-device-noise", 31, 8)
    i, j = _index(default, 4, "return_bottle"), _index(truth, 4, "return_bottle")
    assert t[default.end[i] - 1] - truth.end_ns[j] * 1e-9 > 0.1
    assert abs(t[option.end[i] - 1] - truth.end_ns[j] * 1e-9) < 0.03


def test_where_the_flanks_are_clean_the_rest_level_changes_nothing():
    """`default` 0/1 at the simulator's noise: every boundary identical; `device-noise` 0/0 (the default movements
    at the devices' noise): none moves by more than one sample."""
    _, default, option, _ = _phases("default", 0, 1)
    assert np.array_equal(default.start, option.start) and np.array_equal(default.end, option.end)
    _, default, option, _ = _phases("device-noise", 0, 0)
    assert np.abs(default.start - option.start).max() <= 1 and np.abs(default.end - option.end).max() <= 1
