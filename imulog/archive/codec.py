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

from imulog.archive import block_decode, numbers, wire
from imulog.archive._generated.foxglove import PoseInFrame_pb2
from imulog.archive._generated.imulog import (
    AnalogBlock_pb2,
    ImuBlock_pb2,
    IntervalEvent_pb2,
    MarkerBlock_pb2,
    PoseBlock_pb2,
    SignalBlock_pb2,
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
from imulog.archive.timeline import IDENTITY, LogMap
from imulog.model import AnalogStream, ImuStream, Intervals, MarkerStream, PoseStream, SignalStream, Stream

# SCHEMA_VERSION: newest layout version written (blocks with Numbers or compact times); readers accept <= this.
# SCHEMA_VERSION_V1: blocks using only the fields of the first layout keep writing 1 (readable by older imulog).
# BLOCK_NS: block length: samples are grouped in windows of 1 s.

MESSAGE_CLASSES = {
    "imulog.ImuBlock": ImuBlock_pb2.ImuBlock,
    "imulog.MarkerBlock": MarkerBlock_pb2.MarkerBlock,
    "imulog.AnalogBlock": AnalogBlock_pb2.AnalogBlock,
    "imulog.SignalBlock": SignalBlock_pb2.SignalBlock,
    "imulog.IntervalEvent": IntervalEvent_pb2.IntervalEvent,
    "imulog.PoseBlock": PoseBlock_pb2.PoseBlock,
    "foxglove.PoseInFrame": PoseInFrame_pb2.PoseInFrame,  # poses of files written before PoseBlock
}
KIND_SCHEMA = {
    "imu": "imulog.ImuBlock",
    "markers": "imulog.MarkerBlock",
    "analog": "imulog.AnalogBlock",
    "signal": "imulog.SignalBlock",
    "intervals": "imulog.IntervalEvent",
    "pose": "imulog.PoseBlock",
}
SCHEMA_KIND = {**{v: k for k, v in KIND_SCHEMA.items()}, "foxglove.PoseInFrame": "pose"}
BLOCK_SCHEMAS = (
    "imulog.ImuBlock",
    "imulog.MarkerBlock",
    "imulog.AnalogBlock",
    "imulog.SignalBlock",
    "imulog.PoseBlock",
)
_I8 = np.dtype("<i8")
_F8 = np.dtype("<f8")
_U1 = np.dtype("u1")
_MAX_LOG_TIME = 2**64 - 1


class DecodeError(ValueError):
    """A message could not be decoded into the stream type its schema promises."""


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
        median = float(np.median(dt))
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
        n = len(stream.t_ns)
        pos = stream.pos.reshape(n, -1)
        layout = Layout(
            st(2, stream.frame_id) + strings_field(3, stream.labels),
            4,
            5,
            (8, 9, 10),
            [(6, 11, pos, hints.get("pos"))],
            precision,
            extra=[(7, valid.reshape(n, -1), _U1)],
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
            hints, precision = {}, str(stream.attrs.get("precision", ""))
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
        precision = ""
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


def _join(parts: list[bytes], dtype: np.dtype, width: int, n: int, what: str) -> np.ndarray:
    buf = bytearray().join(parts)
    if len(buf) != n * width * dtype.itemsize:
        raise DecodeError(f"{what}: {len(buf)} bytes for {n} samples x {width} values")
    a = np.frombuffer(buf, dtype=dtype).astype(dtype.newbyteorder("="), copy=False)
    return a.reshape(n, width) if width != 1 else a


def _check_version(msg: Any, schema_name: str) -> None:
    if msg.schema_version > SCHEMA_VERSION:
        raise DecodeError(
            f"{schema_name} schema_version {msg.schema_version} is newer than this imulog understands "
            f"({SCHEMA_VERSION}); upgrade imulog"
        )


class _Block:
    """Attribute bag with the fields of one block message; array fields are zero-copy memoryviews."""


_PACKED = {}  # protobuf field type -> numpy dtype of its packed wire form
_NO_MESSAGE = object()  # default of an absent sub-message field


def _block_specs(cls: Any) -> tuple[dict[int, tuple[str, str]], dict[str, Any]]:
    from google.protobuf.descriptor import FieldDescriptor as FD

    if not _PACKED:
        _PACKED.update({FD.TYPE_SFIXED64: _I8, FD.TYPE_DOUBLE: _F8, FD.TYPE_BOOL: _U1})
    spec, defaults = {}, {}
    for f in cls.DESCRIPTOR.fields:
        if f.type == FD.TYPE_BYTES or (f.is_repeated and f.type in (*_PACKED, FD.TYPE_SINT64)):
            kind, default = ("bool" if f.type == FD.TYPE_BOOL else "array"), b""
        elif f.type == FD.TYPE_SINT64:
            kind, default = "svarint", 0
        elif f.type == FD.TYPE_MESSAGE:
            kind, default = "message", _NO_MESSAGE
        elif f.type == FD.TYPE_STRING:
            kind, default = ("rstring", None) if f.is_repeated else ("string", "")
        elif f.type in (FD.TYPE_UINT32, FD.TYPE_UINT64):
            kind, default = "varint", 0
        else:  # pragma: no cover - the block schemas have no other field types
            raise TypeError(f"unexpected field type in {cls.DESCRIPTOR.full_name}.{f.name}")
        spec[f.number] = (f.name, kind)
        defaults[f.name] = default
    return spec, defaults


_BLOCK_SPECS = {name: _block_specs(MESSAGE_CLASSES[name]) for name in BLOCK_SCHEMAS}
_SCALAR_DEFAULTS = {
    name: {k: (None if d is _NO_MESSAGE else d) for k, d in spec[1].items() if d is not None}
    for name, spec in _BLOCK_SPECS.items()
}
_LIST_FIELDS = {name: [k for k, d in spec[1].items() if d is None] for name, spec in _BLOCK_SPECS.items()}


def _scan_block(schema_name: str, payload: bytes | memoryview) -> _Block:
    """Parse a block message's wire format directly, keeping packed arrays as views (no copies).

    Raises :class:`wire.Fallback` for what it does not handle: unpacked repeated values (legal protobuf
    from another writer), bools that are not one byte 0/1, malformed input.
    """
    spec, defaults = _BLOCK_SPECS[schema_name]
    obj = _Block()
    fields = obj.__dict__
    fields.update(_SCALAR_DEFAULTS[schema_name])  # one call: the blocks have up to 16 fields
    for name in _LIST_FIELDS[schema_name]:
        fields[name] = []
    try:
        for number, wire_type, value in wire.scan(payload):
            field = spec.get(number)
            if field is None:
                continue  # unknown field (a newer writer): ignored, as protobuf does
            name, kind = field
            if kind in ("varint", "svarint"):
                if wire_type != wire.WIRE_VARINT:
                    raise wire.Fallback
                setattr(obj, name, value if kind == "varint" else (value >> 1) ^ -(value & 1))
            elif wire_type != wire.WIRE_LEN:
                raise wire.Fallback
            elif kind in ("array", "message"):
                setattr(obj, name, value)
            elif kind == "bool":
                if len(value) and int(np.frombuffer(value, _U1).max()) > 1:
                    raise wire.Fallback
                setattr(obj, name, value)
            elif kind == "string":
                setattr(obj, name, str(value, "utf-8"))
            else:
                getattr(obj, name).append(str(value, "utf-8"))
    except UnicodeDecodeError:
        raise wire.Fallback from None
    return obj


def _as_block(schema_name: str, msg: Any) -> _Block:
    """A block parsed by protobuf (the slow path) as a :class:`_Block` with packed array bytes."""
    from google.protobuf.descriptor import FieldDescriptor as FD

    obj = _Block()
    for f in msg.DESCRIPTOR.fields:
        value = getattr(msg, f.name)
        if f.is_repeated and f.type in _PACKED:
            value = np.asarray(list(value), dtype=_PACKED[f.type]).tobytes()
        elif f.is_repeated and f.type == FD.TYPE_SINT64:
            value = wire.zigzag_varints(np.asarray(list(value), dtype=np.int64))[0]
        elif f.type == FD.TYPE_MESSAGE:
            value = value.SerializeToString() if msg.HasField(f.name) else None
        elif f.type == FD.TYPE_STRING and f.is_repeated:
            value = list(value)
        setattr(obj, f.name, value)
    return obj


def _parse_all(schema_name: str, payloads: Sequence[bytes | memoryview]) -> list[Any]:
    cls = MESSAGE_CLASSES[schema_name]
    fast = schema_name in _BLOCK_SPECS
    out = []
    for p in payloads:
        if fast:
            try:
                out.append(_scan_block(schema_name, p))
                continue
            except wire.Fallback:
                pass
        try:
            msg = cls.FromString(bytes(p))
        except Exception as exc:  # protobuf raises DecodeError subclasses of Exception
            raise DecodeError(f"message {len(out)} does not parse as {schema_name}: {exc}") from exc
        out.append(_as_block(schema_name, msg) if fast else msg)
    return out


def _json_meta(meta: dict[str, str], key: str, default: Any) -> Any:
    try:
        return json.loads(meta[key])
    except (KeyError, ValueError):
        return default


def _numbers_fields(payload: Any) -> dict[str, Any]:
    try:
        return numbers.scan_numbers(payload)
    except wire.Fallback:
        from imulog.archive._generated.imulog import Numbers_pb2

        try:
            msg = Numbers_pb2.Numbers.FromString(bytes(payload))
        except Exception as exc:  # protobuf raises DecodeError subclasses of Exception
            raise DecodeError(f"a Numbers field does not parse: {exc}") from exc
        out: dict[str, Any] = {"counts": np.asarray(list(msg.counts), dtype="<i4").tobytes()}
        out["f32"] = np.asarray(list(msg.f32), dtype="<f4").tobytes()
        out["decimals"] = wire.zigzag_varints(np.asarray(list(msg.decimals), dtype=np.int64))[0]
        for p in numbers.PARAMS:
            values = list(getattr(msg, p))
            out[p] = np.asarray(values, dtype="<f8").tobytes() if values else None
        return out


def _array(
    msgs: list[Any], f: str, counts: np.ndarray, width: int, topic: str, *, required: bool = False
) -> np.ndarray | None:
    """(N, width) float64 of field ``f`` over all blocks: float64 bytes or ``f_q`` Numbers, mixed per block."""
    qs = [getattr(msg, f + "_q", None) for msg in msgs]
    if all(q is not None for q in qs):  # every block at the same resolution: its parameters parsed once
        fast = numbers.numbers_sources(qs)
        if fast is not None and not any(len(getattr(msg, f)) for msg in msgs):
            try:
                return numbers.decode_numbers([("q", x) for x in fast], counts, width, f"{topic} {f}")
            except ValueError as exc:
                raise DecodeError(str(exc)) from None
    sources: list[tuple[str, Any]] = []
    for msg, c in zip(msgs, counts.tolist(), strict=True):
        raw = getattr(msg, f)
        q = getattr(msg, f + "_q", None)
        if len(raw):
            sources.append(("f64", raw))
        elif q is not None:
            sources.append(("q", _numbers_fields(q)))
        else:
            sources.append(("none" if c or not required else "f64", b""))
    if not required and all(k == "none" for k, _ in sources):
        return None
    if not required and any(k == "none" and c for (k, _), c in zip(sources, counts.tolist(), strict=True)):
        raise DecodeError(f"{topic}: field {f} present in some blocks only")
    try:
        return numbers.decode_numbers(sources, counts, width, f"{topic} {f}")
    except ValueError as exc:
        raise DecodeError(str(exc)) from None


def decode(schema_name: str, topic: str, meta: dict[str, str], payloads: Sequence[bytes | memoryview]) -> Stream:
    """Rebuild the imulog.model stream of one channel from its messages (in log order)."""
    if schema_name not in MESSAGE_CLASSES:
        raise DecodeError(f"{topic}: schema {schema_name!r} is not an imulog stream type")
    kind = SCHEMA_KIND[schema_name]
    name = meta.get("name") or topic.rstrip("/").rsplit("/", 1)[-1]
    if schema_name in BLOCK_SCHEMAS:
        fast = _decode_columns(schema_name, kind, name, topic, meta, payloads)
        if fast is not None:
            return fast
    msgs = _parse_all(schema_name, payloads)
    if schema_name in BLOCK_SCHEMAS:
        for msg in msgs:
            _check_version(msg, schema_name)
        counts = [msg.count for msg in msgs]
        n = int(sum(counts))
        counts_a = np.asarray(counts, dtype=np.int64)
        try:
            t = numbers.decode_times(msgs, counts_a, topic)
        except ValueError as exc:
            raise DecodeError(str(exc)) from None
    if kind == "imu":
        columns = _json_meta(meta, "columns", None)
        values: dict[str, np.ndarray | None] = {}
        for f, width in (("acc", 3), ("gyr", 3), ("mag", 3), ("temperature", 1)):
            if msgs:
                a = _array(msgs, f, counts_a, width, topic)
                values[f] = None if a is None else (a if width > 1 else a.reshape(n))
            else:
                values[f] = np.zeros((0, width) if width > 1 else 0) if columns is not None and f in columns else None
        return ImuStream(
            name=name,
            t_ns=t,
            frame_id=meta.get("frame_id", ""),
            meta=_json_meta(meta, "meta", {}),
            **values,
        )
    if kind == "markers":
        labels = list(msgs[0].labels) if msgs else _json_meta(meta, "labels", [])
        for msg in msgs:
            if list(msg.labels) != labels:
                raise DecodeError(f"{topic}: marker labels change between blocks")
        m = len(labels)
        pos = _array(msgs, "pos", counts_a, m * 3, topic, required=True).reshape(n, m, 3)
        valid = _join([msg.valid for msg in msgs], _U1, m, n, f"{topic} valid").reshape(n, m).astype(bool)
        return MarkerStream(
            name=name,
            t_ns=t,
            labels=labels,
            pos=pos,
            valid=valid,
            frame_id=msgs[0].frame_id if msgs else meta.get("frame_id", "world"),
            meta=_json_meta(meta, "meta", {}),
        )
    if kind in ("analog", "signal"):
        if msgs:
            names = list(msgs[0].channel_names if kind == "analog" else msgs[0].columns)
            units = list(msgs[0].units)
        else:
            names, units = _json_meta(meta, "columns", []), _json_meta(meta, "units", [])
        values = _array(msgs, "values", counts_a, len(names), topic, required=True).reshape(n, len(names))
        if kind == "analog":
            return AnalogStream(
                name=name, t_ns=t, channel_names=names, units=units, values=values, meta=_json_meta(meta, "meta", {})
            )
        frame = msgs[0].frame_id if msgs else meta.get("frame_id", "")
        return SignalStream(topic=topic, t_ns=t, columns=names, units=units, values=values, frame_id=frame)
    if kind == "intervals":
        for msg in msgs:
            _check_version(msg, schema_name)
        return Intervals(
            topic=topic,
            start_ns=np.array([msg.start_ns for msg in msgs], dtype=np.int64),
            end_ns=np.array([msg.end_ns for msg in msgs], dtype=np.int64),
            labels=[msg.label for msg in msgs],
            task_index=np.array([msg.task_index for msg in msgs], dtype=np.int64),
        )
    frame = msgs[0].frame_id if msgs else meta.get("frame_id", "world")
    if schema_name == "imulog.PoseBlock":
        position = _array(msgs, "position", counts_a, 3, topic, required=True)
        orientation = _array(msgs, "orientation", counts_a, 4, topic, required=True)
        return PoseStream(topic=topic, t_ns=t, position=position, orientation=orientation, frame_id=frame)
    return _decode_pose_in_frame(topic, msgs, frame)


_NUMBER = {name: {f[0]: k for k, f in spec[0].items()} for name, spec in _BLOCK_SPECS.items()}


def _decode_columns(
    schema_name: str, kind: str, name: str, topic: str, meta: dict[str, str], payloads: Sequence[bytes | memoryview]
) -> Stream | None:
    """:func:`decode` of many blocks in the common layouts (:mod:`imulog.archive.block_decode`), else None."""
    no = _NUMBER[schema_name]
    c = block_decode.columns(payloads, _BLOCK_SPECS[schema_name][0])
    if c is None:
        return None
    try:
        first = _scan_block(schema_name, payloads[0])  # the strings: the same in every block (checked)
    except wire.Fallback:
        return None
    _check_version(_Version(int(c.value[:, 1].max())), schema_name)
    counts = c.value[:, no["count"]]
    if bool((counts < 0).any()):
        return None
    n = int(counts.sum())
    t = block_decode.times(c, no["t_ns"], no["t0_ns"], no["t_span_ns"], no["t_residual_ns"], counts, topic)
    if t is None:
        return None

    def arr(f: str, width: int, required: bool = True) -> tuple[bool, np.ndarray | None] | None:
        return block_decode.array(c, no[f], no.get(f + "_q"), counts, width, required)

    if kind == "imu":
        values: dict[str, np.ndarray | None] = {}
        for f, width in (("acc", 3), ("gyr", 3), ("mag", 3), ("temperature", 1)):
            got = arr(f, width, required=False)
            if got is None:
                return None
            values[f] = got[1] if got[1] is None or width > 1 else got[1].reshape(n)
        return ImuStream(
            name=name, t_ns=t, frame_id=meta.get("frame_id", ""), meta=_json_meta(meta, "meta", {}), **values
        )
    if kind == "markers":
        labels = list(first.labels)
        got = arr("pos", len(labels) * 3)
        raw = c.gather(no["valid"])
        if got is None or len(raw) != n * len(labels) or (len(raw) and int(raw.max()) > 1):
            return None
        return MarkerStream(
            name=name,
            t_ns=t,
            labels=labels,
            pos=got[1].reshape(n, len(labels), 3),
            valid=raw.reshape(n, len(labels)).astype(bool),
            frame_id=first.frame_id,
            meta=_json_meta(meta, "meta", {}),
        )
    if kind in ("analog", "signal"):
        names = list(first.channel_names if kind == "analog" else first.columns)
        got = arr("values", len(names))
        if got is None:
            return None
        values_a = got[1].reshape(n, len(names))
        if kind == "analog":
            return AnalogStream(name, t, names, list(first.units), values_a, _json_meta(meta, "meta", {}))
        return SignalStream(topic, t, names, list(first.units), values_a, first.frame_id)
    position, orientation = arr("position", 3), arr("orientation", 4)
    if position is None or orientation is None:
        return None
    return PoseStream(topic=topic, t_ns=t, position=position[1], orientation=orientation[1], frame_id=first.frame_id)


class _Version:
    def __init__(self, version: int) -> None:
        self.schema_version = version


def _decode_pose_in_frame(topic: str, msgs: list[Any], frame: str) -> PoseStream:
    """Poses of files written before PoseBlock: one ``foxglove.PoseInFrame`` per sample."""
    n = len(msgs)
    t = np.fromiter((msg.timestamp.seconds * 1_000_000_000 + msg.timestamp.nanos for msg in msgs), np.int64, n)
    arr = np.fromiter(
        (
            v
            for msg in msgs
            for v in (
                msg.pose.position.x,
                msg.pose.position.y,
                msg.pose.position.z,
                msg.pose.orientation.w,
                msg.pose.orientation.x,
                msg.pose.orientation.y,
                msg.pose.orientation.z,
            )
        ),
        np.float64,
        n * 7,
    ).reshape(n, 7)
    return PoseStream(topic=topic, t_ns=t, position=arr[:, :3].copy(), orientation=arr[:, 3:].copy(), frame_id=frame)


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
