"""Anthropometric inputs against the IMU's own waypoint estimates (imulog.process.input_checks)."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process.input_checks import InputCheckParams, apply_checks, value_status, waypoint_checks
from imulog.process.minjerk import R2GReferenceParams

KEYS = R2GReferenceParams().keys


def repetitions(bottle, mouth, spread_m=0.01, n=10, seed=0):
    rng = np.random.default_rng(seed)
    return (
        np.asarray(bottle) + spread_m * rng.standard_normal((n, 3)),
        np.asarray(mouth) + spread_m * rng.standard_normal((n, 3)),
    )


def test_values_that_match_the_imu_are_not_flagged():
    bottles, mouths = repetitions([0.30, 0.15, 0.0], [0.09, 0.15, 0.35])
    checks = waypoint_checks({"h1_m": 0.31, "h2_m": 0.16, "h3_m": 0.34}, bottles, mouths, KEYS)
    assert [(c.name, c.waypoint) for c in checks] == [
        ("h1_m", "bottle"), ("h2_m", "mouth"), ("h3_m", "mouth"), ("h2_m", "bottle")
    ]  # fmt: skip
    assert not any(c.disagrees for c in checks)


def test_a_wrong_h2_is_named_with_both_figures():
    bottles, mouths = repetitions([0.30, 0.01, 0.0], [0.09, 0.01, 0.35])  # the table set up in front of the sternum
    anthro = {"h1_m": 0.30, "h2_m": 0.15, "h3_m": 0.35}
    checks = {(c.name, c.waypoint): c for c in waypoint_checks(anthro, bottles, mouths, KEYS)}
    h2 = checks[("h2_m", "mouth")]
    assert h2.disagrees and not h2.replaced and h2.status == "measured"
    assert checks[("h2_m", "bottle")].disagrees  # the bottle's y is placed from h2 too
    assert not checks[("h1_m", "bottle")].disagrees and not checks[("h3_m", "mouth")].disagrees
    line = h2.line()
    assert "h2_m = 15.0 cm" in line and "mouth's y" in line and "kept as measured" in line and "\n" not in line
    assert checks[("h2_m", "bottle")].line().startswith("h2_m x 1 (the bottle's y) = 15.0 cm")


def test_the_threshold_grows_with_the_spread_of_the_repetitions():
    params = InputCheckParams()
    anthro = {"h1_m": 0.30 + 0.07, "h2_m": 0.15, "h3_m": 0.35}  # 7 cm off in x
    tight = {c.name: c for c in waypoint_checks(anthro, *repetitions([0.30, 0.15, 0], [0.09, 0.15, 0.35]), KEYS)}
    loose = {
        c.name: c
        for c in waypoint_checks(anthro, *repetitions([0.30, 0.15, 0], [0.09, 0.15, 0.35], spread_m=0.15, n=6), KEYS)
    }
    assert tight["h1_m"].threshold_m == params.min_disagreement_m and tight["h1_m"].disagrees
    assert loose["h1_m"].threshold_m > 0.07 and not loose["h1_m"].disagrees


def test_an_approximate_value_that_disagrees_is_replaced_by_the_estimate():
    bottles, mouths = repetitions([0.30, 0.15, 0.0], [0.09, 0.02, 0.35], spread_m=0.002)  # only the mouth moved
    anthro = {"h1_m": 0.30, "h2_m": 0.15, "h3_m": 0.35, "h2_m_status": "approximate"}
    checks = waypoint_checks(anthro, bottles, mouths, KEYS)
    (h2,) = [c for c in checks if c.replaced]
    assert (h2.name, h2.waypoint) == ("h2_m", "mouth") and "IMU's estimate is used" in h2.line()
    bottle, mouth = apply_checks(np.array([0.30, 0.15, 0.0]), np.array([0.09, 0.15, 0.35]), checks)
    assert mouth[1] == pytest.approx(h2.estimated_m) and bottle[1] == 0.15
    assert bottle[0] == 0.30 and mouth[2] == 0.35  # the measured, agreeing values stay


def test_status_for_all_values_and_bad_status():
    assert value_status({"status": "approximate"}, "h1_m") == "approximate"
    assert value_status({"status": "approximate", "h1_m_status": "measured"}, "h1_m") == "measured"
    with pytest.raises(ValueError, match="h3_m_status must be one of"):
        value_status({"h3_m_status": "roughly"}, "h3_m")


def test_values_not_given_are_not_checked_and_cm_keys_are_converted():
    bottles, mouths = repetitions([0.30, 0.15, 0.0], [0.09, 0.15, 0.35])
    checks = waypoint_checks({"mouth_height_cm": 35.0}, bottles, mouths, {**KEYS, "h3": ("mouth_height_cm",)})
    assert [(c.name, c.given_m) for c in checks] == [("mouth_height_cm", pytest.approx(0.35))]
