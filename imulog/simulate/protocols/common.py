"""Pieces shared by protocols: the opening static period and the alignment 'wave'."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imulog.simulate.motion import MotionPlan


@dataclass
class ProtocolResult:
    """What a protocol builds: the motion, its metadata and the recording span (reference clock, s)."""

    plan: MotionPlan
    task: str
    anthropometrics: dict = field(default_factory=dict)
    trial_meta: dict = field(default_factory=dict)
    end_s: float = 0.0
    extra: dict = field(default_factory=dict)


def opening(
    plan: MotionPlan,
    params: Any,
    rng: np.random.Generator,
    axes: tuple[np.ndarray, ...] | None = None,
) -> None:
    """Opening static period, then the 'wave' and a second static period (thesis section 2.2.2:
    1 min static, waving about the sensitive axis to align Vicon and IMU, 1 min static).

    ``params`` is the protocol's parameter object, with ``opening_static_s``, ``wave_cycles``,
    ``wave_amplitude_deg``, ``wave_half_swing_s`` (s) and ``post_wave_static_s``.

    The wave is ``wave_cycles`` back-and-forth rotations about each sensor axis in turn
    (x: pronation/supination, y: flexion/extension, z: radial/ulnar deviation), so the
    IMU-to-cluster rotation is observable about all three axes. ``axes`` (sensor-frame unit
    vectors) restricts it, e.g. to the slide's sensitive axis. Intervals ``opening_static``,
    ``wave`` and ``post_wave_static`` are marked.
    """
    static_s, post_static_s = params.opening_static_s, params.post_wave_static_s
    wave_cycles, wave_half_swing_s = params.wave_cycles, params.wave_half_swing_s
    plan.wait(static_s)
    plan.mark("opening_static", plan.t - static_s, plan.t)
    start = plan.t
    amp = np.radians(params.wave_amplitude_deg)
    for unit in axes if axes is not None else tuple(np.eye(3)):
        unit = np.asarray(unit, dtype=float)
        a = amp * rng.uniform(0.85, 1.15)
        plan.rotate(wave_half_swing_s, unit * a)
        for _ in range(wave_cycles):
            plan.rotate(2 * wave_half_swing_s * rng.uniform(0.9, 1.1), -2 * a * unit)
            plan.rotate(2 * wave_half_swing_s * rng.uniform(0.9, 1.1), 2 * a * unit)
        plan.rotate(wave_half_swing_s, -a * unit)
    plan.mark("wave", start, plan.t)
    plan.wait(post_static_s)
    plan.mark("post_wave_static", plan.t - post_static_s, plan.t)
