"""Markers on other segments than the IMU's: the trunk and the upper arm of a seated reaching subject.

Labs put markers on more than the wrist cluster (the trunk, the upper arm, the other hand). These markers
let the alignment's cluster search be tested against distractors that move with the task: the trunk leans
forward when the wrist reaches out and sways slowly, and the upper arm follows the wrist through a
two-link arm (shoulder on the trunk, elbow by inverse kinematics with a fixed swivel hint), so its angular
velocity is correlated with the wrist's but not equal to it.

The geometry is placed from the wrist's first position (the hand at rest on the table, lab frame x
forward, z up): the shoulder 0.30 m behind and 0.29 m above it, the trunk pivot (hips) 0.5 m under the
sternum. Segment markers carry a smooth soft-tissue displacement (``soft_tissue_mm``, 0.5 Hz low-pass)
on top of the Vicon noise, so they are rigid to about a millimetre, as skin markers are. Positions in m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from imulog.process import quaternion as quat

SEGMENTS = ("trunk", "upper_arm")

#: trunk markers, offsets (m) from the rest shoulder in the lab frame
TRUNK_MARKERS = {
    "STRN": (0.10, 0.17, -0.12),
    "CLAV": (0.08, 0.17, 0.03),
    "C7": (-0.09, 0.17, 0.08),
    "RSHO": (0.0, 0.0, 0.05),
    "LSHO": (0.0, 0.34, 0.05),
}
#: upper-arm plate markers, offsets (m) along the arm (e1), outwards (e2) and across (e3) from mid-arm
UPPER_ARM_MARKERS = {
    "UA1": (0.0, 0.045, 0.0),
    "UA2": (0.045, 0.045, 0.012),
    "UA3": (0.0, 0.05, 0.04),
    "UA4": (0.04, 0.05, -0.03),
}


@dataclass(frozen=True)
class ExtraMarkerParams:
    """Trunk and upper-arm geometry (m, deg, Hz)."""

    shoulder_from_wrist_m: tuple[float, float, float] = (-0.30, 0.0, 0.29)
    hip_below_shoulder_m: float = 0.5
    upper_arm_m: float = 0.30
    forearm_m: float = 0.26
    lean_deg_per_m: float = 60.0  # forward lean per metre the wrist moves forward of its rest position
    sway_deg: float = 1.5  # slow trunk sway about every axis
    soft_tissue_mm: float = 1.0
    swivel_hint: tuple[float, float, float] = (0.0, -0.3, -1.0)  # elbow points down and out


def _smooth_noise(n: int, rate_hz: float, sd: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) low-pass (0.5 Hz) Gaussian noise with standard deviation ``sd``."""
    if sd <= 0 or n < 20:
        return np.zeros((n, 3))
    sos = signal.butter(2, min(0.5, 0.4 * rate_hz), fs=rate_hz, output="sos")
    x = signal.sosfiltfilt(sos, rng.normal(0.0, 1.0, (n, 3)), axis=0)
    return x / max(float(np.std(x)), 1e-12) * sd


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def segment_markers(
    t_s: np.ndarray,
    wrist_m: np.ndarray,
    segments: tuple[str, ...],
    rng: np.random.Generator,
    params: ExtraMarkerParams = ExtraMarkerParams(),
    rate_hz: float = 100.0,
) -> dict[str, np.ndarray]:
    """True marker positions {label: (N, 3) m} of the requested ``segments`` for the wrist path ``wrist_m``."""
    unknown = [s for s in segments if s not in SEGMENTS]
    if unknown:
        raise ValueError(f"unknown extra segment(s) {', '.join(unknown)}; choose from {', '.join(SEGMENTS)}")
    t = np.asarray(t_s, dtype=np.float64)
    w = np.asarray(wrist_m, dtype=np.float64)
    n = len(t)
    s0 = w[0] + np.asarray(params.shoulder_from_wrist_m)
    pivot = s0 + np.array([0.0, 0.17, -params.hip_below_shoulder_m])
    forward = np.clip(w[:, 0] - w[0, 0], 0.0, None)
    f = rng.uniform(0.03, 0.12, 3)
    ph = rng.uniform(0, 2 * np.pi, 3)
    sway = np.radians(params.sway_deg) * np.sin(2 * np.pi * f[None] * t[:, None] + ph[None])
    lean = np.radians(params.lean_deg_per_m) * forward
    q_trunk = quat.from_rotation_vector(sway + np.stack([np.zeros(n), lean, np.zeros(n)], axis=1))
    out: dict[str, np.ndarray] = {}
    if "trunk" in segments:
        for name, off in TRUNK_MARKERS.items():
            local = np.broadcast_to(s0 + np.asarray(off) - pivot, (n, 3))
            out[name] = pivot + quat.rotate(q_trunk, local)
    if "upper_arm" in segments:
        shoulder = pivot + quat.rotate(q_trunk, np.broadcast_to(s0 - pivot, (n, 3)))
        l1, l2 = params.upper_arm_m, params.forearm_m
        d_vec = w - shoulder
        u = _unit(d_vec)
        d = np.clip(np.linalg.norm(d_vec, axis=1), abs(l1 - l2) + 0.01, l1 + l2 - 0.005)
        hint = _unit(np.asarray(params.swivel_hint, dtype=np.float64))
        v = _unit(hint[None] - np.sum(hint[None] * u, axis=1, keepdims=True) * u)
        a = (l1**2 - l2**2 + d**2) / (2 * d)
        b = np.sqrt(np.clip(l1**2 - a**2, 0.0, None))
        elbow = shoulder + a[:, None] * u + b[:, None] * v
        e1 = _unit(elbow - shoulder)
        e3 = _unit(np.cross(u, v))
        e2 = np.cross(e3, e1)
        centre = shoulder + 0.6 * l1 * e1
        for name, (a1, a2, a3) in UPPER_ARM_MARKERS.items():
            out[name] = centre + a1 * e1 + a2 * e2 + a3 * e3
    for name in out:
        out[name] = out[name] + _smooth_noise(n, rate_hz, params.soft_tissue_mm * 1e-3, rng)
    return out
