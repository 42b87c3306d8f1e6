"""Encode imulog.model streams as protobuf messages and decode them back, columnar and bit-exact.

High-rate streams (IMU, markers, analog, signals, poses) become one block message per ~1 s window whose
arrays are packed repeated numeric fields (``repeated sfixed64 t_ns``, ``repeated double``, ``repeated
bool``): any protobuf reader gets numbers, and the packed bytes are little-endian arrays, so blocks are
written by joining array bytes (:mod:`imulog.archive.wire`) and decoded by joining the raw field bytes of
all blocks once and viewing them with ``numpy.frombuffer`` (no per-sample Python objects). The wire bytes
equal those of the older ``bytes`` fields, so files written before the change read unchanged. Intervals
are one ``imulog.IntervalEvent`` per interval. Poses written by older imulog (one ``foxglove.PoseInFrame``
per sample) still decode. Message log times come from a :class:`~imulog.archive.timeline.LogMap` (the
trial's one time axis); the payload keeps the samples' own clock.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import numpy as np
from google.protobuf import descriptor_pb2

from imulog.archive import numbers, wire
from imulog.archive._generated.imulog import (
    IntervalEvent_pb2,
)
from imulog.archive.block_encode import (
    BLOCK_NS,  # noqa: F401 (re-exported: codec.BLOCK_NS)
    SCHEMA_VERSION,
    SCHEMA_VERSION_V1,
    Layout,
    block_bounds,  # noqa: F401 (re-exported)
    encode_blocks,
    strings_field,
)
from imulog.archive.block_schemas import (  # noqa: F401 (re-exported)
    BLOCK_SCHEMAS,
    KIND_SCHEMA,
    MESSAGE_CLASSES,
    SCHEMA_KIND,
    DecodeError,
)
from imulog.archive.timeline import IDENTITY, LogMap
from imulog.model import AnalogStream, ImuStream, Intervals, MarkerStream, PoseStream, SignalStream, Stream
from imulog.numeric import median_int

# SCHEMA_VERSION: newest layout version written (blocks with Numbers or compact times); readers accept <= this.
# SCHEMA_VERSION_V1: blocks using only the fields of the first layout keep writing 1 (readable by older imulog).
# BLOCK_NS: block length: samples are grouped in windows of 1 s.

_I8 = np.dtype("<i8")
_F8 = np.dtype("<f8")
_U1 = np.dtype("u1")
_MAX_LOG_TIME = 2**64 - 1


def _twin_classes() -> dict[str, Any]:
    """Foxglove schemas of the viewer twins (:mod:`imulog.archive.twins`): embedded, never decoded to streams."""
    from imulog.archive._generated.foxglove import FrameTransform_pb2, Log_pb2, PointCloud_pb2, PosesInFrame_pb2

    return {
        "foxglove.PosesInFrame": PosesInFrame_pb2.PosesInFrame,
        "foxglove.PointCloud": PointCloud_pb2.PointCloud,
        "foxglove.FrameTransform": FrameTransform_pb2.FrameTransform,
        "foxglove.Log": Log_pb2.Log,
    }


def file_descriptor_set(schema_name: str) -> bytes:
    """Serialized ``google.protobuf.FileDescriptorSet`` for a schema: its file and all dependencies."""
    cls = MESSAGE_CLASSES.get(schema_name) or _twin_classes()[schema_name]
    descriptor = cls.DESCRIPTOR.file
    ordered: list[Any] = []
    seen: set[str] = set()

    def visit(fd: Any) -> None:
        if fd.name in seen:
            return
        seen.add(fd.name)
        for dep in fd.dependencies:
            visit(dep)
        ordered.append(fd)

    visit(descriptor)
    fds = descriptor_pb2.FileDescriptorSet()
    for fd in ordered:
        fds.file.add().ParseFromString(fd.serialized_pb)
    return fds.SerializeToString(deterministic=True)


def stream_kind(stream: Stream) -> str:
    for kind, cls in (
        ("imu", ImuStream),
        ("markers", MarkerStream),
        ("analog", AnalogStream),
        ("signal", SignalStream),
        ("intervals", Intervals),
        ("pose", PoseStream),
    ):
        if isinstance(stream, cls):
            return kind
    raise TypeError(f"not an imulog.model stream: {type(stream).__name__}")


def log_time(t_ns: int) -> int:
    """MCAP log times are unsigned: negative device times are clamped to 0 (the payload keeps the truth)."""
    return min(max(int(t_ns), 0), _MAX_LOG_TIME)


def channel_log_time(channel_meta: dict[str, str], t_ns: int) -> int:
    """The log time at which a channel's sample time ``t_ns`` sits (its ``log_time`` map; identity for old files)."""
    return LogMap.from_meta(channel_meta).one(t_ns)


def _stats(t_ns: np.ndarray, values: list[np.ndarray | None]) -> dict[str, str]:
    """Channel metadata describing the samples: count, span, rate, gaps (time gaps and NaN samples)."""
    n = len(t_ns)
    out = {"sample_count": str(n)}
    if n:
        out["start_ns"] = str(int(t_ns[0]))
        out["end_ns"] = str(int(t_ns[-1]))
    if n > 1:
        dt = np.diff(t_ns)
        median = median_int(dt)
        out["rate_hz"] = f"{1e9 / median:.6g}" if median > 0 else "0"
        out["time_gaps"] = str(int(np.count_nonzero(dt > 1.5 * median))) if median > 0 else "0"
    arrays = [v for v in values if v is not None]
    if arrays and n:
        out["nan_samples"] = str(nan_samples(n, arrays))
    return out


def nan_samples(n: int, arrays: list[np.ndarray]) -> int:
    """How many of ``n`` samples have a non-finite value in any of ``arrays`` (each with n rows)."""
    bad = [np.asarray(v).reshape(n, -1) for v in arrays]
    bad = [v for v in bad if not np.isfinite(v).all()]  # one fast pass each: most channels have no gap
    if not bad:
        return 0
    finite = np.ones(n, dtype=bool)
    for v in bad:
        finite &= np.isfinite(v).all(axis=1)
    return int(n - np.count_nonzero(finite))


def encode(
    stream: Stream, log_map: LogMap = IDENTITY, *, compact: bool = True
) -> tuple[str, dict[str, str], list[int], list[bytes]]:
    """-> (schema name, channel metadata, log times, serialized messages) for one stream.

    ``log_map`` places the messages on the trial's time axis (:mod:`imulog.archive.timeline`); the
    default keeps log time = sample time (clamped at 0), the layout of files written before the axis.
    Arrays are stored at their source's resolution and evenly spread times as start plus span where that
    gives the values back exactly (:mod:`imulog.archive.numbers`); such blocks carry schema_version 2.
    ``compact=False`` writes the layout of schema_version 1 (float64 arrays, explicit times: the benchmarks' peer).
    """
    kind = stream_kind(stream)
    meta: dict[str, str] = {"kind": kind, "schema_version": str(SCHEMA_VERSION)}
    if log_map is not IDENTITY:
        meta["log_time"] = log_map.to_meta()
    st = wire.string_field
    if kind == "imu":
        assert isinstance(stream, ImuStream)
        fields = [(f, getattr(stream, f)) for f in ("acc", "gyr", "mag", "temperature")]
        present = [f for f, a in fields if a is not None]
        units = {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT", "temperature": "degC"}
        meta.update(
            name=stream.name,
            frame_id=stream.frame_id,
            columns=json.dumps(present),
            units=json.dumps([units[f] for f in present]),
            meta=json.dumps(stream.meta, sort_keys=True, default=str),
            source=str(stream.meta.get("source", "")),
        )
        meta.update(_stats(stream.t_ns, [a for _, a in fields]))
        hints, precision = _hints(stream.meta)
        arrays = [(6 + k, 13 + k, a, hints.get(f)) for k, (f, a) in enumerate(fields)]
        layout = Layout(st(2, stream.name) + st(3, stream.frame_id), 4, 5, (10, 11, 12), arrays, precision)
    elif kind == "markers":
        assert isinstance(stream, MarkerStream)
        meta.update(
            name=stream.name,
            frame_id=stream.frame_id,
            labels=json.dumps(stream.labels),
            units="m",
            meta=json.dumps(stream.meta, sort_keys=True, default=str),
            source=str(stream.meta.get("source", "")),
        )
        meta.update(_stats(stream.t_ns, [stream.pos]))
        valid = np.asarray(stream.valid, dtype=bool)
        hints, precision = _hints(stream.meta)
        n, m_ = len(stream.t_ns), len(stream.labels)
        pos = raw_pos = stream.pos.reshape(n, 3 * m_)  # (N, 3M): also without samples (a stream with none yet)
        valid = valid.reshape(n, m_)
        if compact:  # an invalid marker stored as 0 (counts, decimals, float32), read back as NaN by its valid flag
            pos = np.where(np.repeat(valid, 3, axis=1), pos, 0.0)
        layout = Layout(
            st(2, stream.frame_id) + strings_field(3, stream.labels),
            4,
            5,
            (8, 9, 10),
            [(6, 11, pos, hints.get("pos"))],
            precision,
            extra=[(7, valid, _U1)],
            f64_values={6: raw_pos},  # a block left as float64 keeps NaN at invalid samples, as layout 1
        )
    elif kind in ("analog", "signal"):
        if isinstance(stream, AnalogStream):
            names, extra = stream.channel_names, {"name": stream.name, "frame_id": ""}
            extra.update(
                meta=json.dumps(stream.meta, sort_keys=True, default=str), source=str(stream.meta.get("source", ""))
            )
            second = st(2, stream.name)
            hints, precision = _hints(stream.meta)
        else:
            assert isinstance(stream, SignalStream)
            names, extra = stream.columns, {**stream.attrs, "frame_id": stream.frame_id}
            second = st(2, stream.frame_id)
            precision = str(stream.attrs.get("precision", ""))
            hint = numbers.signal_hint(stream.attrs)
            hints = {"values": hint} if hint else {}
        meta.update(extra, columns=json.dumps(list(names)), units=json.dumps(list(stream.units)))
        meta.update(_stats(stream.t_ns, [stream.values]))
        head = second + strings_field(3, names) + strings_field(4, stream.units)
        layout = Layout(head, 5, 6, (8, 9, 10), [(7, 11, stream.values, hints.get("values"))], precision)
    elif kind == "intervals":
        assert isinstance(stream, Intervals)
        meta.update(frame_id="", units="ns", sample_count=str(len(stream)))
        if len(stream):
            meta.update(start_ns=str(int(stream.start_ns.min())), end_ns=str(int(stream.end_ns.max())))
        payloads = []
        for s, e, label, k in zip(
            stream.start_ns.tolist(), stream.end_ns.tolist(), stream.labels, stream.task_index.tolist(), strict=True
        ):
            msg = IntervalEvent_pb2.IntervalEvent(
                schema_version=SCHEMA_VERSION_V1, start_ns=s, end_ns=e, label=label, task_index=k
            )
            payloads.append(msg.SerializeToString())
        times = log_map(stream.start_ns).tolist()
        return KIND_SCHEMA[kind], meta, times, payloads
    else:
        assert isinstance(stream, PoseStream)
        meta.update(frame_id=stream.frame_id, units="m", columns=json.dumps(["x", "y", "z", "qw", "qx", "qy", "qz"]))
        meta.update(_stats(stream.t_ns, [stream.position, stream.orientation]))
        precision = stream.precision
        if precision:
            meta["precision"] = precision
        arrays = [(5, 10, stream.position, None), (6, 11, stream.orientation, None)]
        layout = Layout(st(2, stream.frame_id), 3, 4, (7, 8, 9), arrays, precision)
    layout.compact = compact
    starts, payloads = encode_blocks(stream.t_ns, layout)
    times = log_map(stream.t_ns[starts]).tolist() if starts else []
    return KIND_SCHEMA[kind], meta, times, payloads


def _hints(meta: dict[str, Any]) -> tuple[dict[str, Any], str]:
    """The converter's ``resolution`` hints (field -> shift/divisor/scale/offset) and a ``precision`` request."""
    res = meta.get("resolution") if isinstance(meta, dict) else None
    return (res if isinstance(res, dict) else {}), str(meta.get("precision", "")) if isinstance(meta, dict) else ""


# --------------------------------------------------------------------------------------------- decoding


def decode(schema_name: str, topic: str, meta: dict[str, str], payloads: Sequence[bytes | memoryview]) -> Stream:
    """Rebuild the imulog.model stream of one channel from its messages (in log order):
    :func:`imulog.archive.codec_decode.decode`."""
    from imulog.archive import codec_decode

    return codec_decode.decode(schema_name, topic, meta, payloads)


def stream_topic(stream: Stream) -> str:
    return stream.topic


def select_time(stream: Stream, start_ns: int | None, end_ns: int | None) -> Stream:
    """Samples with ``start_ns <= t < end_ns`` (intervals: those overlapping that range)."""
    if start_ns is None and end_ns is None:
        return stream
    lo = -(2**63) if start_ns is None else int(start_ns)
    hi = 2**63 - 1 if end_ns is None else int(end_ns)
    if isinstance(stream, Intervals):
        keep = (stream.end_ns >= lo) & (stream.start_ns < hi)
        return Intervals(
            topic=stream.topic,
            start_ns=stream.start_ns[keep],
            end_ns=stream.end_ns[keep],
            labels=[label for label, k in zip(stream.labels, keep, strict=True) if k],
            task_index=stream.task_index[keep],
        )
    t = stream.t_ns
    if len(t) < 2 or bool(np.all(t[1:] >= t[:-1])):
        i, j = int(np.searchsorted(t, lo, "left")), int(np.searchsorted(t, hi, "left"))
        rows: slice | np.ndarray = slice(i, j)
    else:  # a clock that jumps back (device reset): select sample by sample
        rows = np.flatnonzero((t >= lo) & (t < hi))
    if isinstance(stream, ImuStream):
        return ImuStream(
            name=stream.name,
            t_ns=t[rows],
            acc=None if stream.acc is None else stream.acc[rows],
            gyr=None if stream.gyr is None else stream.gyr[rows],
            mag=None if stream.mag is None else stream.mag[rows],
            temperature=None if stream.temperature is None else stream.temperature[rows],
            frame_id=stream.frame_id,
            meta=stream.meta,
        )
    if isinstance(stream, MarkerStream):
        return MarkerStream(
            name=stream.name,
            t_ns=t[rows],
            labels=stream.labels,
            pos=stream.pos[rows],
            valid=stream.valid[rows],
            frame_id=stream.frame_id,
            meta=stream.meta,
        )
    if isinstance(stream, AnalogStream):
        return AnalogStream(stream.name, t[rows], stream.channel_names, stream.units, stream.values[rows], stream.meta)
    if isinstance(stream, SignalStream):
        return SignalStream(stream.topic, t[rows], stream.columns, stream.units, stream.values[rows], stream.frame_id)
    assert isinstance(stream, PoseStream)
    return PoseStream(stream.topic, t[rows], stream.position[rows], stream.orientation[rows], stream.frame_id)
