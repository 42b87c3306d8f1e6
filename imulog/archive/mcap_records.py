"""MCAP records as bytes (spec: https://mcap.dev/spec): opcodes, the encoders of each record, and the parsed
record types with their own ``encode``. The record layer of :mod:`imulog.archive._mcap`."""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

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
