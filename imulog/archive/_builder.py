"""Write MCAP data-section records (one channel per chunk, zstd) and the summary, continuing the data CRC.

:class:`McapBuilder` is used both for a new file (``McapBuilder.new``) and to append after the data section
of an existing file (``McapBuilder.resume``): in the second case it starts from the old summary state and
the old data-section CRC, so the finished file is exactly what a writer producing everything in one go
would have produced.
"""

from __future__ import annotations

import struct
import threading
import zlib
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future
from typing import BinaryIO

import numpy as np

from imulog.archive import _mcap as m
from imulog.archive.summary_check import chunk_time_span
from imulog.workers import COMPRESS_THREADS, PIPELINE, worker_pool

CHUNK_TARGET_BYTES = 2 * 1024 * 1024  # uncompressed size at which a chunk is closed
ZSTD_LEVEL = 3  # the mcap library's level: on IMU blocks both smaller and faster than 1 here (bench_archive)
MAX_PENDING = 2 * COMPRESS_THREADS  # chunks compressed ahead at most (memory: about this many raw chunks)

_HEAD = np.dtype(
    [("op", "u1"), ("len", "<u8"), ("channel", "<u2"), ("seq", "<u4"), ("log", "<u8"), ("publish", "<u8")]
)  # an MCAP Message record's 31-byte head, packed
assert _HEAD.itemsize == 31

_local = threading.local()


def _compressor():
    """This thread's zstd compressor (a ZstdCompressor must not be shared between threads)."""
    c = getattr(_local, "zstd", None)
    if c is None or getattr(_local, "level", None) != ZSTD_LEVEL:
        import zstandard

        c = _local.zstd = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
        _local.level = ZSTD_LEVEL
    return c


def build_chunk(start: int, end: int, raw: bytes | memoryview) -> tuple[bytes, int]:
    """A zstd Chunk record of the message records ``raw`` (CRC of the uncompressed bytes); (record, compressed size).

    Pure function of its input: runs on a compression thread.
    """
    compressed = _compressor().compress(raw)
    record = m.chunk(start, end, len(raw), zlib.crc32(raw), "zstd", compressed)
    return record, len(compressed)


def message_heads(channel_id: int, first_seq: int, log_times: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """(N, 31) uint8: the Message record heads of N messages (sequence numbers from ``first_seq``)."""
    n = len(log_times)
    heads = np.empty(n, dtype=_HEAD)
    heads["op"] = m.Op.MESSAGE
    heads["len"] = np.asarray(lengths, dtype=np.uint64) + (2 + 4 + 8 + 8)
    heads["channel"] = channel_id
    heads["seq"] = (np.arange(n, dtype=np.int64) + first_seq).astype(np.uint32)
    heads["log"] = heads["publish"] = np.asarray(log_times, dtype=np.uint64)
    return heads.view(np.uint8).reshape(n, 31)


class McapBuilder:
    """Writes records in file order; chunks are compressed on worker threads while the caller encodes the next.

    Every record reaches the file in the order it was added: a non-chunk record (or reading ``offset``,
    ``crc``, ``chunk_indexes``) first writes out the chunks still being compressed.
    """

    def __init__(self, f: BinaryIO, offset: int, crc: int, summary: m.Summary | None = None) -> None:
        self.f = f
        self._offset = offset
        self._crc = crc
        self._pending: deque[tuple[Future | tuple[bytes, int], int, int, int, bytes, int]] = deque()
        self.schemas: dict[int, m.SchemaRec] = {}
        self.channels: dict[int, m.ChannelRec] = {}
        self._chunk_indexes: list[m.ChunkIndexRec] = []  # after ``_kept``'s
        # the chunk indexes of the file appended to, read from its summary's bytes when the summary is written
        # (issue 24: a week's ~10,000 ChunkIndex objects are not held for an append)
        self._kept: m.Summary | None = None
        self.attachment_indexes: list[m.AttachmentIndexRec] = []
        self.metadata_indexes: list[m.MetadataIndexRec] = []
        self.channel_counts: dict[int, int] = {}
        if summary is not None:
            self.schemas = dict(summary.schemas)
            self.channels = dict(summary.channels)
            self._kept = summary
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

    @property
    def offset(self) -> int:
        """File offset of the next record (after every pending chunk)."""
        self._drain()
        return self._offset

    @property
    def crc(self) -> int:
        """Data-section CRC so far (after every pending chunk)."""
        self._drain()
        return self._crc

    @property
    def chunk_indexes(self) -> list[m.ChunkIndexRec]:
        """Every chunk index of the file being written (the kept file's, parsed here, then the new ones)."""
        self._drain()
        if self._kept is not None:
            self._chunk_indexes = [*self._kept.chunk_indexes, *self._chunk_indexes]
            self._kept = None
        return self._chunk_indexes

    @chunk_indexes.setter
    def chunk_indexes(self, value: list[m.ChunkIndexRec]) -> None:
        self._drain()
        self._kept = None
        self._chunk_indexes = value

    def _iter_chunk_indexes(self) -> Iterator[m.ChunkIndexRec]:
        """Every chunk index, one at a time (the kept file's parsed from its bytes, not held)."""
        self._drain()
        if self._kept is not None:
            yield from self._kept.iter_chunk_indexes()
        yield from self._chunk_indexes

    def write(self, data: bytes | memoryview) -> None:
        """Write data-section bytes (counted in the data CRC), after any chunk still being compressed."""
        if self._pending:
            self._drain()
        self._write(data)

    def _write(self, data: bytes | memoryview) -> None:
        self._out(data)
        self._offset += len(data)
        self._crc = zlib.crc32(data, self._crc)

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

    def add_message_rows(
        self, channel_id: int, log_times: np.ndarray, rows: np.ndarray, mask: np.ndarray | None = None
    ) -> None:
        """:meth:`add_messages` for messages given as an (N, W) uint8 array, one message per row.

        ``mask`` (N, W) bool, when given, says which bytes of each row belong to its message (the rest is
        left out, order kept); without it every message is the whole row. The records are assembled with
        numpy (no per-message Python), in the same chunks and bytes :meth:`add_messages` would write.
        """
        n = len(rows)
        if len(log_times) != n or (mask is not None and mask.shape != rows.shape):
            raise ValueError("log_times, rows and mask must have one entry per message")
        log_times = np.asarray(log_times, dtype=np.uint64)
        lengths = np.count_nonzero(mask, axis=1) if mask is not None else np.full(n, rows.shape[1], dtype=np.int64)
        sizes = lengths + 31
        ends = np.cumsum(sizes)
        start = 0
        while start < n:
            # messages up to and including the one that reaches CHUNK_TARGET_BYTES, as add_messages does
            base = ends[start - 1] if start else 0
            stop = int(np.searchsorted(ends, base + CHUNK_TARGET_BYTES, "left")) + 1
            stop = min(max(stop, start + 1), n)
            sl = slice(start, stop)
            heads = message_heads(channel_id, start, log_times[sl], lengths[sl])
            records = np.concatenate([heads, rows[sl]], axis=1)
            if mask is not None:
                keep = np.concatenate([np.ones((stop - start, 31), dtype=bool), mask[sl]], axis=1)
                records = records[keep]
            raw = records.reshape(-1).data  # a fresh array: handed to the compressor without a copy to bytes
            offsets = np.concatenate([[0], np.cumsum(sizes[sl])[:-1]]).astype(np.uint64)
            entries = np.column_stack([log_times[sl], offsets]).astype("<u8").tobytes()
            t = log_times[sl]
            self._submit(channel_id, int(t.min()), int(t.max()), raw, entries)
            start = stop
        self.channel_counts[channel_id] = self.channel_counts.get(channel_id, 0) + n

    def _flush_chunk(self, channel_id: int, parts: list[bytes], index: list[tuple[int, int]], size: int) -> None:
        raw = b"".join(parts)
        times = [t for t, _ in index]
        entries = np.asarray(index, dtype="<u8").reshape(-1, 2).tobytes()
        self._submit(channel_id, min(times), max(times), raw, entries)

    def _submit(self, channel_id: int, start: int, end: int, raw: bytes | memoryview, entries: bytes) -> None:
        """Queue a chunk: compressed on a worker thread, written in file order by :meth:`_drain`."""
        job = worker_pool().submit(build_chunk, start, end, raw) if PIPELINE else build_chunk(start, end, raw)
        self._pending.append((job, channel_id, start, end, entries, len(raw)))
        self._drain(keep=MAX_PENDING)

    def _drain(self, keep: int = 0) -> None:
        """Write the pending chunks (oldest first) until at most ``keep`` are left."""
        while len(self._pending) > keep:
            job, channel_id, start, end, entries, raw_size = self._pending.popleft()
            record, compressed_size = job.result() if isinstance(job, Future) else job
            chunk_offset = self._offset
            self._write(record)
            mi_offset = self._offset
            mi = m.message_index(channel_id, entries)
            self._write(mi)
            self._chunk_indexes.append(
                m.ChunkIndexRec(
                    message_start_time=start,
                    message_end_time=end,
                    chunk_start_offset=chunk_offset,
                    chunk_length=len(record),
                    message_index_offsets={channel_id: mi_offset},
                    message_index_length=len(mi),
                    compression="zstd",
                    compressed_size=compressed_size,
                    uncompressed_size=raw_size,
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
        self._drain()
        start, end = chunk_time_span(self._iter_chunk_indexes())
        return m.StatisticsRec(
            message_count=sum(counts.values()),
            schema_count=len(self.schemas),
            channel_count=len(self.channels),
            attachment_count=len(self.attachment_indexes),
            metadata_count=len(self.metadata_indexes),
            chunk_count=(self._kept.chunk_count if self._kept is not None else 0) + len(self._chunk_indexes),
            message_start_time=start,
            message_end_time=end,
            channel_message_counts=counts,
        )

    def finish(self) -> None:
        """Write DataEnd (with the data CRC), the summary, summary offsets, footer and closing magic."""
        self._drain()
        self._out(m.data_end(self._crc))
        self._offset += m.DATA_END_SIZE
        summary_start = self._offset
        groups: list[tuple[int, list[bytes]]] = [
            (m.Op.SCHEMA, [s.encode() for s in sorted(self.schemas.values(), key=lambda s: s.id)]),
            (m.Op.CHANNEL, [c.encode() for c in sorted(self.channels.values(), key=lambda c: c.id)]),
            (m.Op.STATISTICS, [self.statistics().encode()]),
            (m.Op.CHUNK_INDEX, [c.encode() for c in self._iter_chunk_indexes()]),
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
        self._offset += len(body) + m.FOOTER_SIZE + len(m.MAGIC)
