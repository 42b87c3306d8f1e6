"""From IMU (or marker-cluster) orientations to segment orientations in the DH trunk frame.

An IMU's orientation ``q_s2g`` (sensor -> its gravity-aligned global frame, heading arbitrary) gives
the segment orientation in the trunk frame as

    R_seg = R(q_g2t) R(q_s2g) R(q_seg2s)

with ``q_seg2s`` the constant segment-to-sensor mounting rotation (identity when the sensor axes
are aligned with the DH segment axes, as on the paper's 3D-printed supports) and ``q_g2t`` the
global-to-trunk rotation. ``q_g2t`` is found from a static neutral posture with known joint angles
(the paper initialises its filters in a neutral posture): mode ``heading`` fits a rotation about
the vertical only (the global frame is already gravity-aligned, like the trunk frame's z), mode
``full`` a complete rotation (also absorbs a constant inclination error of the posture).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat

__all__ = ["NeutralCalibration", "fit_global_to_trunk", "segment_rotations"]


@dataclass(frozen=True)
class NeutralCalibration:
    """Neutral-posture calibration settings.

    ``pose_deg``: the five free joint angles of the posture (deg, DH order); default
    ``(90, 30, 0, 90, 90)``: arm 30 deg forward, elbow at 90 deg, forearm in mid pronation.
    ``window_s``: (start, end) of the posture in seconds from the first sample (0.5 .. 2.5 s).
    ``mode``: ``heading`` (default) or ``full``.
    """

    pose_deg: tuple[float, float, float, float, float] = (90.0, 30.0, 0.0, 90.0, 90.0)
    window_s: tuple[float, float] = (0.5, 2.5)
    mode: str = "heading"

    def __post_init__(self) -> None:
        if self.mode not in ("heading", "full"):
            raise ValueError(f"calibration mode must be 'heading' or 'full', got {self.mode!r}")
        if len(self.pose_deg) != 5:
            raise ValueError("pose_deg needs the five free joint angles (deg)")
        if not self.window_s[1] > self.window_s[0]:
            raise ValueError(f"neutral window must end after it starts, got {self.window_s} s")

    def window_mask(self, t_ns: np.ndarray) -> np.ndarray:
        """(N,) True for samples inside the neutral window (relative to ``t_ns[0]``)."""
        t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
        return (t >= self.window_s[0]) & (t <= self.window_s[1])


def fit_global_to_trunk(
    q_s2g_window: np.ndarray, r_segment_model: np.ndarray, q_seg2s: np.ndarray = quat.IDENTITY, mode: str = "heading"
) -> np.ndarray:
    """Global-to-trunk quaternion (4,) so that the mean neutral-window orientation matches the model.

    ``q_s2g_window`` (M, 4) sensor-to-global quaternions during the posture (NaN rows ignored);
    ``r_segment_model`` (3, 3) the modelled segment-to-trunk rotation in the posture.
    """
    q = np.asarray(q_s2g_window, dtype=np.float64)
    q = q[np.all(np.isfinite(q), axis=1)]
    if len(q) == 0:
        raise ValueError("no valid orientation sample in the neutral window")
    a = quat.to_rotation_matrix(quat.multiply(quat.average(q), q_seg2s))  # segment -> global
    m = np.asarray(r_segment_model) @ a.T  # ideally global -> trunk
    if mode == "full":
        return quat.normalize(quat.from_rotation_matrix(m))
    if mode != "heading":
        raise ValueError(f"calibration mode must be 'heading' or 'full', got {mode!r}")
    psi = math.atan2(m[1, 0] - m[0, 1], m[0, 0] + m[1, 1])
    return np.array([math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)])


def segment_rotations(q_s2g: np.ndarray, q_g2t: np.ndarray, q_seg2s: np.ndarray = quat.IDENTITY) -> np.ndarray:
    """Segment-to-trunk rotation matrices (N, 3, 3) from sensor-to-global quaternions (N, 4); NaN kept."""
    q = quat.multiply(quat.multiply(q_g2t, np.asarray(q_s2g, dtype=np.float64)), q_seg2s)
    return quat.to_rotation_matrix(q)
