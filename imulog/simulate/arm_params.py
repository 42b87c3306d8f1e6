"""The two-segment arm simulator: its parameters (ArmParams), ground truth (ArmTruth) and trial (ArmTrial)."""

from __future__ import annotations

import dataclasses
import difflib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imulog.model import Recording
from imulog.simulate import imu_model

SEGMENTS = ("upper_arm", "forearm")


TRUNK = "trunk"


VICON_NAME = "vicon"


@dataclass(frozen=True)
class ArmParams:
    """Arm trial parameters (degrees, metres, seconds)."""

    duration_s: float = 60.0
    rate_hz: float = 100.0  # Xsens MTw and Vicon Vero of the paper
    neutral_s: float = 3.0  # static neutral posture at the start
    blend_s: float = 2.0  # minimum-jerk blend from the posture into the movement
    neutral_pose_deg: tuple[float, float, float, float, float] = (90.0, 30.0, 0.0, 90.0, 90.0)
    # movement: centre and amplitude per joint (deg); centre - amplitude = 0 touches the lower limit
    centre_deg: tuple[float, float, float, float, float] = (60.0, 55.0, 15.0, 55.0, 60.0)
    amplitude_deg: tuple[float, float, float, float, float] = (35.0, 30.0, 35.0, 55.0, 60.0)
    frequency_hz: tuple[float, float] = (0.05, 0.25)  # per-joint frequencies drawn in this range
    upper_arm_length_m: float = 0.30
    forearm_length_m: float = 0.27
    styloid_distance_m: float = 0.06
    carrying_angle_deg: float = 15.0
    shoulder_m: tuple[float, float, float] = (0.2, 0.5, 1.3)  # shoulder centre in the Vicon world
    trunk_heading_deg: float = 30.0  # trunk frame's rotation about the world vertical
    workspace_margin_m: float = 0.0
    mounting_error_deg: float = 0.0  # sd of the IMU-on-segment misalignment per axis
    imu_lever_m: float = 0.04  # IMU distance from the segment's long axis
    field_uT: float = 46.0
    inclination_deg: float = 62.0
    noise_free: bool = False
    vicon_noise_mm: float = 0.2
    imu_to_cluster_sd_deg: float = 0.0  # clusters slotted on the IMU supports (paper, Fig. 3a)
    trunk_imu: bool = False  # add a trunk IMU (and cluster)
    trunk_sway_deg: float = 0.0  # amplitude of the trunk's yaw / forward lean / side lean after the posture
    trunk_pivot_below_m: float = 0.45  # the trunk turns about a point this far below the shoulder


@dataclass
class ArmTruth:
    """True state on the common clock: joint angles ``q_rad`` (N, 5) (:data:`JOINT_NAMES` order),
    segment-to-trunk rotations, elbow/wrist centres (N, 3) m in the trunk frame, the trunk-to-world
    quaternions ``q_world_trunk`` (N, 4) and the IMU mounting rotations; per worn IMU its
    sensor-to-world quaternion ``q_world_sensor[name]`` (N, 4, w,x,y,z) and position
    ``imu_position_m[name]`` (N, 3) m in the Vicon world."""

    t_ns: np.ndarray
    q_rad: np.ndarray
    r_upper_arm: np.ndarray
    r_forearm: np.ndarray
    elbow_m: np.ndarray
    wrist_m: np.ndarray
    q_world_trunk: np.ndarray
    q_segment_to_sensor: dict[str, np.ndarray]
    info: dict[str, Any] = field(default_factory=dict)
    q_world_sensor: dict[str, np.ndarray] = field(default_factory=dict)
    imu_position_m: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def joint_angles_deg(self) -> np.ndarray:
        """``q_rad`` in degrees (N, 5)."""
        return np.degrees(self.q_rad)


@dataclass
class ArmTrial:
    recording: Recording
    truth: ArmTruth
    params: ArmParams
    seed: int = 0
    subject: int = 0
    trial: int = 0
    raw: dict[str, Any] | None = None  # exact decimal file values the writers use (see imu_model)

    @property
    def stem(self) -> str:
        """File stem of the written trial (and of the in-memory ``source`` names)."""
        return f"arm_s{self.subject:02d}_t{self.trial:02d}"


def arm_parameter_names() -> dict[str, list[str]]:
    """Names :func:`simulate_arm` accepts as ``**overrides``, grouped: arm model, IMU error model."""
    return {
        "arm": [f.name for f in dataclasses.fields(ArmParams)],
        "imu": [f.name for f in dataclasses.fields(imu_model.ImuParams)],
    }


def _split_overrides(overrides: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(ArmParams fields, ImuParams fields); TypeError naming unknown ones (with the closest name)."""
    names = arm_parameter_names()
    arm = {k: v for k, v in overrides.items() if k in names["arm"]}
    imu = {k: v for k, v in overrides.items() if k in names["imu"] and k not in arm}
    unknown = sorted(set(overrides) - set(arm) - set(imu))
    if unknown:
        valid = names["arm"] + names["imu"]
        hints = []
        for name in unknown:
            close = difflib.get_close_matches(name, valid, n=1)
            hints.append(f"{name} (did you mean {close[0]}?)" if close else name)
        raise TypeError(f"unknown arm parameter(s): {', '.join(hints)}")
    return arm, imu
