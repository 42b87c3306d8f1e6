"""Minimum-jerk reference trajectories (Flash & Hogan 1985) for the R2G drinking task.

A point-to-point minimum-jerk movement from ``p0`` to ``p1`` over ``[t0, t1]`` is the 5th-order
polynomial ``p0 + (p1 - p0) (10 tau^3 - 15 tau^4 + 6 tau^5)`` with ``tau = (t - t0) / (t1 - t0)``.

The R2G thesis (3.3.7) builds a reference for each repetition from three measurements and the phase
boundaries: the hand rests at the start, reaches the bottle (phase 1, ``reach``), lifts it to the
mouth (phase 2, ``lift``), returns the bottle (phase 3, ``return_bottle``) and the hand (phase 4,
``return_hand``), holding still between phases. Waypoints, relative to the hand's start position, in
the task frame (x forward towards the bottle, y lateral, z up):

* bottle: ``(h1, h2_bottle, z_grasp)`` with h1 the hand-to-bottle distance;
* mouth: ``(h1 * mouth_x_fraction, h2, h3)`` with h2 the sternum/shoulder offset in y and h3 the mouth
  height above the table.

The thesis took h1..h3 as per-subject means of the Vicon displacement; here they come from the
``imulog.anthropometrics`` record (see :func:`r2g_waypoints_from_anthropometrics`) or are measured
from a reference trajectory with :func:`r2g_waypoints_from_positions`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

R2G_PHASES = ("reach", "lift", "return_bottle", "return_hand")


def minimum_jerk_profile(tau: np.ndarray) -> np.ndarray:
    """Normalised minimum-jerk position profile s(tau) in [0, 1] for tau clipped to [0, 1]."""
    x = np.clip(np.asarray(tau, dtype=np.float64), 0.0, 1.0)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x**2)


def minimum_jerk(t_s: np.ndarray, t0_s: float, t1_s: float, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """Minimum-jerk movement from ``p0`` to ``p1`` (any units, shape (D,)) over [t0, t1] s; (N, D)."""
    if t1_s <= t0_s:
        raise ValueError("t1_s must be after t0_s")
    s = minimum_jerk_profile((np.asarray(t_s, dtype=np.float64) - t0_s) / (t1_s - t0_s))
    p0 = np.atleast_1d(np.asarray(p0, dtype=np.float64))
    p1 = np.atleast_1d(np.asarray(p1, dtype=np.float64))
    return p0[None, :] + s[:, None] * (p1 - p0)[None, :]


def piecewise_minimum_jerk(t_s: np.ndarray, bounds_s: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    """Hold-move-hold reference: segment k moves ``waypoints[k] -> waypoints[k+1]`` over ``bounds_s[k]``.

    bounds_s: (K, 2) start/end times in s, sorted and non-overlapping; waypoints: (K + 1, D).
    Before the first segment the reference is ``waypoints[0]``, after the last ``waypoints[K]``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    b = np.asarray(bounds_s, dtype=np.float64).reshape(-1, 2)
    w = np.asarray(waypoints, dtype=np.float64)
    if w.ndim == 1:
        w = w[:, None]
    if len(w) != len(b) + 1:
        raise ValueError(f"need {len(b) + 1} waypoints for {len(b)} segments, got {len(w)}")
    out = np.repeat(w[:1], len(t), axis=0)
    for k, (t0, t1) in enumerate(b):
        s = minimum_jerk_profile((t - t0) / max(t1 - t0, 1e-9))
        out = np.where((t >= t0)[:, None], w[k][None, :] + s[:, None] * (w[k + 1] - w[k])[None, :], out)
    return out


@dataclass(frozen=True)
class R2GWaypoints:
    """Bottle and mouth positions (m) relative to the hand's start, in the world frame; ``end_m`` where the hand
    comes back to (relative to its start; 0, the start, unless a repetition's own offsets are known);
    ``bottle_back_m`` where the bottle is put back (None: where it was grasped, ``bottle_m``)."""

    bottle_m: tuple[float, float, float]
    mouth_m: tuple[float, float, float]
    end_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bottle_back_m: tuple[float, float, float] | None = None

    def as_array(self) -> np.ndarray:
        """The five waypoints of one repetition: start, bottle, mouth, bottle (put back), end; (5, 3) m."""
        b = np.asarray(self.bottle_m, dtype=np.float64)
        m = np.asarray(self.mouth_m, dtype=np.float64)
        back = b if self.bottle_back_m is None else np.asarray(self.bottle_back_m, dtype=np.float64)
        return np.stack([np.zeros(3), b, m, back, np.asarray(self.end_m, dtype=np.float64)])


@dataclass(frozen=True)
class R2GReferenceParams:
    """How h1/h2/h3 map onto waypoints (task frame: x forward, y lateral, z up).

    mouth_x_fraction: mouth x as a fraction of h1 (dimensionless), the thesis: x "decreases after
        phase 2" without a value; 0.3 by default.
    bottle_y_fraction: bottle y as a fraction of h2 (the thesis: y "after phase 1 up to phase 4 stays
        around h2", so 1.0).
    grasp_height_m: hand height change at the bottle (m), the thesis's "slight variation", 0.
    heading_rad: rotation about world z from the task frame to the world frame (rad).
    keys: anthropometrics keys tried, in order, for h1, h2 and h3 (values in m).
    """

    mouth_x_fraction: float = 0.3
    bottle_y_fraction: float = 1.0
    grasp_height_m: float = 0.0
    heading_rad: float = 0.0
    keys: Mapping[str, tuple[str, ...]] = field(
        default_factory=lambda: {
            "h1": ("h1_m", "h1", "hand_to_bottle_m", "bottle_distance_m"),
            "h2": ("h2_m", "h2", "sternum_offset_m", "sternum_to_shoulder_m", "shoulder_offset_m"),
            "h3": ("h3_m", "h3", "mouth_height_m", "mouth_height_above_table_m"),
        }
    )


def _lookup(anthro: Mapping[str, Any], names: tuple[str, ...], what: str) -> float:
    for name in names:
        if name in anthro and anthro[name] is not None:
            value = float(anthro[name])
            return value / 100.0 if name.endswith("_cm") else value
    raise KeyError(f"imulog.anthropometrics has no {what} (tried {', '.join(names)})")


def r2g_waypoints(
    h1_m: float, h2_m: float, h3_m: float, params: R2GReferenceParams = R2GReferenceParams()
) -> R2GWaypoints:
    """Waypoints from the thesis's three measurements (m), rotated by ``params.heading_rad`` into the world."""
    bottle = np.array([h1_m, params.bottle_y_fraction * h2_m, params.grasp_height_m])
    mouth = np.array([params.mouth_x_fraction * h1_m, h2_m, h3_m])
    c, s = np.cos(params.heading_rad), np.sin(params.heading_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    b, m = rot @ bottle, rot @ mouth
    return R2GWaypoints(bottle_m=tuple(b.tolist()), mouth_m=tuple(m.tolist()))


def r2g_waypoints_from_anthropometrics(
    anthro: Mapping[str, Any], params: R2GReferenceParams = R2GReferenceParams()
) -> R2GWaypoints:
    """Waypoints from an ``imulog.anthropometrics`` record.

    Explicit waypoint keys win: ``bottle_m`` and ``mouth_m`` ([x, y, z] m relative to the start).
    Otherwise h1, h2, h3 are looked up under the names in ``params.keys``.
    """
    if "bottle_m" in anthro and "mouth_m" in anthro:
        return R2GWaypoints(
            bottle_m=tuple(float(v) for v in anthro["bottle_m"]), mouth_m=tuple(float(v) for v in anthro["mouth_m"])
        )
    h = {k: _lookup(anthro, tuple(params.keys[k]), k) for k in ("h1", "h2", "h3")}
    return r2g_waypoints(h["h1"], h["h2"], h["h3"], params)


def r2g_waypoints_from_positions(pos_m: np.ndarray, t_s: np.ndarray, phase_bounds_s: np.ndarray) -> R2GWaypoints:
    """Measure waypoints from a trajectory (the thesis's way: displacement from the start at phase ends).

    pos_m: (N, 3); phase_bounds_s: (4, 2) reach/lift/return_bottle/return_hand start and end (s).
    The bottle is the mean of the positions after reach and after return_bottle.
    """
    p = np.asarray(pos_m, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    b = np.asarray(phase_bounds_s, dtype=np.float64)

    def at(time: float) -> np.ndarray:
        return np.array([np.interp(time, t, p[:, j]) for j in range(3)])

    start = at(b[0, 0])
    bottle = 0.5 * (at(b[0, 1]) + at(b[2, 1])) - start
    mouth = at(b[1, 1]) - start
    return R2GWaypoints(bottle_m=tuple(bottle.tolist()), mouth_m=tuple(mouth.tolist()))


def r2g_reference(t_s: np.ndarray, phase_bounds_s: np.ndarray, waypoints: R2GWaypoints) -> np.ndarray:
    """Reference position (N, 3) m relative to the start for one repetition with (4, 2) phase bounds in s."""
    b = np.asarray(phase_bounds_s, dtype=np.float64).reshape(-1, 2)
    if len(b) != 4:
        raise ValueError(f"an R2G repetition has 4 phases, got {len(b)}")
    return piecewise_minimum_jerk(t_s, b, waypoints.as_array())
