"""The drinking task's anthropometric inputs checked against what the IMU itself measures (issue 31, point 4).

The optimised trajectory pulls each repetition towards a minimum-jerk reference through the bottle and the
mouth, placed from ``imulog.anthropometrics`` (``h1_m``, ``h2_m``, ``h3_m``, ``mouth_dx_m``, ``bottle_dy_m``).
A value that does not match where the hand really goes (a table set up differently from the thesis's
convention) pulls every repetition the wrong way. The ZUPT estimate of the same repetitions measures each of
these coordinates independently of the given values, so every given value is compared with the median of the
per-repetition ZUPT waypoints; a disagreement beyond ``max(min_disagreement_m, k_sigma * uncertainty)`` is
reported in one line naming the value.

A value can be marked ``approximate`` (``--meta anthropometrics.h2_m_status=approximate``, or
``anthropometrics.status=approximate`` for all of them); a disagreeing approximate value is replaced by the
IMU's estimate. Unmarked values count as ``measured``: they are kept, and the warning says so. Explicit
``bottle_m`` / ``mouth_m`` waypoints (which the reference then uses instead of h1-h3) are checked coordinate by
coordinate under the same rule (``bottle_m_status`` / ``mouth_m_status``).

The placement's side (which wrist) is checked against the lateral direction of the drink (:func:`side_checks`):
towards the midline is +y for a right hand, -y for a left one, for the IMU's mouth and for the given h2.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

STATUSES = ("measured", "approximate")

# anthropometric value -> (waypoint, task-frame axis) it sets; h2 also sets the bottle's y (bottle_y_fraction x
# h2) unless bottle_dy_m is given, which is checked as a coordinate of its own (a table set up differently moves
# the bottle, not the mouth)
COORDINATES: dict[str, tuple[str, int]] = {
    "h1": ("bottle", 0),
    "bottle_dy": ("bottle", 1),
    "mouth_dx": ("mouth", 0),
    "h2": ("mouth", 1),
    "h3": ("mouth", 2),
}


@dataclass(frozen=True)
class InputCheckParams:
    """When a given value disagrees with the IMU's estimate.

    min_disagreement_m: never flag a difference below this (m); the issue's 5 cm.
    k_sigma: flag beyond this many standard errors of the estimate (dimensionless).
    floor_sigma_m: the estimate's standard error is at least this (m): ZUPT's own error at a waypoint, which
        repetitions do not average out (about 1-2 cm on the simulator's grid, docs/accuracy.md).
    """

    min_disagreement_m: float = 0.05
    k_sigma: float = 3.0
    floor_sigma_m: float = 0.015


DEFAULT_INPUT_CHECKS = InputCheckParams()


class CheckRecord:
    """The record both kinds of check write into the run record (``info["input_checks"]``).

    ``RECORD`` names the keys in order; each holds the attribute of the same name, or the one ``RENAMED`` maps
    it to. Every record ends with ``disagrees`` (the value contradicts the IMU) and ``replaced`` (the IMU's
    estimate was used instead of the given value).
    """

    RECORD: ClassVar[tuple[str, ...]] = ()
    RENAMED: ClassVar[Mapping[str, str]] = {}

    @property
    def disagrees(self) -> bool:
        raise NotImplementedError

    @property
    def replaced(self) -> bool:
        raise NotImplementedError

    def as_dict(self) -> dict[str, Any]:
        """The record: ``RECORD``'s keys, then ``disagrees`` and ``replaced``."""
        return {key: getattr(self, self.RENAMED.get(key, key)) for key in (*self.RECORD, "disagrees", "replaced")}


@dataclass(frozen=True)
class InputCheck(CheckRecord):
    """One given value against the IMU's estimate of the same coordinate (m, task frame)."""

    RECORD = ("name", "waypoint", "axis", "given_m", "estimated_m", "uncertainty_m", "threshold_m", "status")
    RENAMED = {"axis": "axis_name"}

    name: str  # the anthropometrics key as given, e.g. "h2_m"
    waypoint: str  # "bottle" or "mouth"
    axis: int  # 0 x forward, 1 y lateral, 2 z up (task frame)
    given_m: float
    estimated_m: float
    uncertainty_m: float  # standard error of the estimate
    threshold_m: float
    status: str  # "measured" or "approximate"
    repetitions: int
    label: str = ""  # how the line names the value when it is not the key alone

    @property
    def axis_name(self) -> str:
        """``x``, ``y`` or ``z``."""
        return "xyz"[self.axis]

    @property
    def disagrees(self) -> bool:
        return abs(self.given_m - self.estimated_m) > self.threshold_m

    @property
    def replaced(self) -> bool:
        """The IMU's estimate is used instead of the given value."""
        return self.disagrees and self.status == "approximate"

    def line(self) -> str:
        """One line for the terminal: the value, both figures, and what was done."""
        what = (
            "the IMU's estimate is used (the value is marked approximate)"
            if self.replaced
            else f"kept as measured (mark it approximate with --meta anthropometrics.{self.name}_status=approximate "
            "to use the IMU's estimate, or correct it)"
        )
        return (
            f"{self.label or self.name} = {self.given_m * 100:.1f} cm, but the IMU puts the {self.waypoint}'s {self.axis_name} at "
            f"{self.estimated_m * 100:.1f} ± {self.uncertainty_m * 100:.1f} cm over {self.repetitions} repetitions: "
            f"{what}"
        )


def value_status(anthro: Mapping[str, Any], key: str) -> str:
    """``measured`` or ``approximate`` for one anthropometrics key (``<key>_status``, else ``status``)."""
    status = anthro.get(f"{key}_status", anthro.get("status", "measured"))
    status = str(status).strip().lower()
    if status not in STATUSES:
        raise ValueError(f"imulog.anthropometrics: {key}_status must be one of {', '.join(STATUSES)}, not {status!r}")
    return status


def given_value(anthro: Mapping[str, Any], names: tuple[str, ...]) -> tuple[str, float] | None:
    """The first of ``names`` the record gives as a number: ``(name, value in m)`` (``*_cm`` keys converted)."""
    for name in names:
        value = anthro.get(name)
        if value is not None and not isinstance(value, (list, dict, bool)):
            try:
                v = float(value)
            except (TypeError, ValueError):
                continue
            return name, v / 100.0 if name.endswith("_cm") else v
    return None


def robust_standard_error(values: np.ndarray) -> float:
    """Standard error of a median from the median absolute deviation (same units as ``values``)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if len(v) < 2:
        return 0.0
    mad = 1.4826 * float(np.median(np.abs(v - np.median(v))))
    return 1.2533 * mad / np.sqrt(len(v))  # the median's efficiency against the mean: sqrt(pi/2)


def _explicit(anthro: Mapping[str, Any], key: str) -> np.ndarray | None:
    """An explicit ``[x, y, z]`` waypoint (m), or None when the record does not give a usable one."""
    value = anthro.get(key)
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 3:
        return None
    try:
        return np.asarray([float(v) for v in value], dtype=np.float64)
    except (TypeError, ValueError):
        return None


def explicit_waypoints(anthro: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """``(bottle_m, mouth_m)`` when the record gives both explicit waypoints (m), which then replace h1-h3."""
    bottle, mouth = _explicit(anthro, "bottle_m"), _explicit(anthro, "mouth_m")
    return None if bottle is None or mouth is None else (bottle, mouth)


def waypoint_checks(
    anthro: Mapping[str, Any],
    bottles_task_m: np.ndarray,
    mouths_task_m: np.ndarray,
    keys: Mapping[str, tuple[str, ...]],
    params: InputCheckParams = InputCheckParams(),
    bottle_y_fraction: float = 1.0,
) -> list[InputCheck]:
    """Every given coordinate against the per-repetition ZUPT waypoints.

    bottles_task_m, mouths_task_m: (R, 3) waypoints of R complete repetitions, relative to each repetition's
    start, in the task frame (m). keys: anthropometrics names tried for h1/h2/h3
    (:class:`imulog.process.minjerk.R2GReferenceParams.keys`); ``mouth_dx`` and ``bottle_dy`` are read from
    ``mouth_dx_m`` and ``bottle_dy_m``. Values the record does not give are not checked. Without
    ``bottle_dy_m`` the bottle's y is ``bottle_y_fraction`` x h2 and is checked as h2's second coordinate.
    When the record gives both explicit waypoints ``bottle_m`` and ``mouth_m`` (the reference then uses them,
    not h1-h3), their six coordinates are checked instead, named ``bottle_m[0]`` ... ``mouth_m[2]``; the
    waypoint arrays must then be in the frame those are given in.
    """
    waypoints = {"bottle": np.asarray(bottles_task_m, dtype=np.float64), "mouth": np.asarray(mouths_task_m)}
    given: list[tuple[str, float, str, int, str]] = []  # (name, given value m, waypoint, axis, label)
    explicit = explicit_waypoints(anthro)
    if explicit is not None:
        for key, vector in zip(("bottle_m", "mouth_m"), explicit, strict=True):
            given += [(key, float(vector[axis]), key.removesuffix("_m"), axis, f"{key}[{axis}]") for axis in range(3)]
    else:
        names = {**{k: tuple(v) for k, v in keys.items()}, "mouth_dx": ("mouth_dx_m",), "bottle_dy": ("bottle_dy_m",)}
        for what, (waypoint, axis) in COORDINATES.items():
            found = given_value(anthro, names.get(what, ()))
            if found is not None:
                given.append((found[0], found[1], waypoint, axis, ""))
        found = given_value(anthro, names.get("h2", ()))
        if found is not None and given_value(anthro, names["bottle_dy"]) is None:
            label = f"{found[0]} x {bottle_y_fraction:g} (the bottle's y)"
            given.append((found[0], found[1] * bottle_y_fraction, "bottle", 1, label))
    out = []
    for name, given_m, waypoint, axis, label in given:
        estimate = imu_estimate(waypoints[waypoint][:, axis], params)
        if estimate is None:
            continue
        median, sigma, threshold, n = estimate
        out.append(
            InputCheck(
                name=name,
                waypoint=waypoint,
                axis=axis,
                given_m=given_m,
                estimated_m=median,
                uncertainty_m=sigma,
                threshold_m=threshold,
                status=value_status(anthro, name),
                repetitions=n,
                label=label,
            )
        )
    return out


def imu_estimate(values_m: np.ndarray, params: InputCheckParams) -> tuple[float, float, float, int] | None:
    """The IMU's estimate of one coordinate from its per-repetition values (m): ``(median, standard error,
    threshold, repetitions)``, the threshold ``max(min_disagreement_m, k_sigma x standard error)``; None
    without a finite value."""
    values = np.asarray(values_m, dtype=np.float64)
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return None
    sigma = float(np.hypot(robust_standard_error(values), params.floor_sigma_m))
    return float(np.median(values)), sigma, max(params.min_disagreement_m, params.k_sigma * sigma), len(values)


SIDE_SIGN = {"right": 1.0, "left": -1.0}  # the sign of the midline's y from the hand's start (task frame)


@dataclass(frozen=True)
class SideCheck(CheckRecord):
    """The placement's side against the lateral direction of the drink (task frame, y to the subject's left).

    Towards the midline is +y for a right hand and -y for a left one. ``name`` is ``placement_side`` for the
    IMU's mouth y (median over repetitions), or the given key (``h2_m``, ``mouth_m[1]``) whose sign is checked.
    A contradiction is a value on the other side of the start by more than ``threshold_m`` (0 for a given value).
    The check only warns: the placement and the given value are never changed, so ``replaced`` is False.
    """

    RECORD = ("name", "side", "source", "value_m", "uncertainty_m", "threshold_m", "seen", "repetitions")

    name: str
    side: str  # "left" or "right", as the placement metadata says
    source: str  # where the metadata says it, e.g. "imulog.trial side"
    value_m: float  # the mouth's y: the IMU's median, or the given value (m)
    uncertainty_m: float = 0.0  # standard error of the IMU's estimate (m); 0 for a given value
    threshold_m: float = 0.0
    repetitions: int = 0  # 0 for a given value

    @property
    def disagrees(self) -> bool:
        return SIDE_SIGN[self.side] * self.value_m < -self.threshold_m

    @property
    def replaced(self) -> bool:
        """Never: a side check changes neither the placement nor the given value."""
        return False

    @property
    def seen(self) -> str:
        """``left`` / ``right`` as the value points, ``undecided`` within the threshold of the start."""
        if abs(self.value_m) <= self.threshold_m or self.value_m == 0.0:
            return "undecided"
        return "right" if self.value_m > 0 else "left"

    def line(self) -> str:
        """One line for the terminal: the placement, what the value says, and that nothing was changed."""
        if self.repetitions:
            return (
                f"placement side = {self.side} ({self.source}), but the IMU puts the mouth's y at "
                f"{self.value_m * 100:.1f} ± {self.uncertainty_m * 100:.1f} cm over {self.repetitions} repetitions, "
                f"a {self.seen} hand's drink (towards the midline is +y for a right hand, -y for a left one): "
                "the placement is kept; check which wrist the IMU is on"
            )
        return (
            f"{self.name} = {self.value_m * 100:.1f} cm puts the mouth on a {self.seen} hand's side, but the "
            f"placement says {self.side} ({self.source}): kept (h2 is +y for a right hand, -y for a left one)"
        )


def side_checks(
    side: str,
    source: str,
    mouths_task_m: np.ndarray,
    given_mouth_y: tuple[str, float] | None = None,
    params: InputCheckParams = InputCheckParams(),
) -> list[SideCheck]:
    """The placement's side (``left``/``right``, named by ``source``) against the IMU's mouth y (the median of
    the per-repetition ZUPT mouths ``mouths_task_m`` (R, 3), task frame, m, with the threshold of
    :func:`imu_estimate`) and against the sign of ``given_mouth_y`` (``(key, m)``: h2 or the explicit mouth's
    y, what the reference uses), when given."""
    side = str(side).strip().lower()
    if side not in SIDE_SIGN:
        raise ValueError(f"placement side must be left or right, not {side!r}")
    out = []
    estimate = imu_estimate(np.asarray(mouths_task_m, dtype=np.float64).reshape(-1, 3)[:, 1], params)
    if estimate is not None:
        median, sigma, threshold, n = estimate
        out.append(SideCheck("placement_side", side, source, median, sigma, threshold, n))
    if given_mouth_y is not None:
        out.append(SideCheck(given_mouth_y[0], side, source, float(given_mouth_y[1])))
    return out


def apply_checks(
    bottle_task_m: np.ndarray, mouth_task_m: np.ndarray, checks: list[InputCheck]
) -> tuple[np.ndarray, np.ndarray]:
    """The waypoints (task frame, m) with every replaced value's coordinate set to the IMU's estimate (h2's two
    coordinates, the mouth's y and the bottle's, are checked and replaced each on its own)."""
    bottle, mouth = np.array(bottle_task_m, dtype=np.float64), np.array(mouth_task_m, dtype=np.float64)
    for c in checks:
        if c.replaced:
            (bottle if c.waypoint == "bottle" else mouth)[c.axis] = c.estimated_m
    return bottle, mouth
