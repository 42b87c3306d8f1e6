"""One heading frame for the IMUs of a trial (issue 27): a reduce over the per-IMU orientations, then a correction.

Each IMU's orientation (``/derived/orientation/{imu}``, sensor to its global frame) is z-up; its heading is
magnetic north when the magnetometer was fused (9D, ENU) and arbitrary otherwise (6D). Orientations of several
IMUs share one global frame only when something ties their headings together. In order of preference:

1. ``magnetometer``: every IMU has a magnetometer whose field, seen in its global frame, is steady (norm and
   horizontal direction) and the same field for all (norm and dip within limits): the correction turns each
   global frame about the vertical so that the horizontal field points north (+y); identity for a 9D
   orientation in a clean field.
2. ``optical``: every IMU is aligned with a marker cluster and its ``rotation_global_to_world`` is known
   (``imulog process align`` after ``imulog process orientation``): the correction is that rotation, and the
   common frame is the optical world.
3. ``static pose``: a declared interval where the subject holds a pose in which the sensors face declared
   headings (all the same by default, as OpenSense's calibration pose): the correction turns each heading there
   onto the declared one.
4. ``none``: the headings do not relate; whoever combines the IMUs must say so.

Pure functions: quaternions w,x,y,z (sensor to global), field in uT, angles in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from imulog.process import quaternion as quat


@dataclass(frozen=True)
class HeadingParams:
    """Limits for a consistent magnetic field: norm varying by at most ``max_norm_cv`` (coefficient of
    variation) and horizontal direction by ``max_direction_sd_deg`` (circular sd) within each IMU; across IMUs
    norms within ``max_norm_diff`` (relative) and dips within ``max_dip_diff_deg``."""

    max_norm_cv: float = 0.1
    max_direction_sd_deg: float = 10.0
    max_norm_diff: float = 0.15
    max_dip_diff_deg: float = 8.0


def yaw_quaternion(yaw_rad: float) -> np.ndarray:
    """Rotation about the vertical (z) by ``yaw_rad``."""
    return np.array([np.cos(yaw_rad / 2), 0.0, 0.0, np.sin(yaw_rad / 2)])


def field_in_global(q_s2g: np.ndarray, mag_uT: np.ndarray) -> dict[str, Any]:
    """The magnetic field seen in an IMU's global frame: norm (mean, cv), dip (deg, positive down), the
    horizontal direction (deg from +y towards +x, i.e. the heading of north in that frame) and its circular sd."""
    m = quat.rotate(np.asarray(q_s2g, dtype=float), np.asarray(mag_uT, dtype=float))
    ok = np.all(np.isfinite(m), axis=1)
    if ok.sum() < 10:
        raise ValueError("too few magnetometer samples with an orientation")
    m = m[ok]
    norm = np.linalg.norm(m, axis=1)
    horiz = np.arctan2(m[:, 0], m[:, 1])
    c, s = np.mean(np.cos(horiz)), np.mean(np.sin(horiz))
    r = min(1.0, float(np.hypot(c, s)))
    return {
        "norm_uT": float(np.mean(norm)),
        "norm_cv": float(np.std(norm) / np.mean(norm)),
        "dip_deg": float(np.degrees(np.mean(np.arcsin(np.clip(-m[:, 2] / norm, -1, 1))))),
        "north_deg": float(np.degrees(np.arctan2(s, c))),
        "direction_sd_deg": float(np.degrees(np.sqrt(-2 * np.log(max(r, 1e-12))))),
    }


def magnetic_corrections(
    fields: dict[str, dict[str, Any]], params: HeadingParams = HeadingParams()
) -> tuple[dict[str, np.ndarray] | None, str]:
    """Per IMU the yaw correction (global -> magnetic ENU) from :func:`field_in_global` results, or None and
    why the field is not consistent."""
    for name, f in fields.items():
        if f["norm_cv"] > params.max_norm_cv:
            return None, f"{name}: field norm varies by {100 * f['norm_cv']:.0f} % (disturbed)"
        if f["direction_sd_deg"] > params.max_direction_sd_deg:
            return None, f"{name}: the field's direction in its global frame wanders by {f['direction_sd_deg']:.0f} deg"
    norms = [f["norm_uT"] for f in fields.values()]
    dips = [f["dip_deg"] for f in fields.values()]
    if (max(norms) - min(norms)) / np.mean(norms) > params.max_norm_diff:
        return None, f"field norms differ between IMUs ({min(norms):.0f}-{max(norms):.0f} uT)"
    if max(dips) - min(dips) > params.max_dip_diff_deg:
        return None, f"field dips differ between IMUs ({min(dips):.0f}-{max(dips):.0f} deg)"
    # north at angle a from +y towards +x: turning the frame by +a about z brings it onto +y
    return {n: yaw_quaternion(np.radians(f["north_deg"])) for n, f in fields.items()}, ""


def heading_deg(q_s2g: np.ndarray, axis: tuple[float, float, float] = (1.0, 0.0, 0.0)) -> np.ndarray:
    """Heading (deg, from +x towards +y) of a sensor axis projected on the horizontal plane."""
    v = quat.rotate(np.asarray(q_s2g, dtype=float), np.tile(np.asarray(axis, dtype=float), (len(q_s2g), 1)))
    return np.degrees(np.arctan2(v[:, 1], v[:, 0]))


def static_pose_corrections(
    q_in_pose: dict[str, np.ndarray], declared_deg: dict[str, float] | None = None
) -> dict[str, np.ndarray]:
    """Yaw corrections that turn each IMU's sensor x heading, averaged over the pose's samples, onto its declared
    heading (default: the first IMU's, i.e. all sensors face the same way in the pose)."""
    means = {}
    for name, q in q_in_pose.items():
        h = np.radians(heading_deg(q))
        h = h[np.isfinite(h)]
        if not len(h):
            raise ValueError(f"{name}: no orientation sample in the static pose")
        means[name] = float(np.arctan2(np.mean(np.sin(h)), np.mean(np.cos(h))))
    first = next(iter(means.values()))
    out = {}
    for name, h in means.items():
        target = np.radians(declared_deg[name]) if declared_deg and name in declared_deg else first
        out[name] = yaw_quaternion(target - h)
    return out


def apply_correction(correction: np.ndarray, q_s2g: np.ndarray) -> np.ndarray:
    """Orientation in the common frame: ``correction`` (global -> common) times ``q_s2g`` (N, 4)."""
    q = np.asarray(q_s2g, dtype=float)
    return quat.multiply(np.tile(np.asarray(correction, dtype=float), (len(q), 1)), q)
