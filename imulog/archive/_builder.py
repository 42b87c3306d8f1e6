"""Write MCAP data-section records (one channel per chunk, zstd) and the summary, continuing the data CRC.

:class:`McapBuilder` is used both for a new file (``McapBuilder.new``) and to append after the data section
of an existing file (``McapBuilder.resume``): in the second case it starts from the old summary state and
the old data-section CRC, so the finished file is exactly what a writer producing everything in one go
would have produced.
"""

from __future__ import annotations

import os
import struct
import zlib
from typing import BinaryIO

import numpy as np

from imulog.archive import _mcap as m

CHUNK_TARGET_BYTES = 2 * 1024 * 1024  # uncompressed size at which a chunk is closed
ZSTD_LEVEL = 3  # the mcap library's level: on IMU blocks both smaller and faster than 1 here (bench_archive)
ZSTD_THREADS = min(2, os.cpu_count() or 1)  # zstd's own worker threads (the GIL is released)


class McapBuilder:
    def __init__(self, f: BinaryIO, offset: int, crc: int, summary: m.Summary | None = None) -> None:
        import zstandard

        self.f = f
        self.offset = offset
        self.crc = crc
        self._zstd = zstandard.ZstdCompressor(level=ZSTD_LEVEL, threads=ZSTD_THREADS if ZSTD_THREADS > 1 else 0)
        self.schemas: dict[int, m.SchemaRec] = {}
        self.channels: dict[int, m.ChannelRec] = {}
        self.chunk_indexes: list[m.ChunkIndexRec] = []
        self.attachment_indexes: list[m.AttachmentIndexRec] = []
        self.metadata_indexes: list[m.MetadataIndexRec] = []
        self.channel_counts: dict[int, int] = {}
        if summary is not None:
            self.schemas = dict(summary.schemas)
            self.channels = dict(summary.channels)
            self.chunk_indexes = list(summary.chunk_indexes)
            self.attachment_indexes = list(summary.attachment_indexes)
            self.metadata_indexes = list(summary.metadata_indexes)
            stats = summary.statistics
            self.channel_counts = dict(stats.channel_message_counts) if stats else {}

    # ------------------------------------------------------------------ construction
    @classmethod
    def new(cls, f: BinaryIO, library: str, profile: str = "") -> McapBuilder:
        b = cls(f, 0, 0)
        b.write(m.MAGIC)
        b.write(m.header(profile, library))
        return b

    def write(self, data: bytes | memoryview) -> None:
        """Write data-section bytes (counted in the data CRC)."""
        self._out(data)
        self.offset += len(data)
        self.crc = zlib.crc32(data, self.crc)

    def _out(self, data: bytes | memoryview) -> None:
        """Every byte of the file goes through here (one place to instrument)."""
        self.f.write(data)

    # ------------------------------------------------------------------ records
    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        for s in self.schemas.values():
            if s.name == name and s.encoding == encoding and s.data == data:
                return s.id
        sid = max(self.schemas, default=0) + 1
        if sid > 0xFFFF:
            raise ValueError("too many schemas in one MCAP file")
        rec = m.SchemaRec(sid, name, encoding, data)
        self.schemas[sid] = rec
        self.write(rec.encode())
        return sid

    def add_channel(self, topic: str, schema_id: int, metadata: dict[str, str], encoding: str = "protobuf") -> int:
        cid = max(self.channels, default=-1) + 1
        if cid > 0xFFFF:
            raise ValueError("too many channels in one MCAP file")
        rec = m.ChannelRec(cid, schema_id, topic, encoding, dict(metadata))
        self.channels[cid] = rec
        self.channel_counts.setdefault(cid, 0)
        self.write(rec.encode())
        return cid

    def add_messages(self, channel_id: int, log_times: list[int], payloads: list[bytes]) -> None:
        """Write the channel's messages in chunks of about CHUNK_TARGET_BYTES (one channel per chunk)."""
        parts: list[bytes] = []
        index: list[tuple[int, int]] = []
        size = 0
        for seq, (log_time, payload) in enumerate(zip(log_times, payloads, strict=True)):
            head = m.message_head(channel_id, seq, log_time, log_time, len(payload))
            index.append((log_time, size))
            parts.append(head)
            parts.append(payload)
            size += len(head) + len(payload)
            if size >= CHUNK_TARGET_BYTES:
                self._flush_chunk(channel_id, parts, index, size)
                parts, index, size = [], [], 0
        if parts:
            self._flush_chunk(channel_id, parts, index, size)
        self.channel_counts[channel_id] = self.channel_counts.get(channel_id, 0) + len(payloads)

    def _flush_chunk(self, channel_id: int, parts: list[bytes], index: list[tuple[int, int]], size: int) -> None:
        raw = b"".join(parts)
        compressed = self._zstd.compress(raw)
        times = [t for t, _ in index]
        start, end = min(times), max(times)
        chunk_offset = self.offset
        record = m.chunk(start, end, len(raw), zlib.crc32(raw), "zstd", compressed)
        self.write(record)
        mi_offset = self.offset
        entries = np.asarray(index, dtype="<u8").reshape(-1, 2).tobytes()
        mi = m.message_index(channel_id, entries)
        self.write(mi)
        self.chunk_indexes.append(
            m.ChunkIndexRec(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_offset,
                chunk_length=len(record),
                message_index_offsets={channel_id: mi_offset},
                message_index_length=len(mi),
                compression="zstd",
                compressed_size=len(compressed),
                uncompressed_size=len(raw),
            )
        )

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time: int = 0, create_time: int = 0) -> None:
        offset = self.offset
        record = m.attachment(log_time, create_time, name, media_type, data)
        self.write(record)
        self.attachment_indexes.append(
            m.AttachmentIndexRec(offset, len(record), log_time, create_time, len(data), name, media_type)
        )

    def add_metadata(self, name: str, items: dict[str, str]) -> None:
        offset = self.offset
        record = m.metadata(name, items)
        self.write(record)
        self.metadata_indexes.append(m.MetadataIndexRec(offset, len(record), name))

    # ------------------------------------------------------------------ summary
    def statistics(self) -> m.StatisticsRec:
        counts = {cid: self.channel_counts.get(cid, 0) for cid in self.channels}
        return m.StatisticsRec(
            message_count=sum(counts.values()),
            schema_count=len(self.schemas),
            channel_count=len(self.channels),
            attachment_count=len(self.attachment_indexes),
            metadata_count=len(self.metadata_indexes),
            chunk_count=len(self.chunk_indexes),
            message_start_time=min((c.message_start_time for c in self.chunk_indexes), default=0),
            message_end_time=max((c.message_end_time for c in self.chunk_indexes), default=0),
            channel_message_counts=counts,
        )

    def finish(self) -> None:
        """Write DataEnd (with the data CRC), the summary, summary offsets, footer and closing magic."""
        self._out(m.data_end(self.crc))
        self.offset += m.DATA_END_SIZE
        summary_start = self.offset
        groups: list[tuple[int, list[bytes]]] = [
            (m.Op.SCHEMA, [s.encode() for s in sorted(self.schemas.values(), key=lambda s: s.id)]),
            (m.Op.CHANNEL, [c.encode() for c in sorted(self.channels.values(), key=lambda c: c.id)]),
            (m.Op.STATISTICS, [self.statistics().encode()]),
            (m.Op.CHUNK_INDEX, [c.encode() for c in self.chunk_indexes]),
            (m.Op.ATTACHMENT_INDEX, [a.encode() for a in self.attachment_indexes]),
            (m.Op.METADATA_INDEX, [x.encode() for x in self.metadata_indexes]),
        ]
        body = bytearray()
        offsets = []
        for op, records in groups:
            if not records:
                continue
            start = summary_start + len(body)
            for r in records:
                body += r
            offsets.append(
                m.record(m.Op.SUMMARY_OFFSET, struct.pack("<BQQ", op, start, summary_start + len(body) - start))
            )
        summary_offset_start = summary_start + len(body)
        for r in offsets:
            body += r
        footer_head = struct.pack("<BQQQ", m.Op.FOOTER, 20, summary_start, summary_offset_start)
        summary_crc = zlib.crc32(footer_head, zlib.crc32(body))
        self._out(bytes(body))
        self._out(footer_head + struct.pack("<I", summary_crc))
        self._out(m.MAGIC)
        self.offset += len(body) + m.FOOTER_SIZE + len(m.MAGIC)
