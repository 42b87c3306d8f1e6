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
    ) -> tuple[float, float]:
        """One segment to position ``p1`` and orientation ``q1`` (None: unchanged).

        ``law(t_rel_s) -> (s, ds/dt, d2s/dt2)`` replaces the minimum-jerk time law (it must give
        s = 0 at 0 and s = 1 at ``seconds`` with zero rates there); ``lift`` (m, world) adds the
        bump arc to a minimum-jerk segment."""
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
        for k, law in enumerate(self.law):
            if law is None:
                continue
            sel = np.flatnonzero((idx == k) & ~before)
            if len(sel):
                t_rel = np.clip(t_s[sel] - t0[k], 0.0, dur[k])
                s[sel], ds[sel], dds[sel] = law(t_rel)
                done = sel[t_rel >= dur[k]]  # after the segment: exactly at rest at its end point
                s[done], ds[done], dds[done] = 1.0, 0.0, 0.0
        position = p0[idx] + dp[idx] * s[:, None] + lift_pos
        velocity = dp[idx] * ds[:, None] + lift_vel
        acceleration = dp[idx] * dds[:, None] + lift_acc
        orientation = quat.multiply(q0[idx], quat.from_rotation_vector(rv[idx] * s[:, None]))
        omega = rv[idx] * ds[:, None]
        return Kinematics(t_s, position, velocity, acceleration, orientation, omega, moving)

    @property
    def end_s(self) -> float:
        return self.t
