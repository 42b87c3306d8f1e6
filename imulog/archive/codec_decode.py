"""Decode block messages back into imulog.model streams: all blocks at once, or block by block.

:func:`decode` first tries the column path (:mod:`imulog.archive.block_decode`: one compiled scan of every
block, numpy over the joined fields); unusual layouts, a few blocks, or bad input go block by block
(:func:`_scan_block`, protobuf's parser as the last resort), which also words the errors. Both give the same
arrays (``tests/test_codec_fast.py``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import numpy as np

from imulog.archive import block_decode, numbers, numbers_decode, wire
from imulog.archive.block_encode import SCHEMA_VERSION
from imulog.archive.block_schemas import BLOCK_SCHEMAS, MESSAGE_CLASSES, SCHEMA_KIND, DecodeError
from imulog.model import AnalogStream, ImuStream, Intervals, MarkerStream, PoseStream, SignalStream, Stream

_I8, _F8, _U1 = np.dtype("<i8"), np.dtype("<f8"), np.dtype("u1")


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
        return numbers_decode.scan_numbers(payload)
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
        fast = numbers_decode.numbers_sources(qs)
        if fast is not None and not any(len(getattr(msg, f)) for msg in msgs):
            try:
                return numbers_decode.decode_numbers([("q", x) for x in fast], counts, width, f"{topic} {f}")
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
        return numbers_decode.decode_numbers(sources, counts, width, f"{topic} {f}")
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
            t = numbers_decode.decode_times(msgs, counts_a, topic)
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
