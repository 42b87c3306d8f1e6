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
IMU's estimate. Unmarked values count as ``measured``: they are kept, and the warning says so.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

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


@dataclass(frozen=True)
class InputCheck:
    """One given value against the IMU's estimate of the same coordinate (m, task frame)."""

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
    def disagrees(self) -> bool:
        return abs(self.given_m - self.estimated_m) > self.threshold_m

    @property
    def replaced(self) -> bool:
        """The IMU's estimate is used instead of the given value."""
        return self.disagrees and self.status == "approximate"

    def line(self) -> str:
        """One line for the terminal: the value, both figures, and what was done."""
        axis = "xyz"[self.axis]
        what = (
            "the IMU's estimate is used (the value is marked approximate)"
            if self.replaced
            else f"kept as measured (mark it approximate with --meta anthropometrics.{self.name}_status=approximate "
            "to use the IMU's estimate, or correct it)"
        )
        return (
            f"{self.label or self.name} = {self.given_m * 100:.1f} cm, but the IMU puts the {self.waypoint}'s {axis} at "
            f"{self.estimated_m * 100:.1f} ± {self.uncertainty_m * 100:.1f} cm over {self.repetitions} repetitions: "
            f"{what}"
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "waypoint": self.waypoint,
            "axis": "xyz"[self.axis],
            "given_m": self.given_m,
            "estimated_m": self.estimated_m,
            "uncertainty_m": self.uncertainty_m,
            "threshold_m": self.threshold_m,
            "status": self.status,
            "disagrees": self.disagrees,
            "replaced": self.replaced,
        }


def value_status(anthro: Mapping[str, Any], key: str) -> str:
    """``measured`` or ``approximate`` for one anthropometrics key (``<key>_status``, else ``status``)."""
    status = anthro.get(f"{key}_status", anthro.get("status", "measured"))
    status = str(status).strip().lower()
    if status not in STATUSES:
        raise ValueError(f"imulog.anthropometrics: {key}_status must be one of {', '.join(STATUSES)}, not {status!r}")
    return status


def _given(anthro: Mapping[str, Any], names: tuple[str, ...]) -> tuple[str, float] | None:
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
    """
    waypoints = {"bottle": np.asarray(bottles_task_m, dtype=np.float64), "mouth": np.asarray(mouths_task_m)}
    names = {**{k: tuple(v) for k, v in keys.items()}, "mouth_dx": ("mouth_dx_m",), "bottle_dy": ("bottle_dy_m",)}
    coordinates: list[tuple[str, str, int, float, str]] = []  # (what, waypoint, axis, factor, label)
    for what, (waypoint, axis) in COORDINATES.items():
        coordinates.append((what, waypoint, axis, 1.0, ""))
    if _given(anthro, names["bottle_dy"]) is None:
        found = _given(anthro, names.get("h2", ()))
        label = f"{found[0]} x {bottle_y_fraction:g} (the bottle's y)" if found else ""
        coordinates.append(("h2", "bottle", 1, bottle_y_fraction, label))
    out = []
    for what, waypoint, axis, factor, label in coordinates:
        found = _given(anthro, names.get(what, ()))
        if found is None:
            continue
        name, given = found
        given *= factor
        values = waypoints[waypoint][:, axis]
        values = values[np.isfinite(values)]
        if len(values) == 0:
            continue
        sigma = float(np.hypot(robust_standard_error(values), params.floor_sigma_m))
        out.append(
            InputCheck(
                name=name,
                waypoint=waypoint,
                axis=axis,
                given_m=given,
                estimated_m=float(np.median(values)),
                uncertainty_m=sigma,
                threshold_m=max(params.min_disagreement_m, params.k_sigma * sigma),
                status=value_status(anthro, name),
                repetitions=len(values),
                label=label,
            )
        )
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
