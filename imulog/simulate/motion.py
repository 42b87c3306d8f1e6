"""Piecewise minimum-jerk rigid-body motion, evaluated analytically.

A :class:`MotionPlan` is a chain of non-overlapping segments on the reference clock (seconds).
Each segment moves the sensor origin from ``p0`` to ``p0 + dp`` and turns its orientation from
``q0`` to ``q0 * exp(r)`` (``r`` a rotation vector in the sensor frame), both along one time law
``s(t)`` (0 -> 1): the minimum-jerk polynomial, or an analytic custom law (the slide's constant
acceleration and damped end-stop impact). A segment may add an arc ``lift * b(tau)`` (a
``64 tau^3 (1-tau)^3`` bump, e.g. lifting a peg). Between segments the body is exactly still.
Therefore, at any time,

* position ``p = p0 + dp s + lift b``; velocity ``dp s' + lift b'``; acceleration
  ``dp s'' + lift b''`` (world frame, m, derivatives with respect to time);
* orientation ``q = q0 exp(r s)``; body (sensor-frame) angular velocity ``omega = r s'``
  (exact, because the rotation axis is fixed in the sensor frame during a segment).

Nothing is differentiated numerically, so a noise-free IMU built from these values integrates
back to the positions up to the integration scheme's own error.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from imulog.process import quaternion as quat
from imulog.simulate import minjerk


def skewed_bump(s: np.ndarray, peak: np.ndarray | float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Path bow ``c(s) = s^a (1-s)^b / (p^a (1-p)^b)`` with ``a = 4p``, ``b = 4(1-p)`` (height 1 at path
    fraction ``p`` in [0.3, 0.7]; ``p = 0.5`` is the symmetric ``16 s^2 (1-s)^2``), and ``dc/ds``, ``d2c/ds2``.

    ``c(0) = c(1) = 0``; the path parameter ``s`` itself starts and stops with zero rate, so the bowed path
    keeps zero velocity and acceleration at both ends."""
    s = np.clip(np.asarray(s, dtype=float), 0.0, 1.0)
    p = np.clip(np.broadcast_to(np.asarray(peak, dtype=float), s.shape), 0.3, 0.7)
    a, b = 4.0 * p, 4.0 * (1.0 - p)
    norm = p**a * (1.0 - p) ** b
    u = 1.0 - s
    with np.errstate(divide="ignore", invalid="ignore"):
        c = s**a * u**b / norm
        # d/ds log c = a/s - b/u
        g = np.where((s > 0) & (u > 0), a / np.where(s > 0, s, 1.0) - b / np.where(u > 0, u, 1.0), 0.0)
        dg = np.where((s > 0) & (u > 0), -a / np.where(s > 0, s, 1.0) ** 2 - b / np.where(u > 0, u, 1.0) ** 2, 0.0)
    dc = c * g
    ddc = c * (g**2 + dg)
    return c, dc, ddc


@dataclass(frozen=True)
class SubmovementLaw:
    """Time law ``s(t) = sum_i w_i mj((t - t_i) / T_i)`` of overlapping minimum-jerk submovements: ``onsets_s``
    t_i and ``durations_s`` T_i in seconds from the segment start, ``weights`` w_i summing to 1. Calling it at
    ``t_rel`` (s from the segment start) gives ``(s, ds/dt, d2s/dt2)``; its fields let an analysis rebuild the
    phase (benchmarks/boundary_limit.py)."""

    onsets_s: np.ndarray
    durations_s: np.ndarray
    weights: np.ndarray

    def __call__(self, t_rel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t_rel = np.asarray(t_rel, dtype=float)
        s = np.zeros_like(t_rel)
        ds = np.zeros_like(t_rel)
        dds = np.zeros_like(t_rel)
        for t_i, T_i, w in zip(self.onsets_s, self.durations_s, self.weights, strict=True):
            a, b, c = minjerk.profile((t_rel - t_i) / T_i)
            s += w * a
            ds += w * b / T_i
            dds += w * c / T_i**2
        return s, ds, dds


def submovement_law(
    duration_s: float, onsets: np.ndarray, durations: np.ndarray, weights: np.ndarray
) -> SubmovementLaw:
    """Time law ``s(t) = sum_i w_i mj((t - t_i) / T_i)`` of overlapping minimum-jerk submovements (s).

    ``onsets`` t_i and ``durations`` T_i in seconds from the segment start, each ending by
    ``duration_s``; ``weights`` (normalised to sum 1) are the fractions of the path each covers. Overlapping
    submovements give several velocity peaks (stroke reaching, Rohrer et al. 2002); a gap between two gives a
    pause inside the segment. ``s`` runs 0 -> 1 with zero rate at both ends."""
    onsets = np.asarray(onsets, dtype=float)
    durations = np.asarray(durations, dtype=float)
    weights = np.asarray(weights, dtype=float) / float(np.sum(weights))
    if np.any(onsets < 0) or np.any(onsets + durations > duration_s + 1e-9) or np.any(durations <= 0):
        raise ValueError("submovements must lie inside the segment")
    return SubmovementLaw(onsets, durations, weights)


@dataclass
class Kinematics:
    """Sampled true state. Positions m, velocities m/s, accelerations m/s^2 (world frame);
    ``orientation`` (N, 4) sensor-to-world w,x,y,z; ``omega`` (N, 3) rad/s in the sensor frame;
    ``moving`` (N,) True inside a segment (False where the body is exactly still)."""

    t_s: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    orientation: np.ndarray
    omega: np.ndarray
    moving: np.ndarray


@dataclass
class Interval:
    label: str
    start_s: float
    end_s: float
    task_index: int = -1


@dataclass
class MotionPlan:
    """Builder and evaluator of a chain of minimum-jerk segments starting at pose (p, q) at time t."""

    p: np.ndarray
    q: np.ndarray
    t: float = 0.0
    t0: list[float] = field(default_factory=list)
    duration: list[float] = field(default_factory=list)
    p0: list[np.ndarray] = field(default_factory=list)
    dp: list[np.ndarray] = field(default_factory=list)
    q0: list[np.ndarray] = field(default_factory=list)
    rv: list[np.ndarray] = field(default_factory=list)
    lift: list[np.ndarray] = field(default_factory=list)
    law: list[Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | None] = field(default_factory=list)
    rot_law: list[Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | None] = field(
        default_factory=list
    )
    curve: list[np.ndarray] = field(default_factory=list)
    curve_peak: list[float] = field(default_factory=list)
    intervals: list[Interval] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.p = np.asarray(self.p, dtype=float).copy()
        self.q = quat.normalize(np.asarray(self.q, dtype=float))
        self.start_p = self.p.copy()
        self.start_q = self.q.copy()

    def wait(self, seconds: float) -> None:
        """Stay exactly still for ``seconds``."""
        if seconds < 0:
            raise ValueError("negative wait")
        self.t += float(seconds)

    def move(
        self,
        seconds: float,
        p1: np.ndarray | None = None,
        q1: np.ndarray | None = None,
        *,
        lift: np.ndarray | None = None,
        law: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
        rot_law: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
        curve: np.ndarray | None = None,
        curve_peak: float = 0.5,
    ) -> tuple[float, float]:
        """One segment to position ``p1`` and orientation ``q1`` (None: unchanged).

        ``law(t_rel_s) -> (s, ds/dt, d2s/dt2)`` replaces the minimum-jerk time law (it must give
        s = 0 at 0 and s = 1 at ``seconds`` with zero rates there); ``lift`` (m, world) adds the
        bump arc to a minimum-jerk segment. ``rot_law`` (same contract) gives the rotation its own
        time law (default: the translation's). ``curve`` (m, world) bows the path: the position is
        ``p0 + dp s + curve c(s)`` with ``c`` a bump of height 1 peaking at path fraction
        ``curve_peak`` (0.5 symmetric; see :func:`skewed_bump`)."""
        if seconds <= 0:
            raise ValueError("a movement needs a positive duration")
        p1 = self.p if p1 is None else np.asarray(p1, dtype=float)
        q1 = self.q if q1 is None else quat.normalize(np.asarray(q1, dtype=float))
        rel = quat.multiply(quat.conjugate(self.q), q1)
        rv = quat.to_rotation_vector(rel)
        start = self.t
        self.t0.append(start)
        self.duration.append(float(seconds))
        self.p0.append(self.p.copy())
        self.dp.append(p1 - self.p)
        self.q0.append(self.q.copy())
        self.rv.append(rv)
        self.lift.append(np.zeros(3) if lift is None else np.asarray(lift, dtype=float))
        self.law.append(law)
        self.rot_law.append(rot_law)
        self.curve.append(np.zeros(3) if curve is None else np.asarray(curve, dtype=float))
        self.curve_peak.append(float(curve_peak))
        self.p = p1.copy()
        self.q = quat.multiply(self.q, quat.from_rotation_vector(rv))
        self.t = start + float(seconds)
        return start, self.t

    def rotate(self, seconds: float, rotvec_sensor: np.ndarray) -> tuple[float, float]:
        """Rotate by a sensor-frame rotation vector (rad) in place (no translation)."""
        q1 = quat.multiply(self.q, quat.from_rotation_vector(np.asarray(rotvec_sensor, dtype=float)))
        return self.move(seconds, None, q1)

    def mark(self, label: str, start_s: float, end_s: float, task_index: int = -1) -> None:
        self.intervals.append(Interval(label, float(start_s), float(end_s), int(task_index)))

    # -- evaluation -------------------------------------------------------------------------
    def evaluate(self, t_s: np.ndarray) -> Kinematics:
        """Exact state at times ``t_s`` (seconds, reference clock), vectorised."""
        t_s = np.asarray(t_s, dtype=float)
        n = len(t_s)
        if not self.t0:
            pos = np.tile(self.start_p, (n, 1))
            zeros = np.zeros((n, 3))
            return Kinematics(
                t_s, pos, zeros, zeros.copy(), np.tile(self.start_q, (n, 1)), zeros.copy(), np.zeros(n, bool)
            )
        t0 = np.asarray(self.t0)
        dur = np.asarray(self.duration)
        p0 = np.asarray(self.p0)
        dp = np.asarray(self.dp)
        q0 = np.asarray(self.q0)
        rv = np.asarray(self.rv)
        idx = np.searchsorted(t0, t_s, side="right") - 1
        before = idx < 0
        idx = np.clip(idx, 0, len(t0) - 1)
        tau = (t_s - t0[idx]) / dur[idx]
        tau[before] = 0.0
        moving = (~before) & (tau > 0.0) & (tau < 1.0)
        T = dur[idx]
        s, ds, dds = minjerk.profile(tau)
        ds = ds / T
        dds = dds / T**2
        lift = np.asarray(self.lift)
        b, db, ddb = minjerk.bump(tau)
        lift_pos = lift[idx] * b[:, None]
        lift_vel = lift[idx] * (db / T)[:, None]
        lift_acc = lift[idx] * (ddb / T**2)[:, None]
        sr, dsr = s.copy(), ds.copy()  # rotation's time law (default: the translation's)
        for k, (law, rlaw) in enumerate(zip(self.law, self.rot_law, strict=True)):
            if law is None and rlaw is None:
                continue
            sel = np.flatnonzero((idx == k) & ~before)
            if len(sel):
                t_rel = np.clip(t_s[sel] - t0[k], 0.0, dur[k])
                done = sel[t_rel >= dur[k]]  # after the segment: exactly at rest at its end point
                if law is not None:
                    s[sel], ds[sel], dds[sel] = law(t_rel)
                    s[done], ds[done], dds[done] = 1.0, 0.0, 0.0
                if rlaw is not None:
                    sr[sel], dsr[sel], _ = rlaw(t_rel)
                    sr[done], dsr[done] = 1.0, 0.0
                else:
                    sr[sel], dsr[sel] = s[sel], ds[sel]
        position = p0[idx] + dp[idx] * s[:, None] + lift_pos
        velocity = dp[idx] * ds[:, None] + lift_vel
        acceleration = dp[idx] * dds[:, None] + lift_acc
        curve = np.asarray(self.curve)
        bowed = np.flatnonzero(np.any(curve[idx] != 0.0, axis=1) & ~before)
        if len(bowed):  # path bow: curve c(s), velocity curve c' s', acceleration curve (c'' s'^2 + c' s'')
            peak = np.asarray(self.curve_peak)[idx[bowed]]
            c, dc, ddc = skewed_bump(s[bowed], peak)
            cv = curve[idx[bowed]]
            position[bowed] += cv * c[:, None]
            velocity[bowed] += cv * (dc * ds[bowed])[:, None]
            acceleration[bowed] += cv * (ddc * ds[bowed] ** 2 + dc * dds[bowed])[:, None]
        orientation = quat.multiply(q0[idx], quat.from_rotation_vector(rv[idx] * sr[:, None]))
        omega = rv[idx] * dsr[:, None]
        return Kinematics(t_s, position, velocity, acceleration, orientation, omega, moving)

    @property
    def end_s(self) -> float:
        return self.t
