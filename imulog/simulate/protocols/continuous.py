"""Continuous motion with sparse rests (issue 32): what a hand-moved chain or free arm use looks like.

After the opening (static, wave, static) the sensor moves without a pause for ``duration_s`` except for
``rests`` short rests (``rest_s`` each, evenly spaced): a sum of sinusoids in every axis (translation,
``amplitude_m``) under a smooth envelope that starts and ends each stretch at rest, and a rotation about one
sensor axis whose own envelope goes to zero for ``glide_s`` in ``glides`` places per stretch while the
translation goes on: the gyroscope is exactly still there although the sensor translates (a segmentation
that reads stillness from the angular rate alone takes those for rests). Every stretch between two rests is
a phase ``movement`` (``task_index`` = stretch number); the truth's static mask is True only at the rests.

The motion is exact: positions, velocities and accelerations are analytic (envelope x sinusoid, product
rule), the angular velocity is the rotation angle's derivative about a fixed sensor axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from imulog.process import quaternion as quat
from imulog.simulate import minjerk
from imulog.simulate.motion import Kinematics, MotionPlan
from imulog.simulate.protocols.common import ProtocolResult, opening


@dataclass(frozen=True)
class Params:
    duration_s: float = 60.0  # continuous motion, rests included
    rests: int = 1  # short rests inside the motion (the chain recording: one of 0.3 s)
    rest_s: float = 0.3
    amplitude_m: float = 0.12  # per-axis translation amplitude
    frequency_hz: tuple[float, float] = (0.15, 0.6)  # range of the translation's sinusoids
    components: int = 3  # sinusoids per axis
    rotation_deg: float = 35.0  # amplitude of the rotation about one sensor axis
    rotation_hz: tuple[float, float] = (0.2, 0.5)
    glides: int = 3  # per stretch: intervals where the rotation stops while the translation goes on
    glide_s: float = 1.5
    ramp_s: float = 1.0  # envelope rise and fall (s) at the start and end of each stretch
    opening_static_s: float = 5.0
    wave_cycles: int = 2
    wave_amplitude_deg: float = 30.0
    wave_half_swing_s: float = 0.3
    post_wave_static_s: float = 3.0
    closing_static_s: float = 3.0
    height_m: float = 0.9


def envelope(t: np.ndarray, total_s: float, ramp_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smooth 0 -> 1 -> 0 over [0, total_s] with minimum-jerk ramps of ``ramp_s``: (w, w', w'')."""
    r = min(ramp_s, total_s / 2)
    up, dup, ddup = minjerk.profile(t / r)
    dn, ddn, dddn = minjerk.profile((total_s - t) / r)
    w = up * dn
    dw = dup / r * dn - up * ddn / r
    ddw = ddup / r**2 * dn - 2 * dup / r * ddn / r + up * dddn / r**2
    return w, dw, ddw


def gate(t: np.ndarray, starts: np.ndarray, glide_s: float, ramp_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """1 except in each glide ``[start, start + glide_s]``, where it falls to 0, stays, and rises again
    (minimum-jerk ramps of ``ramp_s``): (g, g', g'')."""
    g, dg, ddg = np.ones_like(t), np.zeros_like(t), np.zeros_like(t)
    for s in starts:
        w, dw, ddw = envelope(t - (s - ramp_s), glide_s + 2 * ramp_s, ramp_s)
        inside = (t > s - ramp_s) & (t < s + glide_s + ramp_s)
        # 1 - w in the glide: w rises to 1 over the ramp before the glide and falls after it
        g = np.where(inside, g * (1 - w), g)
        dg = np.where(inside, -dw, dg)
        ddg = np.where(inside, -ddw, ddg)
    return g, dg, ddg


@dataclass
class Stretch:
    """One continuous stretch: start (s), duration (s), translation sinusoids (amp m, freq Hz, phase rad per
    axis and component), rotation axis (sensor frame), rotation sinusoids and glide starts (s, relative)."""

    t0: float
    total_s: float
    amp: np.ndarray
    freq: np.ndarray
    phase: np.ndarray
    axis: np.ndarray
    rot_amp: np.ndarray
    rot_freq: np.ndarray
    rot_phase: np.ndarray
    glides: np.ndarray
    glide_s: float
    ramp_s: float

    def translation(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w, dw, ddw = envelope(t, self.total_s, self.ramp_s)
        arg = 2 * np.pi * self.freq[None] * t[:, None, None] + self.phase[None]
        om = 2 * np.pi * self.freq[None]
        f = np.sum(self.amp[None] * np.sin(arg), axis=2)
        df = np.sum(self.amp[None] * om * np.cos(arg), axis=2)
        ddf = np.sum(-self.amp[None] * om**2 * np.sin(arg), axis=2)
        return (
            w[:, None] * f,
            dw[:, None] * f + w[:, None] * df,
            ddw[:, None] * f + 2 * dw[:, None] * df + w[:, None] * ddf,
        )

    def angle(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w, dw, _ = envelope(t, self.total_s, self.ramp_s)
        g, dg, _ = gate(t, self.glides, self.glide_s, min(self.ramp_s, 0.5))
        arg = 2 * np.pi * self.rot_freq[None] * t[:, None] + self.rot_phase[None]
        f = np.sum(self.rot_amp[None] * np.sin(arg), axis=1)
        df = np.sum(self.rot_amp[None] * 2 * np.pi * self.rot_freq[None] * np.cos(arg), axis=1)
        e, de = w * g, dw * g + w * dg
        return e * f, de * f + e * df


@dataclass
class ContinuousPlan(MotionPlan):
    """A :class:`MotionPlan` (opening, wave, static waits) plus continuous stretches laid over its waits."""

    stretches: list[Stretch] = field(default_factory=list)

    def evaluate(self, t_s: np.ndarray) -> Kinematics:
        kin = super().evaluate(t_s)
        t = np.asarray(t_s, dtype=float)
        for st in self.stretches:
            sel = np.flatnonzero((t > st.t0) & (t < st.t0 + st.total_s))
            if not len(sel):
                continue
            tr = t[sel] - st.t0
            p, v, a = st.translation(tr)
            kin.position[sel] += p
            kin.velocity[sel] += v
            kin.acceleration[sel] += a
            th, dth = st.angle(tr)
            kin.orientation[sel] = quat.multiply(kin.orientation[sel], quat.from_rotation_vector(st.axis * th[:, None]))
            kin.omega[sel] = st.axis * dth[:, None]
            kin.moving[sel] = True
        return kin


def build(params: Params, subject_rng: np.random.Generator, rng: np.random.Generator, trial: int = 0) -> ProtocolResult:
    home = np.array([0.4, 0.0, params.height_m])
    plan = ContinuousPlan(home, quat.from_euler_zyx(rng.uniform(-30, 30), 0.0, 0.0))
    opening(plan, params, rng)
    n = params.rests + 1
    moving_s = params.duration_s - params.rests * params.rest_s
    lengths = np.full(n, moving_s / n)
    start = plan.t
    for k in range(n):
        total = float(lengths[k])
        m = params.components
        axis = rng.normal(size=3)
        margin = params.ramp_s + 0.5
        slot = (total - 2 * margin) / max(params.glides, 1)  # one glide per slot: they never overlap
        room = slot - params.glide_s - 1.0
        glides = (
            margin + slot * np.arange(params.glides) + 0.5 + rng.uniform(0.0, room, params.glides)
            if room > 0
            else np.zeros(0)
        )
        plan.stretches.append(
            Stretch(
                t0=plan.t,
                total_s=total,
                amp=params.amplitude_m / np.sqrt(m) * rng.uniform(0.6, 1.0, (3, m)),
                freq=rng.uniform(*params.frequency_hz, (3, m)),
                phase=rng.uniform(0, 2 * np.pi, (3, m)),
                axis=axis / np.linalg.norm(axis),
                rot_amp=np.radians(params.rotation_deg) / 2 * rng.uniform(0.6, 1.0, 2),
                rot_freq=rng.uniform(*params.rotation_hz, 2),
                rot_phase=rng.uniform(0, 2 * np.pi, 2),
                glides=glides,
                glide_s=params.glide_s,
                ramp_s=params.ramp_s,
            )
        )
        plan.mark("movement", plan.t, plan.t + total, k + 1)
        for g in glides:
            plan.mark("glide", plan.t + g, plan.t + g + params.glide_s)
        plan.wait(total)
        if k + 1 < n:
            plan.mark("rest", plan.t, plan.t + params.rest_s)
            plan.wait(params.rest_s)
    plan.mark("continuous", start, plan.t)
    plan.wait(params.closing_static_s)
    return ProtocolResult(
        plan=plan,
        task="continuous",
        trial_meta={"rests": params.rests, "rest_s": params.rest_s, "duration_s": params.duration_s},
        end_s=plan.t,
    )
