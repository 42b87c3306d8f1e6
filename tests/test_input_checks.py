"""Anthropometric inputs against the IMU's own waypoint estimates (imulog.process.input_checks)."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process.input_checks import (
    InputCheckParams,
    SideCheck,
    apply_checks,
    side_checks,
    value_status,
    waypoint_checks,
)
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


def test_explicit_waypoints_are_checked_per_coordinate_and_replace_h_values():
    """Explicit bottle_m / mouth_m are what the reference uses: their six coordinates are checked (the h-values
    beside them are not); an approximate one that disagrees is replaced coordinate by coordinate."""
    bottles, mouths = repetitions([0.38, 0.05, 0.0], [0.09, 0.15, 0.35], spread_m=0.005)  # the bottle moved
    anthro = {"bottle_m": [0.30, 0.15, 0.0], "mouth_m": [0.09, 0.15, 0.35], "h1_m": 0.0, "h2_m": 0.0, "h3_m": 0.0}
    checks = waypoint_checks(anthro, bottles, mouths, KEYS)
    assert [c.label for c in checks] == [f"{k}[{a}]" for k in ("bottle_m", "mouth_m") for a in range(3)]
    assert [c.label for c in checks if c.disagrees] == ["bottle_m[0]", "bottle_m[1]"]
    line = checks[0].line()
    assert line.startswith("bottle_m[0] = 30.0 cm, but the IMU puts the bottle's x at 38.")
    assert "kept as measured" in line and "anthropometrics.bottle_m_status=approximate" in line
    assert not any(c.replaced for c in checks)
    approx = {**anthro, "bottle_m_status": "approximate"}
    checks = waypoint_checks(approx, bottles, mouths, KEYS)
    assert [c.label for c in checks if c.replaced] == ["bottle_m[0]", "bottle_m[1]"]
    bottle, mouth = apply_checks(np.array(anthro["bottle_m"]), np.array(anthro["mouth_m"]), checks)
    assert bottle[:2] == pytest.approx([0.38, 0.05], abs=0.005) and bottle[2] == 0.0  # z agreed: kept
    assert mouth.tolist() == anthro["mouth_m"]
    # one explicit waypoint alone is not what the reference uses (it needs both): the h-values are checked
    alone = waypoint_checks({"bottle_m": [0.3, 0.15, 0.0], "h1_m": 0.30}, bottles, mouths, KEYS)
    assert [c.name for c in alone] == ["h1_m"] and alone[0].disagrees


def test_the_placement_side_is_checked_against_the_mouths_lateral_direction():
    """Towards the midline is +y for a right hand, -y for a left one: a left hand labelled right is one line
    naming the placement and what the IMU saw, and h2's sign is checked against the side too."""
    _, left_mouths = repetitions([0.30, -0.15, 0.0], [0.09, -0.15, 0.35])
    (imu, h2) = side_checks("right", "imulog.trial side", left_mouths, ("h2_m", -0.15))
    assert imu.disagrees and imu.seen == "left" and imu.value_m == pytest.approx(-0.15, abs=0.01)
    line = imu.line()
    assert line.startswith("placement side = right (imulog.trial side), but the IMU puts the mouth's y at -1")
    assert "a left hand's drink" in line and "placement is kept" in line and "\n" not in line
    assert h2.disagrees and h2.line().startswith("h2_m = -15.0 cm puts the mouth on a left hand's side")
    assert imu.as_dict()["seen"] == "left" and imu.as_dict()["replaced"] is False
    # labelled left, the same trial is consistent; a right-labelled right hand too
    assert not any(c.disagrees for c in side_checks("left", "name", left_mouths, ("h2_m", -0.15)))
    _, right_mouths = repetitions([0.30, 0.15, 0.0], [0.09, 0.15, 0.35])
    assert not any(c.disagrees for c in side_checks("Right", "name", right_mouths, ("h2_m", 0.15)))
    # a right-labelled hand with a positive h2 whose IMU disagrees: only the IMU's line
    assert [c.name for c in side_checks("right", "x", left_mouths, ("h2_m", 0.15)) if c.disagrees] == ["placement_side"]
    with pytest.raises(ValueError, match="left or right"):
        side_checks("both", "x", right_mouths)


def test_every_check_record_says_what_its_check_did():
    """Both kinds of check write records of one shape (the run record's ``input_checks``): the keys in a fixed
    order, ending with ``disagrees`` and ``replaced``, each what the check itself says. A side check only warns,
    so its ``replaced`` is always False and is not a field anyone can set to something else."""
    bottles, mouths = repetitions([0.30, 0.15, 0.0], [0.09, 0.15, 0.35])
    (h1, *_) = waypoint_checks({"h1_m": 0.40, "h2_m": 0.15, "status": "approximate"}, bottles, mouths, KEYS)
    assert h1.replaced and h1.as_dict()["axis"] == "x"
    assert list(h1.as_dict()) == [
        "name", "waypoint", "axis", "given_m", "estimated_m", "uncertainty_m", "threshold_m", "status",
        "disagrees", "replaced",
    ]  # fmt: skip
    sides = side_checks("left", "imulog.trial side", mouths, ("h2_m", 0.15))
    assert [c.disagrees for c in sides] == [True, True]
    for check in [h1, *sides]:
        record = check.as_dict()
        assert (record["disagrees"], record["replaced"]) == (check.disagrees, check.replaced)
    assert list(sides[0].as_dict()) == [
        "name", "side", "source", "value_m", "uncertainty_m", "threshold_m", "seen", "repetitions",
        "disagrees", "replaced",
    ]  # fmt: skip
    assert not any(c.replaced for c in sides)
    with pytest.raises(TypeError):
        SideCheck("h2_m", "left", "x", 0.15, replaced=True)  # type: ignore[call-arg]


def test_a_mouth_near_the_start_does_not_contradict_the_side():
    """Within the estimate's threshold of the start the IMU cannot tell the side: undecided, no warning."""
    params = InputCheckParams()
    _, mouths = repetitions([0.30, 0.0, 0.0], [0.09, -0.03, 0.35])  # 3 cm to the right: inside 5 cm
    (imu,) = side_checks("right", "x", mouths, params=params)
    assert imu.seen == "undecided" and not imu.disagrees and imu.threshold_m >= params.min_disagreement_m
    spread = np.zeros((5, 3))
    spread[:, 1] = [-0.35, -0.25, -0.09, 0.05, 0.15]  # 9 cm to the right in the median, repetitions far apart
    (imu,) = side_checks("right", "x", spread, params=params)
    assert imu.value_m == pytest.approx(-0.09) and imu.threshold_m > 0.09 and not imu.disagrees
    spread[:, 1] = [-0.10, -0.095, -0.09, -0.085, -0.08]  # the same median, repetitions that agree
    (imu,) = side_checks("right", "x", spread, params=params)
    assert imu.threshold_m == params.min_disagreement_m and imu.disagrees and imu.seen == "left"


# --- on simulated trials: the simulator's true repetitions, as trial_waypoints takes them -------------------


@pytest.fixture(scope="module")
def moved_trials():
    """Trial 4 of subject 3 as set up (``base``), with the bottle 8 cm further and 10 cm to the right
    (``moved``), and drunk towards -y like a left hand (``left``: mouth and bottle 40 cm to the right; the
    simulator still labels it right)."""
    from imulog.simulate import simulate

    kw = dict(subject=3, seed=4, repetitions=4, noise_free=True)
    return {
        "base": simulate("r2g", **kw),
        "moved": simulate("r2g", bottle_offset_m=(0.08, -0.10), **kw),
        "left": simulate("r2g", bottle_offset_m=(0.0, -0.40), mouth_offset_m=(0.0, -0.40, 0.0), **kw),
    }


def _waypoints_and_checks(sim, anthro, side=None):
    from truth_repetitions import true_repetitions

    from imulog.process.trajectory_opt import trial_waypoints

    t, rel, _, reps = true_repetitions(sim)
    checks: list = []
    return trial_waypoints(anthro, t, rel, reps, checks=checks, side=side), checks


def test_stale_explicit_waypoints_on_a_moved_bottle(moved_trials):
    """The bottle moved 8 cm forward and 10 cm right, the explicit bottle_m not: the two coordinates are named;
    marked approximate they are replaced by the IMU's (here the truth's) estimate, z and the mouth kept."""
    before, _ = _waypoints_and_checks(moved_trials["base"], None)  # the unmoved bottle where the hand went
    moved = moved_trials["moved"]
    anth = moved.recording.metadata["imulog.anthropometrics"]
    stale = {"bottle_m": list(before.bottle_m), "mouth_m": [anth["mouth_dx_m"], anth["h2_m"], anth["h3_m"]]}
    wp, checks = _waypoints_and_checks(moved, stale)
    assert [c.label for c in checks if c.disagrees] == ["bottle_m[0]", "bottle_m[1]"]
    assert wp.bottle_m == pytest.approx(tuple(stale["bottle_m"]))  # measured: kept
    wp, checks = _waypoints_and_checks(moved, {**stale, "bottle_m_status": "approximate"})
    assert [c.label for c in checks if c.replaced] == ["bottle_m[0]", "bottle_m[1]"]
    assert wp.bottle_m[0] == pytest.approx(anth["h1_m"], abs=0.015)  # the moved bottle, within the jitter
    assert wp.bottle_m[1] == pytest.approx(anth["bottle_dy_m"], abs=0.015)
    assert wp.bottle_m[2] == stale["bottle_m"][2] and wp.mouth_m == pytest.approx(tuple(stale["mouth_m"]))


def test_a_left_hand_labelled_right(moved_trials):
    """The IMU drinks towards -y (a left hand) under a right label: the IMU's line and h2's sign are named;
    labelled left, or the right hand labelled right, nothing is said."""
    from imulog.steps.placements import placement_side

    left = moved_trials["left"]
    meta = left.recording.metadata
    anth = meta["imulog.anthropometrics"]
    assert anth["h2_m"] < -0.1 and meta["imulog.trial"]["side"] == "right"
    side = placement_side("wrist", meta)
    assert side == ("right", "imulog.trial side")
    _, checks = _waypoints_and_checks(left, anth, side)
    lines = [c.line() for c in checks if c.disagrees]
    assert len(lines) == 2 and lines[0].startswith("placement side = right (imulog.trial side), but the IMU puts")
    assert "a left hand's drink" in lines[0] and lines[1].startswith(f"h2_m = {anth['h2_m'] * 100:.1f} cm")
    (rec,) = [c.as_dict() for c in checks if c.name == "placement_side"]
    assert rec["seen"] == "left" and rec["value_m"] == pytest.approx(anth["h2_m"], abs=0.015)
    relabelled = {**meta, f"imulog.device.{left.recording.imus[0].name}": {"placement": "Left wrist"}}
    side = placement_side(left.recording.imus[0].name, relabelled)
    assert side[0] == "left" and "placement 'Left wrist'" in side[1]
    _, checks = _waypoints_and_checks(left, anth, side)
    assert not any(c.disagrees for c in checks) and len(checks) > 2
    base = moved_trials["base"]
    _, checks = _waypoints_and_checks(base, base.recording.metadata["imulog.anthropometrics"], ("right", "x"))
    assert not any(c.disagrees for c in checks) and {"placement_side", "h2_m"} <= {c.name for c in checks}
