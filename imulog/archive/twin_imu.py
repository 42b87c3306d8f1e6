"""The ROS 2 ``sensor_msgs/msg/Imu`` twin of an IMU channel (CDR rows built with numpy).

Part of :mod:`imulog.archive.twins` (which re-exports these names).
"""

from __future__ import annotations

import numpy as np

from imulog.archive.timeline import LogMap
from imulog.archive.twin_rate import decimated
from imulog.archive.twin_record import Twin, twin_meta, twin_topic
from imulog.model import ImuStream

ROS_IMU_SCHEMA = """std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"""


def ros_imu_rows(stamps: np.ndarray, frame_id: str, gyr: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """CDR (little-endian) ``sensor_msgs/msg/Imu`` messages, built as one numpy record array.

    ``stamps`` int64 ns (the header stamp), ``gyr`` rad/s and ``acc`` m/s^2, (N, 3). The orientation is
    marked unknown (``orientation_covariance[0] = -1``, the ROS convention). (N, message size) uint8.
    """
    name = frame_id.encode("utf-8") + b"\0"
    head = 12 + len(name)
    pad = (-head) % 8
    dtype = np.dtype(
        [
            ("enc", "u1", 4),
            ("sec", "<i4"),
            ("nsec", "<u4"),
            ("slen", "<u4"),
            ("name", f"S{len(name) + pad}"),
            ("f", "<f8", 37),
        ]
    )
    n = len(stamps)
    rec = np.zeros(n, dtype=dtype)
    rec["enc"] = [0, 1, 0, 0]  # CDR_LE encapsulation header
    sec, nsec = np.divmod(np.asarray(stamps, dtype=np.int64), 1_000_000_000)
    rec["sec"], rec["nsec"], rec["slen"] = sec, nsec, len(name)
    rec["name"] = name
    f = rec["f"]
    f[:, 3] = 1.0  # orientation (x, y, z, w) = identity, unknown:
    f[:, 4] = -1.0  # orientation_covariance[0] = -1
    f[:, 13:16] = gyr
    f[:, 25:28] = acc
    return rec.view(np.uint8).reshape(n, dtype.itemsize)


def ros_imu_payloads(stamps: np.ndarray, frame_id: str, gyr: np.ndarray, acc: np.ndarray) -> list[bytes]:
    """:func:`ros_imu_rows` as one ``bytes`` per message."""
    return [row.tobytes() for row in ros_imu_rows(stamps, frame_id, gyr, acc)]


def imu_twin(stream: ImuStream, log_map: LogMap) -> Twin | None:
    if stream.acc is None and stream.gyr is None:
        return None
    keep, low = decimated(stream)
    stamps = log_map(stream.t_ns[keep]).astype(np.int64)
    nan = np.full((len(keep), 3), np.nan)
    gyr = low.gyr if low.gyr is not None else nan
    acc = low.acc if low.acc is not None else nan
    meta = twin_meta(stream, stream.topic, stream.name, keep, stream.t_ns)
    meta.update(units=f"angular_velocity rad/s, linear_acceleration m/s^2 ({stream.frame_id} frame)")
    twin = Twin(twin_topic(stream.topic), "sensor_msgs/msg/Imu", "ros2msg", ROS_IMU_SCHEMA.encode(), "cdr", meta)
    twin.set_rows(stamps.astype(np.uint64), ros_imu_rows(stamps, stream.frame_id, gyr, acc))
    return twin
