"""Decoding MCAP records (spec: https://mcap.dev/spec): a bounds-checked cursor, one parser per record type,
the records of a section and the messages of a chunk. Part of the record layer :mod:`imulog.archive._mcap`."""

from __future__ import annotations

import struct
import zlib

from imulog.archive.mcap_records import (
    _H,
    _I,
    _MSG_HEAD,
    _Q,
    _REC,
    OP_NAMES,
    AttachmentIndexRec,
    AttachmentRec,
    ChannelRec,
    ChunkIndexRec,
    ChunkRec,
    McapFormatError,
    MetadataIndexRec,
    Op,
    SchemaRec,
    StatisticsRec,
)

# ----------------------------------------------------------------------------------------------- decoding


class Cursor:
    """Reads little-endian fields from a bytes-like body, raising McapFormatError on overrun."""

    __slots__ = ("buf", "pos", "end")

    def __init__(self, buf: bytes | memoryview, pos: int = 0, end: int | None = None) -> None:
        self.buf = buf
        self.pos = pos
        self.end = len(buf) if end is None else end

    def _need(self, n: int) -> int:
        p = self.pos
        if n < 0 or p + n > self.end:
            raise McapFormatError(f"record field runs past the end of its record ({p + n} > {self.end})")
        self.pos = p + n
        return p

    def u16(self) -> int:
        return _H.unpack_from(self.buf, self._need(2))[0]

    def u32(self) -> int:
        return _I.unpack_from(self.buf, self._need(4))[0]

    def u64(self) -> int:
        return _Q.unpack_from(self.buf, self._need(8))[0]

    def raw(self, n: int) -> memoryview:
        p = self._need(n)
        return memoryview(self.buf)[p : p + n]

    def string(self) -> str:
        n = self.u32()
        try:
            return bytes(self.raw(n)).decode()
        except UnicodeDecodeError as exc:
            raise McapFormatError("invalid UTF-8 in a string field") from exc

    def str_map(self) -> dict[str, str]:
        n = self.u32()
        end = self._need(n) + n
        sub = Cursor(self.buf, end - n, end)
        out = {}
        while sub.pos < end:
            key = sub.string()
            out[key] = sub.string()
        return out

    def u16_u64_map(self) -> dict[int, int]:
        n = self.u32()
        end = self._need(n) + n
        sub = Cursor(self.buf, end - n, end)
        out = {}
        while sub.pos < end:
            key = sub.u16()
            out[key] = sub.u64()
        return out


def parse_schema(body: bytes | memoryview) -> SchemaRec:
    c = Cursor(body)
    sid = c.u16()
    name = c.string()
    encoding = c.string()
    return SchemaRec(sid, name, encoding, bytes(c.raw(c.u32())))


def parse_channel(body: bytes | memoryview) -> ChannelRec:
    c = Cursor(body)
    cid = c.u16()
    sid = c.u16()
    topic = c.string()
    enc = c.string()
    return ChannelRec(cid, sid, topic, enc, c.str_map())


def parse_chunk(body: bytes | memoryview) -> ChunkRec:
    c = Cursor(body)
    start, end, usize = c.u64(), c.u64(), c.u64()
    crc = c.u32()
    compression = c.string()
    return ChunkRec(start, end, usize, crc, compression, c.raw(c.u64()))


_CI_HEAD = struct.Struct("<QQQQI")  # message start/end time, chunk offset, chunk length, offsets-map byte length
_CI_ENTRY = struct.Struct("<HQ")
_CI_MID = struct.Struct("<QI")  # message index length, compression string length
_CI_TAIL = struct.Struct("<QQ")


def parse_chunk_index(body: bytes | memoryview) -> ChunkIndexRec:
    """A ChunkIndex record (one ``struct`` call per field group: a week's summary holds thousands)."""
    try:
        start, end, offset, length, map_len = _CI_HEAD.unpack_from(body, 0)
        pos = _CI_HEAD.size
        if map_len % _CI_ENTRY.size or pos + map_len > len(body):
            raise ValueError
        offsets = dict(_CI_ENTRY.iter_unpack(body[pos : pos + map_len]))
        pos += map_len
        mi_len, name_len = _CI_MID.unpack_from(body, pos)
        pos += _CI_MID.size
        compression = bytes(body[pos : pos + name_len]).decode()
        if len(compression) != name_len:
            raise ValueError
        compressed, uncompressed = _CI_TAIL.unpack_from(body, pos + name_len)
    except (struct.error, ValueError):  # malformed: the field-by-field parse says where
        return _parse_chunk_index_fields(body)
    return ChunkIndexRec(start, end, offset, length, offsets, mi_len, compression, compressed, uncompressed)


def _chunk_index_is_plain(body: bytes | memoryview) -> bool:
    """True when :func:`parse_chunk_index` reads ``body`` on its fast path (every length inside the record)."""
    if len(body) < _CI_HEAD.size:
        return False
    map_len = _CI_HEAD.unpack_from(body, 0)[4]
    pos = _CI_HEAD.size + map_len
    if map_len % _CI_ENTRY.size or pos + _CI_MID.size > len(body):
        return False
    name_len = _CI_MID.unpack_from(body, pos)[1]
    return pos + _CI_MID.size + name_len + _CI_TAIL.size <= len(body)


def _parse_chunk_index_fields(body: bytes | memoryview) -> ChunkIndexRec:
    c = Cursor(body)
    start, end, offset, length = c.u64(), c.u64(), c.u64(), c.u64()
    offsets = c.u16_u64_map()
    mi_len = c.u64()
    compression = c.string()
    return ChunkIndexRec(start, end, offset, length, offsets, mi_len, compression, c.u64(), c.u64())


def parse_attachment(body: bytes | memoryview) -> AttachmentRec:
    c = Cursor(body)
    log_time, create_time = c.u64(), c.u64()
    name = c.string()
    media_type = c.string()
    data = bytes(c.raw(c.u64()))
    computed = zlib.crc32(memoryview(body)[: c.pos])
    return AttachmentRec(log_time, create_time, name, media_type, data, c.u32(), computed)


def parse_attachment_index(body: bytes | memoryview) -> AttachmentIndexRec:
    c = Cursor(body)
    vals = [c.u64() for _ in range(5)]
    return AttachmentIndexRec(*vals, c.string(), c.string())


def parse_metadata(body: bytes | memoryview) -> tuple[str, dict[str, str]]:
    c = Cursor(body)
    return c.string(), c.str_map()


def parse_metadata_index(body: bytes | memoryview) -> MetadataIndexRec:
    c = Cursor(body)
    return MetadataIndexRec(c.u64(), c.u64(), c.string())


def parse_statistics(body: bytes | memoryview) -> StatisticsRec:
    c = Cursor(body)
    mc = c.u64()
    sc = c.u16()
    cc, ac, mdc, chc = c.u32(), c.u32(), c.u32(), c.u32()
    start, end = c.u64(), c.u64()
    return StatisticsRec(mc, sc, cc, ac, mdc, chc, start, end, c.u16_u64_map())


def iter_records(buf: bytes | memoryview, start: int = 0, end: int | None = None):
    """Yield ``(opcode, offset, body_memoryview)`` for consecutive records in ``buf[start:end]``."""
    view = memoryview(buf)
    end = len(view) if end is None else end
    pos = start
    while pos < end:
        if pos + 9 > end:
            raise McapFormatError(f"truncated record header at byte {pos}")
        op, length = _REC.unpack_from(view, pos)
        body_start = pos + 9
        if body_start + length > end:
            raise McapFormatError(f"{OP_NAMES.get(op, hex(op))} record at byte {pos} runs past its section end")
        yield op, pos, view[body_start : body_start + length]
        pos = body_start + length


def chunk_messages(records: bytes | memoryview, channel_id: int | None = None):
    """Yield ``(channel_id, log_time, data_memoryview)`` for Message records in decompressed chunk bytes."""
    view = memoryview(records)
    end = len(view)
    pos = 0
    unpack = _MSG_HEAD.unpack_from
    rec = _REC.unpack_from
    while pos < end:
        if pos + 9 > end:
            raise McapFormatError("truncated record inside a chunk")
        op, length = rec(view, pos)
        nxt = pos + 9 + length
        if nxt > end:
            raise McapFormatError("record inside a chunk runs past the chunk end")
        if op == Op.MESSAGE:
            if length < 22:
                raise McapFormatError("message record too short")
            _, _, cid, _, log_time, _ = unpack(view, pos)
            if channel_id is None or cid == channel_id:
                yield cid, log_time, view[pos + 31 : nxt]
        pos = nxt
