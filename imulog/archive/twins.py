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

The module is split by concern: :mod:`imulog.archive.twin_record` (the :class:`Twin` record, topics, shared
message pieces), :mod:`~imulog.archive.twin_rate` (which samples a twin keeps), :mod:`~imulog.archive.twin_imu`
(the ROS 2 IMU twin) and :mod:`~imulog.archive.twin_frames` (point clouds, frame transforms, axes); this module
builds the trajectory and event twins and picks a stream's twins (:func:`twins_for`), and re-exports the rest.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from imulog.archive.timeline import LogMap
from imulog.archive.twin_frames import (
    AXES_RATE_HZ,
    AXIS_LENGTH_M,
    AXIS_POINTS,
    Origin,
    axes_twin,
    frame_twin,
    marker_twin,
)
from imulog.archive.twin_imu import (
    ROS_IMU_SCHEMA,
    imu_twin,
    ros_imu_payloads,
    ros_imu_rows,
)
from imulog.archive.twin_rate import (
    MAX_TWIN_MESSAGES,
    OVERVIEW_AFTER_S,
    OVERVIEW_EPOCH_S,
    TWIN_RATE_HZ,
    decimated,
    decimation,
    decimation_step,
    overview_step,
)
from imulog.archive.twin_record import (
    ORIENTATION_COLUMNS,
    TWIN_PREFIX,
    Twin,
    is_twin,
    protobuf_twin,
    set_stamp,
    twin_topic,
)
from imulog.model import ImuStream, Intervals, MarkerStream, PoseStream, SignalStream, Stream

__all__ = [
    "AXES_RATE_HZ",
    "axes_twin",
    "AXIS_LENGTH_M",
    "AXIS_POINTS",
    "decimated",
    "decimation",
    "decimation_step",
    "frame_twin",
    "imu_twin",
    "is_twin",
    "log_twin",
    "marker_twin",
    "MAX_TWIN_MESSAGES",
    "ORIENTATION_COLUMNS",
    "orientation_twins",
    "Origin",
    "OVERVIEW_AFTER_S",
    "OVERVIEW_EPOCH_S",
    "overview_step",
    "ros_imu_payloads",
    "ros_imu_rows",
    "ROS_IMU_SCHEMA",
    "TRAJECTORY_RATE_HZ",
    "trajectory_twin",
    "Twin",
    "TWIN_PREFIX",
    "TWIN_RATE_HZ",
    "twin_topic",
    "twins_for",
]

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
    twin = protobuf_twin(
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
        set_stamp(msg, stamp)
        twin.log_times.append(stamp)
        twin.payloads.append(msg.SerializeToString())
    return twin


def log_twin(stream: Intervals, log_map: LogMap, clock: str) -> Twin:
    """One ``foxglove.Log`` per interval, at its start: ``reach #3 (1.24 s)``."""
    from imulog.archive._generated.foxglove import Log_pb2

    twin = protobuf_twin(
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
        set_stamp(msg, stamp)
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
