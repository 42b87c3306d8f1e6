"""Viewer twins: well-known-schema copies of block channels that Foxglove and Rerun's MCAP loader draw as is.

The block channels stay the canonical store; next to them the writer puts, under ``/derived/viewer/``, a
reduced-rate copy in a schema both tools understand without imulog (docs/schemas.md has the table):

==================================  ====================================  ===========================
canonical channel                   twin                                  Rerun archetype
==================================  ====================================  ===========================
``/imu/{name}`` (ImuBlock)          ``sensor_msgs/msg/Imu`` (ROS 2, CDR)  Scalars (plotted)
``/markers/{name}`` (MarkerBlock)   ``foxglove.PointCloud``               Points3D
``/derived/orientation/{imu}``      ``foxglove.FrameTransform``           Transform3D (world -> imu)
``/derived/orientation/{imu}``      ``foxglove.PointCloud`` (axes/{imu})  Points3D (the IMU frame)
pose channels (PoseBlock)           ``foxglove.FrameTransform``           Transform3D (frame -> name)
interval channels (IntervalEvent)   ``foxglove.Log``                      TextLog
``/derived/trajectory/{method}``    ``foxglove.PosesInFrame`` (per rep.)  InstancePoses3D
==================================  ====================================  ===========================

Twins are at most :data:`TWIN_RATE_HZ` (every k-th sample) and at most :data:`MAX_TWIN_MESSAGES` messages per
channel; recordings longer than :data:`OVERVIEW_AFTER_S` get an overview of one sample per :data:`OVERVIEW_EPOCH_S`. IMU axes are low-passed before decimation
(:mod:`imulog.archive.twin_filter`: zero-phase FIR, flat to 0.8x the twin's Nyquist, >= 60 dB down from it), so
what an IMU twin shows is the signal below its Nyquist frequency, not aliases of the content above it; marker
positions, orientations, poses and trajectories are the canonical samples (their content above the twin's
Nyquist is 46-60 dB down already on a real Nexus capture; a quaternion is not filtered component-wise). Their log time is the
trial's time axis (:mod:`imulog.archive.timeline`), and so is the timestamp inside the message.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imulog.archive.timeline import LogMap
from imulog.model import ImuStream, Intervals, MarkerStream, PoseStream, SignalStream, Stream
from imulog.numeric import finite_rows

TWIN_PREFIX = "/derived/viewer"
# At most this rate (every k-th sample of the canonical channel). A preview for Foxglove and Rerun's MCAP loader:
# 25 Hz keeps a wrist's movements (below ~10 Hz) and costs about 6 % of a 100 Hz IMU trial's size, where 50 Hz
# cost 12 % (MCAP indexes every message uncompressed); imulog's own viewer and every step read the full rate.
TWIN_RATE_HZ = 25.0
MAX_TWIN_MESSAGES = 180_000  # 2 h at 25 Hz; longer recordings get a proportionally lower twin rate
# Recordings longer than this (home monitoring, days) get an epoch-rate overview instead: one low-passed sample
# per OVERVIEW_EPOCH_S (a day 8 640 messages, 0.5 MB; a week 60 480). Issue 28: the 25 Hz copy budgeted to
# 180 000 messages cost 10.5 MB a day, 7 % of the archive. Short trials keep 25 Hz.
OVERVIEW_AFTER_S = 3 * 3600.0
OVERVIEW_EPOCH_S = 10.0
ORIENTATION_COLUMNS = ["qw", "qx", "qy", "qz"]

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


@dataclass
class Twin:
    """One viewer channel, ready to write: schema, channel metadata, log times and payloads."""

    topic: str
    schema_name: str
    schema_encoding: str  # "protobuf" or "ros2msg"
    schema_data: bytes
    message_encoding: str  # "protobuf" or "cdr"
    metadata: dict[str, str] = field(default_factory=dict)
    log_times: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)
    rows: np.ndarray | None = None  # or: the messages as (N, W) uint8 rows (imulog.archive.wire.Rows) ...
    mask: np.ndarray | None = None  # ... with the bytes each message uses (None: whole rows)

    def set_rows(self, log_times: np.ndarray, rows: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Hold the messages as rows (written and hashed with numpy, no per-message Python)."""
        self.log_times = np.asarray(log_times, dtype=np.uint64)
        self.rows, self.mask, self.payloads = rows, mask, []

    def __len__(self) -> int:
        return len(self.rows) if self.rows is not None else len(self.payloads)

    def payload_list(self) -> list[bytes]:
        """The messages as one ``bytes`` each, whichever form the twin holds."""
        if self.rows is None:
            return self.payloads
        from imulog.archive.wire import row_messages

        return row_messages(self.rows, self.mask)


def twin_topic(topic: str) -> str:
    """``/markers/vicon`` -> ``/derived/viewer/markers/vicon``; ``/derived/x/y`` -> ``/derived/viewer/x/y``."""
    rest = topic[len("/derived") :] if topic.startswith("/derived/") else topic
    return TWIN_PREFIX + rest


def is_twin(topic: str, channel_meta: Mapping[str, str] | None = None) -> bool:
    return bool((channel_meta or {}).get("twin_of")) or topic.startswith(TWIN_PREFIX + "/")


def decimation(t_ns: np.ndarray, rate_hz: float = TWIN_RATE_HZ, max_messages: int = MAX_TWIN_MESSAGES) -> np.ndarray:
    """Indices of the samples a twin keeps: every k-th, k chosen for <= ``rate_hz`` and <= ``max_messages``."""
    n = len(t_ns)
    if n < 2:
        return np.arange(n)
    return np.arange(0, n, decimation_step(n, float(np.median(np.diff(t_ns))), rate_hz, max_messages))


def decimation_step(
    n: int, median_dt_ns: float, rate_hz: float = TWIN_RATE_HZ, max_messages: int = MAX_TWIN_MESSAGES
) -> int:
    """The ``k`` of :func:`decimation` for ``n`` samples whose median sampling interval is ``median_dt_ns`` (ns)."""
    src_rate = 1e9 / median_dt_ns if median_dt_ns > 0 else rate_hz
    k = max(1, math.ceil(src_rate / rate_hz - 1e-9), math.ceil(n / max_messages))
    if n / src_rate > OVERVIEW_AFTER_S:  # its length in samples over its rate (not the span: clock jumps)
        k = max(k, overview_step(src_rate))
    return k


def overview_step(rate_hz: float) -> int:
    """Every k-th sample of a long recording's twin: one per :data:`OVERVIEW_EPOCH_S`."""
    return max(1, math.ceil(rate_hz * OVERVIEW_EPOCH_S - 1e-9))


def decimated(stream: ImuStream) -> tuple[np.ndarray, ImuStream]:
    """The kept indices of a twin and the stream at them, low-passed first (:mod:`imulog.archive.twin_filter`)."""
    from imulog.archive.twin_filter import lowpassed

    keep = decimation(stream.t_ns)
    k = int(keep[1] - keep[0]) if len(keep) > 1 else 1
    return keep, lowpassed(stream, keep, k)


def _stamp(msg: Any, t: int) -> None:
    msg.timestamp.seconds, msg.timestamp.nanos = divmod(int(t), 1_000_000_000)


def _meta(stream: Stream, canonical: str, clock: str, keep: np.ndarray, t: np.ndarray) -> dict[str, str]:
    out = {"twin_of": canonical, "clock": clock, "kind": "viewer", "sample_count": str(len(keep))}
    if len(keep):
        out.update(start_ns=str(int(t[keep[0]])), end_ns=str(int(t[keep[-1]])))
        if len(keep) > 1:
            out["rate_hz"] = f"{1e9 * (len(keep) - 1) / max(1, int(t[keep[-1]] - t[keep[0]])):.6g}"
    return out


def _protobuf_twin(topic: str, schema_name: str, meta: dict[str, str]) -> Twin:
    from imulog.archive import codec

    return Twin(topic, schema_name, "protobuf", codec.file_descriptor_set(schema_name), "protobuf", meta)


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


def _timestamp(stamps: np.ndarray) -> Any:
    """``google.protobuf.Timestamp`` sub-messages of int64 ns stamps, as :class:`imulog.archive.wire.Rows`."""
    from imulog.archive.wire import Rows

    sec, nsec = np.divmod(np.asarray(stamps, dtype=np.int64), 1_000_000_000)
    return Rows(len(sec)).varint(1, sec).varint(2, nsec)


def imu_twin(stream: ImuStream, log_map: LogMap) -> Twin | None:
    if stream.acc is None and stream.gyr is None:
        return None
    keep, low = decimated(stream)
    stamps = log_map(stream.t_ns[keep]).astype(np.int64)
    nan = np.full((len(keep), 3), np.nan)
    gyr = low.gyr if low.gyr is not None else nan
    acc = low.acc if low.acc is not None else nan
    meta = _meta(stream, stream.topic, stream.name, keep, stream.t_ns)
    meta.update(units=f"angular_velocity rad/s, linear_acceleration m/s^2 ({stream.frame_id} frame)")
    twin = Twin(twin_topic(stream.topic), "sensor_msgs/msg/Imu", "ros2msg", ROS_IMU_SCHEMA.encode(), "cdr", meta)
    twin.set_rows(stamps.astype(np.uint64), ros_imu_rows(stamps, stream.frame_id, gyr, acc))
    return twin


def marker_twin(stream: MarkerStream, log_map: LogMap, keep: np.ndarray | None = None) -> Twin:
    """``foxglove.PointCloud`` of the valid markers; ``keep``: the samples shown (default :func:`decimation`)."""
    from imulog.archive._generated.foxglove import PackedElementField_pb2, PointCloud_pb2

    # positions as sampled: their content above the twin's Nyquist is < -46 dB
    keep = decimation(stream.t_ns) if keep is None else keep
    twin = _protobuf_twin(
        twin_topic(stream.topic), "foxglove.PointCloud", _meta(stream, stream.topic, "reference", keep, stream.t_ns)
    )
    twin.metadata["units"] = "m"
    fld = PackedElementField_pb2.PackedElementField
    # float32 like Rerun's Points3D: under a micrometre for lab coordinates, half the bytes of float64
    fields = [fld(name=axis, offset=4 * k, type=fld.FLOAT32) for k, axis in enumerate("xyz")]
    from imulog.archive.wire import Rows

    stamps = np.asarray(log_map(stream.t_ns[keep]), dtype=np.int64)
    msg = PointCloud_pb2.PointCloud(frame_id=stream.frame_id, point_stride=12, fields=fields)
    msg.pose.position.SetInParent()  # an empty Pose makes Rerun 0.41 write null translations
    msg.pose.orientation.w = 1.0
    ok = np.asarray(stream.valid, dtype=bool)[keep] & finite_rows(stream.pos[keep])  # (K, M)
    n, m_ = ok.shape
    pos = np.ascontiguousarray(stream.pos[keep], dtype="<f4").view(np.uint8).reshape(n, m_ * 12)
    rows = Rows(n).message(1, _timestamp(stamps)).raw(msg.SerializeToString())  # fields 2-5: the same each time
    rows.data(6, pos, np.repeat(ok, 12, axis=1))  # the valid markers' x, y, z
    twin.set_rows(stamps.astype(np.uint64), *rows.build())
    return twin


def frame_twin(
    stream: SignalStream | PoseStream,
    log_map: LogMap,
    *,
    parent: str,
    child: str,
    clock: str,
    rotation: list[float] | None = None,
    origin: Origin | None = None,
    keep: np.ndarray | None = None,
) -> Twin:
    """``foxglove.FrameTransform`` parent -> child from a pose stream or an orientation (qw..qz) stream.

    ``rotation`` (w, x, y, z) is applied in front of every orientation (e.g. the alignment's global-to-world);
    ``origin`` places an orientation stream's frame (else at the parent's origin); ``keep``: the samples the
    twin shows (default :func:`decimation`).
    """
    from imulog.archive._generated.foxglove import FrameTransform_pb2

    keep, q, p = _frame_samples(stream, rotation, origin, keep)
    twin = _protobuf_twin(
        twin_topic(stream.topic), "foxglove.FrameTransform", _meta(stream, stream.topic, clock, keep, stream.t_ns)
    )
    twin.metadata.update(parent_frame_id=parent, child_frame_id=child)
    from imulog.archive.wire import Rows

    stamps = np.asarray(log_map(stream.t_ns[keep]), dtype=np.int64)
    good = np.isfinite(q).all(axis=1) & np.isfinite(p).all(axis=1)
    stamps, q, p = stamps[good], q[good], p[good]
    n = len(stamps)
    names = FrameTransform_pb2.FrameTransform(parent_frame_id=parent, child_frame_id=child).SerializeToString()
    translation = Rows(n).double(1, p[:, 0]).double(2, p[:, 1]).double(3, p[:, 2])
    rotation = Rows(n).double(1, q[:, 1]).double(2, q[:, 2]).double(3, q[:, 3]).double(4, q[:, 0])  # x, y, z, w
    rows = Rows(n).message(1, _timestamp(stamps)).raw(names).message(4, translation).message(5, rotation)
    twin.set_rows(stamps.astype(np.uint64), *rows.build())
    return twin


Origin = tuple[np.ndarray, np.ndarray]  # (t_ns on the stream's clock, (N, 3) positions in m)
AXIS_LENGTH_M = 0.12
AXIS_POINTS = 12
AXES_RATE_HZ = 5.0  # the axis points are constant (the transform moves them): a few repeats per second
_AXIS_RGBA = ((230, 40, 40, 255), (40, 190, 40, 255), (40, 90, 230, 255))  # x red, y green, z blue


def _frame_samples(
    stream: SignalStream | PoseStream,
    rotation: list[float] | None,
    origin: Origin | None,
    keep: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kept indices (``keep``, default :func:`decimation`), orientations (w, x, y, z) and positions of a frame twin."""
    keep = decimation(stream.t_ns) if keep is None else keep
    if isinstance(stream, PoseStream):
        q, p = stream.orientation[keep], stream.position[keep]
    else:
        q, p = stream.values[keep][:, :4], np.zeros((len(keep), 3))
        if origin is not None and len(origin[0]) > 1:
            t = stream.t_ns[keep].astype(np.float64)
            src_t = origin[0].astype(np.float64)
            p = np.column_stack([np.interp(t, src_t, origin[1][:, k]) for k in range(3)])
    if rotation is not None and len(rotation) == 4:
        from imulog.process import quaternion as quat

        q = quat.multiply(np.asarray(rotation, dtype=np.float64)[None, :], q)
    return keep, q, p


def axes_twin(
    stream: SignalStream,
    log_map: LogMap,
    *,
    clock: str,
    rate_hz: float = AXES_RATE_HZ,
    keep: np.ndarray | None = None,
) -> Twin:
    """The IMU frame as coloured points along its axes (``foxglove.PointCloud``, x red, y green, z blue).

    The points are constant, in the IMU's own frame (``frame_id`` = the IMU name): the ``FrameTransform``
    twin world -> IMU moves them, in Rerun (named coordinate frames) as in Foxglove. Rerun's loader draws a
    PointCloud without any blueprint (a transform alone needs an axes visualizer added by hand), so this is
    the form in which the moving IMU frame shows up as is. Repeated at ``rate_hz`` (bytes: almost nothing).
    """
    from imulog.archive._generated.foxglove import PackedElementField_pb2, PointCloud_pb2

    keep = decimation(stream.t_ns, rate_hz) if keep is None else keep
    name = stream.topic.rsplit("/", 1)[-1]
    twin = _protobuf_twin(
        f"{TWIN_PREFIX}/axes/{name}", "foxglove.PointCloud", _meta(stream, stream.topic, clock, keep, stream.t_ns)
    )
    twin.metadata.update(units="m", axis_length_m=str(AXIS_LENGTH_M), frame_id=name)
    fld = PackedElementField_pb2.PackedElementField
    fields = [fld(name=axis, offset=4 * k, type=fld.FLOAT32) for k, axis in enumerate("xyz")]
    fields += [fld(name=c, offset=12 + k, type=fld.UINT8) for k, c in enumerate(("red", "green", "blue", "alpha"))]
    point = np.dtype([("xyz", "<f4", 3), ("rgba", "u1", 4)])
    s = np.linspace(AXIS_LENGTH_M / AXIS_POINTS, AXIS_LENGTH_M, AXIS_POINTS)
    cloud = np.zeros(3 * AXIS_POINTS, dtype=point)
    cloud["xyz"] = np.concatenate([np.outer(s, np.eye(3)[k]) for k in range(3)])  # along x, y, z of the IMU
    cloud["rgba"] = np.repeat(np.array(_AXIS_RGBA, dtype=np.uint8), AXIS_POINTS, axis=0)
    msg = PointCloud_pb2.PointCloud(frame_id=name, point_stride=point.itemsize, fields=fields, data=cloud.tobytes())
    msg.pose.position.SetInParent()  # an empty Pose makes Rerun 0.41 write null translations
    msg.pose.orientation.w = 1.0
    from imulog.archive.wire import Rows

    stamps = np.asarray(log_map(stream.t_ns[keep]), dtype=np.int64)
    rows = Rows(len(stamps)).message(1, _timestamp(stamps)).raw(msg.SerializeToString())  # the rest never changes
    twin.set_rows(stamps.astype(np.uint64), *rows.build())
    return twin


TRAJECTORY_RATE_HZ = 10.0  # poses per second of a trajectory path twin


def trajectory_twin(
    stream: SignalStream, log_map: LogMap, clock: str, repetitions: list[Mapping[str, Any]] | None
) -> Twin:
    """``foxglove.PosesInFrame``: one message per repetition (at its start) holding its whole path (x, y, z).

    ``repetitions``: ``imulog.trajectory["repetitions"]`` (``start_ns``/``end_ns`` on the stream's clock);
    without them one message holds the whole channel. Poses at most :data:`TRAJECTORY_RATE_HZ`, orientation
    identity. Foxglove's 3D panel draws it as a path; Rerun 0.41 makes InstancePoses3D (not drawn by default).
    """
    from imulog.archive._generated.foxglove import PosesInFrame_pb2

    t = stream.t_ns
    spans = [(int(r["start_ns"]), int(r["end_ns"])) for r in repetitions or [] if "start_ns" in r and "end_ns" in r]
    if not spans and len(t):
        spans = [(int(t[0]), int(t[-1]))]
    twin = _protobuf_twin(
        twin_topic(stream.topic), "foxglove.PosesInFrame", {"twin_of": stream.topic, "clock": clock, "kind": "viewer"}
    )
    twin.metadata.update(sample_count=str(len(spans)), units="m", frame_id=stream.frame_id or "world")
    if len(t):
        twin.metadata.update(start_ns=str(int(t[0])), end_ns=str(int(t[-1])))
    xyz = stream.values[:, :3]
    for lo, hi in spans:
        i, j = int(np.searchsorted(t, lo)), int(np.searchsorted(t, hi, "right"))
        rows = np.arange(i, j)[decimation(t[i:j], TRAJECTORY_RATE_HZ)] if j > i else np.arange(0)
        rows = rows[np.isfinite(xyz[rows]).all(axis=1)]
        if not len(rows):
            continue
        msg = PosesInFrame_pb2.PosesInFrame(frame_id=stream.frame_id or "world")
        for x, y, z in xyz[rows].tolist():
            pose = msg.poses.add()
            pose.position.x, pose.position.y, pose.position.z = x, y, z
            pose.orientation.w = 1.0
        stamp = log_map.one(int(t[rows[0]]))
        _stamp(msg, stamp)
        twin.log_times.append(stamp)
        twin.payloads.append(msg.SerializeToString())
    return twin


def log_twin(stream: Intervals, log_map: LogMap, clock: str) -> Twin:
    """One ``foxglove.Log`` per interval, at its start: ``reach #3 (1.24 s)``."""
    from imulog.archive._generated.foxglove import Log_pb2

    twin = _protobuf_twin(
        twin_topic(stream.topic), "foxglove.Log", {"twin_of": stream.topic, "clock": clock, "kind": "viewer"}
    )
    twin.metadata["sample_count"] = str(len(stream))
    if len(stream):
        twin.metadata.update(start_ns=str(int(stream.start_ns.min())), end_ns=str(int(stream.end_ns.max())))
    stamps = log_map(stream.start_ns)
    name = stream.topic.rsplit("/", 1)[-1]
    for s, e, label, k, stamp in zip(
        stream.start_ns.tolist(),
        stream.end_ns.tolist(),
        stream.labels,
        stream.task_index.tolist(),
        stamps.tolist(),
        strict=True,
    ):
        rep = f" #{k}" if k >= 0 else ""
        msg = Log_pb2.Log(level=Log_pb2.Log.INFO, message=f"{label}{rep} ({(e - s) / 1e9:.2f} s)", name=name)
        _stamp(msg, stamp)
        twin.log_times.append(int(stamp))
        twin.payloads.append(msg.SerializeToString())
    return twin


def twins_for(
    stream: Stream,
    log_map: LogMap,
    clock: str,
    metadata: Mapping[str, Mapping[str, Any]] | None = None,
    origin: Origin | None = None,
) -> list[Twin]:
    """The viewer twins of one canonical stream (none for kinds without one, e.g. trajectories).

    ``clock``: ``"reference"`` or the IMU name whose device clock the stream is on; ``metadata``: the
    trial's records (``imulog.alignment`` rotates the IMU frames into the Vicon world); ``origin``: where an
    IMU frame sits (the Vicon cluster's position on the IMU's clock), else at the world origin.
    """
    if isinstance(stream, ImuStream):
        twin = imu_twin(stream, log_map)
        return [twin] if twin is not None else []
    if isinstance(stream, MarkerStream):
        return [marker_twin(stream, log_map)] if len(stream) else []
    if isinstance(stream, PoseStream):
        # a frame name unique in the trial (kinematics' "wrist" joint centre is not the IMU frame "wrist")
        child = "_".join(p for p in stream.topic.strip("/").split("/") if p != "derived")
        return [frame_twin(stream, log_map, parent=stream.frame_id or "world", child=child, clock=clock)]
    if (
        isinstance(stream, SignalStream)
        and stream.columns[:4] == ORIENTATION_COLUMNS
        and stream.topic.startswith("/derived/orientation/")
    ):
        return orientation_twins(stream, log_map, clock, metadata, origin)
    if isinstance(stream, Intervals) and len(stream):
        return [log_twin(stream, log_map, clock)]
    parts = stream.topic.strip("/").split("/")
    if (
        isinstance(stream, SignalStream)
        and parts[:2] == ["derived", "trajectory"]
        and stream.columns[:3] == ["x", "y", "z"]
    ):
        record = (metadata or {}).get("imulog.trajectory") or {}
        if len(parts) == 4:  # /derived/trajectory/METHOD/IMU: that IMU's record (imulog.trajectory.IMU)
            own = (metadata or {}).get(f"imulog.trajectory.{parts[3]}")
            record = own or (record if str(record.get("imu", "")).endswith(f"/{parts[3]}") else {})
        repetitions = record.get("repetitions")
        return [trajectory_twin(stream, log_map, clock, repetitions if isinstance(repetitions, list) else None)]
    return []


def orientation_twins(
    stream: SignalStream,
    log_map: LogMap,
    clock: str,
    metadata: Mapping[str, Mapping[str, Any]] | None = None,
    origin: Origin | None = None,
    keeps: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[Twin]:
    """The frame (world -> IMU) and axes twins of an orientation stream (``/derived/orientation/{imu}``).

    ``keeps``: the samples of ``stream`` each twin shows (frame, axes); default :func:`decimation` at
    :data:`TWIN_RATE_HZ` and :data:`AXES_RATE_HZ` (:mod:`imulog.archive.twin_blocks` passes the samples it
    kept of a long channel read block by block).
    """
    name = stream.topic.rstrip("/").rsplit("/", 1)[-1]
    alignment = (metadata or {}).get("imulog.alignment") or {}
    rotation = alignment.get("rotation_global_to_world")
    frame_keep, axes_keep = keeps if keeps is not None else (None, None)
    return [
        frame_twin(
            stream, log_map, parent="world", child=name, clock=clock, rotation=rotation, origin=origin, keep=frame_keep
        ),
        axes_twin(stream, log_map, clock=clock, keep=axes_keep),
    ]
