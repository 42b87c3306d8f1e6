"""Where the viewer draws an IMU's orientation in 3D: a moving frame (its x, y, z axes) beside the Vicon cluster.

Pure numpy, no Rerun: :func:`imu_frame` gives the rows of one ``Transform3D`` entity. The rotation is the
orientation (sensor to global, w, x, y, z) turned into the Vicon world by the alignment's
``rotation_global_to_world`` when there is one (derived orientations; a device's own orientation is in the
device's global frame and is drawn as is). The frame sits :data:`BESIDE_CLUSTER_M` from the Vicon cluster's
origin at the same instant (so the cluster's axes and the IMU's can be compared side by side), or, without a
cluster, at the world origin, one IMU :data:`IMU_SPACING_M` from the next.
"""

from __future__ import annotations

import numpy as np

ORIENTATION_COLUMNS = ["qw", "qx", "qy", "qz"]
BESIDE_CLUSTER_M = np.array([0.0, 0.2, 0.0])  # world +y of the cluster's origin
IMU_SPACING_M = 0.3  # along world x between IMUs when there is no cluster
AXIS_LENGTH_M = 0.1
UNIT_TOLERANCE = 1e-3  # rows whose |q| differs more from 1 are not orientations (e.g. an overview's envelope)


def is_orientation(topic: str, columns: list[str]) -> bool:
    """A derived (``/derived/orientation/{imu}``) or device (``/orientation/{imu}``) quaternion channel."""
    return topic.startswith(("/derived/orientation/", "/orientation/")) and list(columns[:4]) == ORIENTATION_COLUMNS


def imu_frame(
    t_ref: np.ndarray,
    q_wxyz: np.ndarray,
    *,
    rotation: list[float] | None = None,
    cluster: tuple[np.ndarray, np.ndarray] | None = None,
    index: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(valid rows, translations (V, 3) m, quaternions (V, 4) x, y, z, w) of the IMU frame.

    ``t_ref``: reference-clock ns of each row; ``cluster``: (t_ref ns, (N, 3) positions m) of the Vicon cluster.
    """
    q = np.asarray(q_wxyz, np.float64)[:, :4]
    norm = np.linalg.norm(q, axis=1)
    valid = np.isfinite(q).all(axis=1) & (np.abs(norm - 1.0) < UNIT_TOLERANCE)
    q = q[valid] / norm[valid, None]
    if rotation is not None and len(rotation) == 4:
        from imulog.process import quaternion as quat

        q = quat.multiply(np.asarray(rotation, np.float64)[None, :], q)
    t = np.asarray(t_ref, np.int64)[valid]
    if cluster is not None and len(cluster[0]) > 1:
        ct, cp = np.asarray(cluster[0], np.float64), np.asarray(cluster[1], np.float64)
        good = np.isfinite(cp).all(axis=1)
        if good.sum() > 1:
            pos = np.column_stack([np.interp(t.astype(np.float64), ct[good], cp[good, k]) for k in range(3)])
            return valid, pos + BESIDE_CLUSTER_M, q[:, [1, 2, 3, 0]]
    pos = np.tile([IMU_SPACING_M * index, 0.0, 0.0], (len(t), 1))
    return valid, pos, q[:, [1, 2, 3, 0]]
