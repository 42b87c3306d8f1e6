"""Minimal, fast MCAP record layer (spec: https://mcap.dev/spec) used by the writer, reader, appender and doctor.

The ``mcap`` package reads and writes files but cannot append, cannot write one channel per chunk and
parses records one Python object at a time. This module encodes and decodes the records directly with
``struct`` so that imulog controls the exact byte layout (needed to append after the old data section and
to copy chunks verbatim). Files written here are ordinary MCAP files that any reader opens.
"""

from __future__ import annotations

import contextlib
import struct
import zlib
from array import array
from dataclasses import dataclass, field
from typing import BinaryIO

MAGIC = b"\x89MCAP0\r\n"


class Op:
    HEADER = 0x01
    FOOTER = 0x02
    SCHEMA = 0x03
    CHANNEL = 0x04
    MESSAGE = 0x05
    CHUNK = 0x06
    MESSAGE_INDEX = 0x07
    CHUNK_INDEX = 0x08
    ATTACHMENT = 0x09
    ATTACHMENT_INDEX = 0x0A
    STATISTICS = 0x0B
    METADATA = 0x0C
    METADATA_INDEX = 0x0D
    SUMMARY_OFFSET = 0x0E
    DATA_END = 0x0F


OP_NAMES = {v: k.lower() for k, v in vars(Op).items() if not k.startswith("_")}
FOOTER_SIZE = 1 + 8 + 20  # opcode, length, summary_start, summary_offset_start, summary_crc
DATA_END_SIZE = 1 + 8 + 4

_Q = struct.Struct("<Q")
_H = struct.Struct("<H")
_I = struct.Struct("<I")
_REC = struct.Struct("<BQ")
_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, length, channel_id, sequence, log_time, publish_time


class McapFormatError(ValueError):
    """The bytes are not a valid MCAP structure (message says where)."""


# ----------------------------------------------------------------------------------------------- encoding


def _s(value: str) -> bytes:
    b = value.encode()
    return _I.pack(len(b)) + b


def _b4(value: bytes) -> bytes:
    return _I.pack(len(value)) + value


def _map(items: dict[str, str]) -> bytes:
    body = b"".join(_s(k) + _s(v) for k, v in items.items())
    return _I.pack(len(body)) + body


def record(op: int, body: bytes) -> bytes:
    return _REC.pack(op, len(body)) + body


def header(profile: str, library: str) -> bytes:
    return record(Op.HEADER, _s(profile) + _s(library))


def schema(schema_id: int, name: str, encoding: str, data: bytes) -> bytes:
    return record(Op.SCHEMA, _H.pack(schema_id) + _s(name) + _s(encoding) + _b4(data))


def channel(channel_id: int, schema_id: int, topic: str, message_encoding: str, metadata: dict[str, str]) -> bytes:
    return record(
        Op.CHANNEL, _H.pack(channel_id) + _H.pack(schema_id) + _s(topic) + _s(message_encoding) + _map(metadata)
    )


def message_head(channel_id: int, sequence: int, log_time: int, publish_time: int, data_len: int) -> bytes:
    return _MSG_HEAD.pack(Op.MESSAGE, 2 + 4 + 8 + 8 + data_len, channel_id, sequence, log_time, publish_time)


def chunk(start: int, end: int, uncompressed_size: int, uncompressed_crc: int, compression: str, data: bytes) -> bytes:
    body_head = struct.pack("<QQQI", start, end, uncompressed_size, uncompressed_crc) + _s(compression)
    return _REC.pack(Op.CHUNK, len(body_head) + 8 + len(data)) + body_head + _Q.pack(len(data)) + data


def message_index(channel_id: int, entries: bytes) -> bytes:
    """``entries``: packed little-endian (log_time u64, offset u64) pairs."""
    return record(Op.MESSAGE_INDEX, _H.pack(channel_id) + _I.pack(len(entries)) + entries)


def attachment(log_time: int, create_time: int, name: str, media_type: str, data: bytes) -> bytes:
    body = struct.pack("<QQ", log_time, create_time) + _s(name) + _s(media_type) + _Q.pack(len(data)) + data
    crc = zlib.crc32(body)
    return record(Op.ATTACHMENT, body + _I.pack(crc))


def metadata(name: str, items: dict[str, str]) -> bytes:
    return record(Op.METADATA, _s(name) + _map(items))


def data_end(crc: int) -> bytes:
    return record(Op.DATA_END, _I.pack(crc))


# ----------------------------------------------------------------------------------------------- records


@dataclass
class SchemaRec:
    id: int
    name: str
    encoding: str
    data: bytes

    def encode(self) -> bytes:
        return schema(self.id, self.name, self.encoding, self.data)


@dataclass
class ChannelRec:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]

    def encode(self) -> bytes:
        return channel(self.id, self.schema_id, self.topic, self.message_encoding, self.metadata)


@dataclass
class ChunkIndexRec:
    message_start_time: int
    message_end_time: int
    chunk_start_offset: int
    chunk_length: int
    message_index_offsets: dict[int, int]
    message_index_length: int
    compression: str
    compressed_size: int
    uncompressed_size: int

    def encode(self) -> bytes:
        offsets = b"".join(_H.pack(k) + _Q.pack(v) for k, v in self.message_index_offsets.items())
        body = (
            struct.pack(
                "<QQQQ", self.message_start_time, self.message_end_time, self.chunk_start_offset, self.chunk_length
            )
            + _I.pack(len(offsets))
            + offsets
            + _Q.pack(self.message_index_length)
            + _s(self.compression)
            + struct.pack("<QQ", self.compressed_size, self.uncompressed_size)
        )
        return record(Op.CHUNK_INDEX, body)


@dataclass
class AttachmentIndexRec:
    offset: int
    length: int
    log_time: int
    create_time: int
    data_size: int
    name: str
    media_type: str

    def encode(self) -> bytes:
        body = struct.pack("<QQQQQ", self.offset, self.length, self.log_time, self.create_time, self.data_size)
        return record(Op.ATTACHMENT_INDEX, body + _s(self.name) + _s(self.media_type))


@dataclass
class MetadataIndexRec:
    offset: int
    length: int
    name: str

    def encode(self) -> bytes:
        return record(Op.METADATA_INDEX, struct.pack("<QQ", self.offset, self.length) + _s(self.name))


@dataclass
class StatisticsRec:
    message_count: int = 0
    schema_count: int = 0
    channel_count: int = 0
    attachment_count: int = 0
    metadata_count: int = 0
    chunk_count: int = 0
    message_start_time: int = 0
    message_end_time: int = 0
    channel_message_counts: dict[int, int] = field(default_factory=dict)

    def encode(self) -> bytes:
        counts = b"".join(_H.pack(k) + _Q.pack(v) for k, v in sorted(self.channel_message_counts.items()))
        body = struct.pack(
            "<QHIIIIQQ",
            self.message_count,
            self.schema_count,
            self.channel_count,
            self.attachment_count,
            self.metadata_count,
            self.chunk_count,
            self.message_start_time,
            self.message_end_time,
        )
        return record(Op.STATISTICS, body + _I.pack(len(counts)) + counts)


@dataclass
class ChunkRec:
    message_start_time: int
    message_end_time: int
    uncompressed_size: int
    uncompressed_crc: int
    compression: str
    data: memoryview


@dataclass
class AttachmentRec:
    log_time: int
    create_time: int
    name: str
    media_type: str
    data: bytes
    crc: int
    computed_crc: int


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


MAX_CHUNK_BYTES = 256 * 1024 * 1024  # refuse chunks declaring more than this uncompressed (bytes)
MAX_CHUNK_RATIO = 1024  # ... or more than this many times their compressed size, above RATIO_FREE_BYTES
RATIO_FREE_BYTES = 4 * 1024 * 1024  # chunks up to this uncompressed size may have any ratio


def check_chunk_size(compressed_size: int, uncompressed_size: int) -> None:
    """Refuse a chunk whose declared uncompressed size is implausible (huge, or a decompression bomb)."""
    if uncompressed_size > MAX_CHUNK_BYTES:
        raise McapFormatError(
            f"chunk declares {uncompressed_size} bytes uncompressed, above the {MAX_CHUNK_BYTES >> 20} MiB limit"
        )
    if uncompressed_size > RATIO_FREE_BYTES and uncompressed_size > MAX_CHUNK_RATIO * max(compressed_size, 1):
        raise McapFormatError(
            f"chunk declares {uncompressed_size} bytes from {compressed_size} compressed "
            f"(ratio above {MAX_CHUNK_RATIO}: a decompression bomb?)"
        )


def _read_bounded(reader, limit: int) -> bytes:
    """Read at most ``limit`` bytes from a decompressing reader (stops early at its end)."""
    parts, total = [], 0
    while total < limit:
        block = reader.read(limit - total)
        if not block:
            break
        parts.append(block)
        total += len(block)
    return parts[0] if len(parts) == 1 else b"".join(parts)


def decompress(compression: str, data: bytes | memoryview, uncompressed_size: int) -> bytes:
    """Decompress chunk data, never producing more than ``uncompressed_size`` + 1 bytes.

    Raises McapFormatError when the declared size is implausible (:func:`check_chunk_size`) or the output
    is not exactly ``uncompressed_size`` bytes.
    """
    check_chunk_size(len(data), uncompressed_size)
    if compression == "":
        out = bytes(data)
    elif compression == "zstd":
        import zstandard

        try:
            out = b""
            if zstandard.frame_content_size(data) == uncompressed_size:  # one frame says its exact size (imulog,
                with contextlib.suppress(zstandard.ZstdError):  # the mcap library): decompress at once
                    out = zstandard.ZstdDecompressor().decompress(data, allow_extra_data=False)
            if len(out) != uncompressed_size:  # several frames, no size in the header, or a lie: bounded reads
                reader = zstandard.ZstdDecompressor().stream_reader(bytes(data), read_across_frames=True)
                out = _read_bounded(reader, uncompressed_size + 1)
        except zstandard.ZstdError as exc:
            raise McapFormatError(f"zstd data does not decompress ({exc})") from None
    elif compression == "lz4":
        import lz4.frame

        try:
            d = lz4.frame.LZ4FrameDecompressor()
            out = d.decompress(bytes(data), max_length=uncompressed_size + 1)
        except (RuntimeError, ValueError, TypeError) as exc:
            raise McapFormatError(f"lz4 data does not decompress ({exc})") from None
        if len(out) <= uncompressed_size and not d.eof:
            raise McapFormatError("lz4 data ends before its frame does (truncated)")
    else:
        raise McapFormatError(f"unsupported chunk compression {compression!r}")
    if len(out) != uncompressed_size:
        more = "more than" if len(out) > uncompressed_size else f"{len(out)}, not"
        raise McapFormatError(f"chunk decompresses to {more} the declared {uncompressed_size} bytes")
    return out


def decompress_chunk(chunk: ChunkRec) -> bytes:
    """Decompress a chunk record and verify its uncompressed CRC (when recorded); McapFormatError if damaged."""
    out = decompress(chunk.compression, chunk.data, chunk.uncompressed_size)
    if chunk.uncompressed_crc != 0 and zlib.crc32(out) != chunk.uncompressed_crc:
        raise McapFormatError("chunk CRC mismatch (damaged data)")
    return out


# ----------------------------------------------------------------------------------------------- summary


@dataclass
class Summary:
    """Everything in an MCAP file's summary section plus the locations needed to append."""

    file_size: int
    summary_start: int
    summary_offset_start: int
    summary_crc: int
    computed_summary_crc: int
    data_end_offset: int  # where the DataEnd record starts (== end of the data section)
    data_section_crc: int
    schemas: dict[int, SchemaRec] = field(default_factory=dict)
    channels: dict[int, ChannelRec] = field(default_factory=dict)
    statistics: StatisticsRec | None = None
    attachment_indexes: list[AttachmentIndexRec] = field(default_factory=list)
    metadata_indexes: list[MetadataIndexRec] = field(default_factory=list)
    summary_offsets: list[tuple[int, int, int]] = field(default_factory=list)
    duplicate_chunk_indexes: int = 0  # chunk index entries dropped because an earlier one names the same chunk
    duplicate_record_indexes: int = 0  # attachment/metadata index entries dropped (same record indexed again)
    # A week's summary indexes ~6000 chunks: as Python objects ~800 bytes each, as kept here 16 (the section's
    # bytes are kept and each ChunkIndex is parsed when ``chunk_indexes`` is first used; ``info`` never is).
    _section: bytes = field(default=b"", repr=False)
    _chunk_spans: array = field(default_factory=lambda: array("Q"), repr=False)  # (start, length) in _section
    _records: array = field(default_factory=lambda: array("Q"), repr=False)  # (opcode, offset, length) triples
    _chunk_indexes: list[ChunkIndexRec] | None = field(default=None, repr=False)

    @property
    def chunk_indexes(self) -> list[ChunkIndexRec]:
        """Every ChunkIndex record (duplicates dropped), in summary order; parsed on first use."""
        if self._chunk_indexes is None:
            spans, section = self._chunk_spans, memoryview(self._section)
            self._chunk_indexes = [
                parse_chunk_index(section[spans[i] : spans[i] + spans[i + 1]]) for i in range(0, len(spans), 2)
            ]
        return self._chunk_indexes

    @chunk_indexes.setter
    def chunk_indexes(self, value: list[ChunkIndexRec]) -> None:
        self._chunk_indexes = list(value)

    @property
    def summary_records(self) -> list[tuple[int, int, int]]:
        """(opcode, file offset, total length) of every record of the summary section, in order."""
        r = self._records
        return [(r[i], r[i + 1], r[i + 2]) for i in range(0, len(r), 3)]

    def stored_bytes_by_channel(self) -> dict[int, int]:
        """Compressed chunk bytes per channel id (a chunk's length shared evenly among its channels), read
        straight from the ChunkIndex records without building them."""
        if self._chunk_indexes is not None:
            pairs = [(ci.chunk_length, list(ci.message_index_offsets)) for ci in self._chunk_indexes]
        else:
            pairs = []
            spans, section = self._chunk_spans, self._section
            for i in range(0, len(spans), 2):
                lo = spans[i]
                *_, length, map_len = _CI_HEAD.unpack_from(section, lo)
                entries = section[lo + _CI_HEAD.size : lo + _CI_HEAD.size + map_len]
                pairs.append((length, [cid for cid, _ in _CI_ENTRY.iter_unpack(entries)]))
        out: dict[int, int] = {}
        for length, ids in pairs:
            for cid in ids:
                out[cid] = out.get(cid, 0) + length // len(ids)
        return out


def read_summary(f: BinaryIO, file_size: int) -> Summary:
    """Parse the footer and summary section; raise McapFormatError with a one-line reason."""
    try:
        return _read_summary(f, file_size)
    except McapFormatError:
        raise
    except (struct.error, ValueError, OverflowError, MemoryError) as exc:
        raise McapFormatError(f"corrupt MCAP summary ({exc})") from exc


def read_summary_from_bytes(data: bytes) -> Summary:
    """:func:`read_summary` of a file held in memory."""
    import io

    return read_summary(io.BytesIO(data), len(data))


def _read_summary(f: BinaryIO, file_size: int) -> Summary:
    if file_size < len(MAGIC) * 2 + FOOTER_SIZE:
        raise McapFormatError(f"too short for an MCAP file ({file_size} bytes)")
    f.seek(0)
    if f.read(len(MAGIC)) != MAGIC:
        raise McapFormatError("not an MCAP file (bad magic at start)")
    f.seek(file_size - len(MAGIC) - FOOTER_SIZE)
    tail = f.read(FOOTER_SIZE + len(MAGIC))
    if tail[-len(MAGIC) :] != MAGIC:
        raise McapFormatError("truncated or unfinished MCAP file (no closing magic / footer)")
    op, length = _REC.unpack_from(tail, 0)
    if op != Op.FOOTER or length != 20:
        raise McapFormatError("corrupt MCAP footer")
    summary_start, summary_offset_start, summary_crc = struct.unpack_from("<QQI", tail, 9)
    footer_offset = file_size - len(MAGIC) - FOOTER_SIZE
    if summary_start == 0:
        raise McapFormatError("MCAP file has no summary section (not written by an indexed writer)")
    if not (len(MAGIC) < summary_start <= footer_offset) or not (
        summary_offset_start == 0 or summary_start <= summary_offset_start <= footer_offset
    ):
        raise McapFormatError("corrupt MCAP footer (summary offsets outside the file)")
    f.seek(summary_start)
    section = f.read(footer_offset - summary_start)
    computed = zlib.crc32(tail[: 1 + 8 + 16], zlib.crc32(section))
    # DataEnd sits right before the summary.
    de_off = summary_start - DATA_END_SIZE
    f.seek(de_off)
    de = f.read(DATA_END_SIZE)
    if len(de) != DATA_END_SIZE or de[0] != Op.DATA_END or _Q.unpack_from(de, 1)[0] != 4:
        raise McapFormatError("no DataEnd record before the summary section")
    s = Summary(
        file_size=file_size,
        summary_start=summary_start,
        summary_offset_start=summary_offset_start,
        summary_crc=summary_crc,
        computed_summary_crc=computed,
        data_end_offset=de_off,
        data_section_crc=_I.unpack_from(de, 9)[0],
    )
    if summary_crc != 0 and summary_crc != computed:
        raise McapFormatError(f"summary CRC mismatch (stored {summary_crc:#010x}, computed {computed:#010x})")
    seen_chunks: set[int] = set()
    seen_records: set[tuple[int, int]] = set()
    s._section = section
    for op, rel, body in iter_records(section):
        s._records.extend((op, summary_start + rel, 9 + len(body)))
        if op == Op.SCHEMA:
            rec = parse_schema(body)
            s.schemas[rec.id] = rec
        elif op == Op.CHANNEL:
            rec = parse_channel(body)
            s.channels[rec.id] = rec
        elif op == Op.STATISTICS:
            s.statistics = parse_statistics(body)
        elif op == Op.CHUNK_INDEX:
            offset = _Q.unpack_from(body, 16)[0] if len(body) >= 24 else -1
            if offset in seen_chunks:  # a chunk is read once, however often it is indexed
                s.duplicate_chunk_indexes += 1
                continue
            if not _chunk_index_is_plain(body):
                _parse_chunk_index_fields(body)  # raises, naming what is malformed, like the eager parse did
            seen_chunks.add(offset)
            s._chunk_spans.extend((rel + 9, len(body)))
        elif op in (Op.ATTACHMENT_INDEX, Op.METADATA_INDEX):
            offset = _Q.unpack_from(body, 0)[0] if len(body) >= 8 else -1
            if (op, offset) in seen_records:  # each attachment / metadata record is read once
                s.duplicate_record_indexes += 1
                continue
            seen_records.add((op, offset))
            if op == Op.ATTACHMENT_INDEX:
                s.attachment_indexes.append(parse_attachment_index(body))
            else:
                s.metadata_indexes.append(parse_metadata_index(body))
        elif op == Op.SUMMARY_OFFSET:
            if len(body) < 17:
                raise McapFormatError("summary offset record too short")
            s.summary_offsets.append(struct.unpack_from("<BQQ", body))
    return s


def read_record_at(f: BinaryIO, offset: int, expect: int, limit: int) -> memoryview:
    """Read the body of the record starting at ``offset`` and check its opcode."""
    if not 0 <= offset <= limit - 9:
        raise McapFormatError(f"index points at byte {offset}, outside the data section")
    f.seek(offset)
    head = f.read(9)
    if len(head) != 9:
        raise McapFormatError(f"record at byte {offset} is past the end of the file")
    op, length = _REC.unpack(head)
    if op != expect:
        raise McapFormatError(f"expected a {OP_NAMES.get(expect)} record at byte {offset}, found opcode {op:#04x}")
    if offset + 9 + length > limit:
        raise McapFormatError(f"{OP_NAMES.get(expect)} record at byte {offset} runs past the data section")
    body = f.read(length)
    if len(body) != length:
        raise McapFormatError(f"{OP_NAMES.get(expect)} record at byte {offset} is truncated")
    return memoryview(body)
