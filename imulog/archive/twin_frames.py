"""Twins drawn in 3D: marker point clouds, frame transforms (poses, orientations) and an IMU frame's axes.

Part of :mod:`imulog.archive.twins` (which re-exports these names).
"""

from __future__ import annotations

import numpy as np

from imulog.archive.timeline import LogMap
from imulog.archive.twin_rate import decimation
from imulog.archive.twin_record import TWIN_PREFIX, Twin, protobuf_twin, timestamp_message, twin_meta, twin_topic
from imulog.model import MarkerStream, PoseStream, SignalStream
from imulog.numeric import finite_rows

Origin = tuple[np.ndarray, np.ndarray]  # (t_ns on the stream's clock, (N, 3) positions in m)
AXIS_LENGTH_M = 0.12
AXIS_POINTS = 12
AXES_RATE_HZ = 5.0  # the axis points are constant (the transform moves them): a few repeats per second
_AXIS_RGBA = ((230, 40, 40, 255), (40, 190, 40, 255), (40, 90, 230, 255))  # x red, y green, z blue


def marker_twin(stream: MarkerStream, log_map: LogMap, keep: np.ndarray | None = None) -> Twin:
    """``foxglove.PointCloud`` of the valid markers; ``keep``: the samples shown (default :func:`decimation`)."""
    from imulog.archive._generated.foxglove import PackedElementField_pb2, PointCloud_pb2

    # positions as sampled: their content above the twin's Nyquist is < -46 dB
    keep = decimation(stream.t_ns) if keep is None else keep
    twin = protobuf_twin(
        twin_topic(stream.topic), "foxglove.PointCloud", twin_meta(stream, stream.topic, "reference", keep, stream.t_ns)
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
    rows = Rows(n).message(1, timestamp_message(stamps)).raw(msg.SerializeToString())  # fields 2-5: the same each time
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
    twin = protobuf_twin(
        twin_topic(stream.topic), "foxglove.FrameTransform", twin_meta(stream, stream.topic, clock, keep, stream.t_ns)
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
    rows = Rows(n).message(1, timestamp_message(stamps)).raw(names).message(4, translation).message(5, rotation)
    twin.set_rows(stamps.astype(np.uint64), *rows.build())
    return twin


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
    twin = protobuf_twin(
        f"{TWIN_PREFIX}/axes/{name}", "foxglove.PointCloud", twin_meta(stream, stream.topic, clock, keep, stream.t_ns)
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
    # the rest of the message never changes
    rows = Rows(len(stamps)).message(1, timestamp_message(stamps)).raw(msg.SerializeToString())
    twin.set_rows(stamps.astype(np.uint64), *rows.build())
    return twin
