"""The scan of :mod:`imulog.archive.salvage`: one linear pass over the records of a damaged MCAP file.

Records are read from the start, so a missing or damaged summary does not matter; after a damaged record
the scan resynchronises on the next record the summary (when readable) indexes, or on the next plausible
Chunk / Metadata record header. Every chunk is decompressed within its declared size and checked against
its CRC before any of its messages is kept; attachments are checked against their CRC. The scan keeps where
each channel's intact messages are (not the messages), and the byte ranges that no CRC of their own covers
(where damage found only by the data-section CRC can lie).
"""

from __future__ import annotations

import contextlib
import hashlib
import mmap
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imulog.archive import _mcap as m
from imulog.archive.packing import unpack

_KNOWN_OPS = set(range(m.Op.HEADER, m.Op.DATA_END + 1))
RELEASE_BYTES = 32 << 20  # hand mapped pages back to the kernel every this many bytes


def sha256_of(data: bytes | memoryview) -> str:
    return hashlib.sha256(data).hexdigest()


def release(buf: memoryview, start: int, end: int) -> None:
    """Drop the mapped pages of ``buf[start:end]`` from this process's RSS (they are re-read if touched)."""
    page = mmap.PAGESIZE
    lo, hi = -(-start // page) * page, end // page * page
    if hi > lo:
        with contextlib.suppress(AttributeError, OSError, ValueError):  # not a map, or no madvise here
            buf.obj.madvise(mmap.MADV_DONTNEED, lo, hi - lo)


_CHUNK_FIXED = 8 + 8 + 8 + 4  # start, end, uncompressed size, crc before the compression string
LOST_SOURCE = -2  # a channel source whose chunk was lost (its place in the channel's order)


@dataclass
class _Channel:
    """A channel found in the scan: where its intact messages are (not the messages: memory stays small)."""

    rec: m.ChannelRec
    sources: list[tuple[int, int, memoryview | None]] = field(default_factory=list)  # (chunk pos, end, None)
    # or (log time, -1, payload view into the map) for a message outside chunks
    messages: int = 0
    hasher: Any = field(default_factory=hashlib.sha256)  # content hash of the intact messages, in order
    chunks_kept: int = 0
    chunks_lost: int = 0
    messages_lost: int = 0

    def add(self, payload: memoryview) -> None:
        self.messages += 1
        self.hasher.update(struct.pack("<Q", len(payload)))
        self.hasher.update(payload)


@dataclass
class SalvageReport:
    """What :func:`salvage` found: recovered channels/attachments/metadata and one line per loss."""

    source: Path
    output: Path | None = None
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)  # topic -> messages, chunks kept/lost,
    # partial (True when samples were lost), lost_spans ([after, before] ns), clock ("sample" or "log")
    attachments: list[str] = field(default_factory=list)
    metadata: list[str] = field(default_factory=list)
    dropped_metadata: list[str] = field(default_factory=list)  # "name at byte N: why"
    lost: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    summary_found: bool = False
    data_crc: str = "truncated"  # "ok", "mismatch", "not recorded", or "truncated" (no DataEnd reached)

    @property
    def complete(self) -> bool:
        """True when nothing was lost (the output holds everything the input held)."""
        return not self.lost

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": str(self.source),
            "output": str(self.output) if self.output else None,
            "summary_found": self.summary_found,
            "data_crc": self.data_crc,
            "channels": self.channels,
            "attachments": self.attachments,
            "metadata": self.metadata,
            "dropped_metadata": self.dropped_metadata,
            "lost": self.lost,
            "notes": self.notes,
        }


class Scan:
    """One linear pass over the records of a (possibly damaged) MCAP file."""

    def __init__(
        self, buf: memoryview, size: int, report: SalvageReport, hints: list[int], summary: m.Summary | None = None
    ) -> None:
        self.buf = buf
        self.size = size
        self.report = report
        self.hints = sorted(set(hints))
        self.summary = summary  # CRC-checked copies of the schema and channel records, when readable
        self.regions: list[tuple[int, int, int]] = []  # byte ranges no CRC of their own covers (where damage may hide)
        self.attachment_sha: dict[str, str] = {}
        self._indexed = {ci.chunk_start_offset: ci for ci in summary.chunk_indexes} if summary is not None else {}
        self.stored_crc = 0
        self.data_end = 0  # where DataEnd starts (0: not reached)
        self.schemas: dict[int, m.SchemaRec] = {}
        self.channels: dict[int, _Channel] = {}
        # ("channel", id) / ("attachment", (record start, end)) / ("metadata", (name, items)), in file order
        self.order: list[tuple[str, Any]] = []
        self.header: tuple[str, str] = ("", "")
        self.crc = zlib.crc32(buf[: len(m.MAGIC)])  # data-section CRC of the bytes read contiguously so far
        self.crc_upto = len(m.MAGIC)
        self.released = 0  # pages before this offset were handed back (madvise): RSS stays small
        self.failed_chunk: int | None = None  # offset of the last chunk that could not be used
        self.failed_channels: set[int] = set()

    # ------------------------------------------------------------------ records
    def _schema(self, rec: m.SchemaRec) -> None:
        self.schemas.setdefault(rec.id, rec)

    def _channel(self, rec: m.ChannelRec) -> None:
        if rec.id not in self.channels:
            self.channels[rec.id] = _Channel(rec)
            self.order.append(("channel", rec.id))

    def _known(self, cid: int) -> _Channel | None:
        """The channel ``cid``; from the summary when its own record was not found (damaged or cut)."""
        if cid not in self.channels and self.summary is not None and cid in self.summary.channels:
            self._channel(self.summary.channels[cid])
        return self.channels.get(cid)

    def _chunk(self, pos: int, body: memoryview) -> None:
        try:
            chunk = m.parse_chunk(body)
            data = m.decompress_chunk(chunk)
            found: list[tuple[int, int, memoryview]] = []
            for op, _, rec in m.iter_records(data):
                if op == m.Op.SCHEMA:
                    self._schema(m.parse_schema(rec))
                elif op == m.Op.CHANNEL:
                    self._channel(m.parse_channel(rec))
                elif op == m.Op.MESSAGE:
                    if len(rec) < 22:
                        raise m.McapFormatError("message record too short")
                    cid = m._H.unpack_from(rec, 0)[0]
                    found.append((cid, m._Q.unpack_from(rec, 6)[0], rec[22:]))
        except (m.McapFormatError, struct.error, ValueError) as exc:
            self.failed_chunk, self.failed_channels = pos, set()
            self.report.lost.append(f"chunk at byte {pos}: {exc}")
            ci = self._indexed.get(pos)  # the summary (CRC-checked) says which channels the chunk held
            for cid in ci.message_index_offsets if ci is not None else ():
                self._mark_lost(cid, 0)
            return
        self.failed_chunk = None
        kept: set[int] = set()
        for cid, _, payload in found:
            ch = self._known(cid)
            if ch is None:
                self.report.lost.append(f"chunk at byte {pos}: message of unknown channel {cid} dropped")
                continue
            ch.add(payload)
            kept.add(cid)
        for cid in kept:
            ch = self.channels[cid]
            ch.chunks_kept += 1
            ch.sources.append((pos, pos + 9 + len(body), None))

    def _message_index(self, body: memoryview) -> None:
        """Message indexes follow their chunk: they tell which channels a damaged chunk held."""
        if self.failed_chunk is None or len(body) < 6:
            return
        cid, n = m._H.unpack_from(body, 0)[0], m._I.unpack_from(body, 2)[0]
        self._mark_lost(cid, n // 16)

    def _mark_lost(self, cid: int, messages: int) -> None:
        """The failed chunk held messages of channel ``cid``: count it lost there."""
        ch = self._known(cid)
        if cid not in self.failed_channels:
            self.failed_channels.add(cid)
            if ch is not None:
                ch.chunks_lost += 1
                ch.sources.append((self.failed_chunk or 0, LOST_SOURCE, None))
            self.report.lost[-1] += f"; held messages of channel {ch.rec.topic if ch else cid}"
        if ch is not None and messages:
            ch.messages_lost += messages
            self.report.lost[-1] += f" ({messages})"

    def _record(self, op: int, pos: int, body: memoryview) -> bool:
        """Take one record; False when it could not be used (damaged)."""
        n_lost = len(self.report.lost)
        self._take(op, pos, body)
        return len(self.report.lost) == n_lost or op == m.Op.MESSAGE_INDEX

    def _take(self, op: int, pos: int, body: memoryview) -> None:
        if op == m.Op.HEADER:
            c = m.Cursor(body)
            self.header = (c.string(), c.string())
        elif op == m.Op.SCHEMA:
            self._schema(m.parse_schema(body))
        elif op == m.Op.CHANNEL:
            self._channel(m.parse_channel(body))
        elif op == m.Op.MESSAGE:
            cid = m._H.unpack_from(body, 0)[0]
            ch = self._known(cid)
            if ch is None:
                self.report.lost.append(f"message at byte {pos}: unknown channel {cid}")
            else:
                ch.add(body[22:])
                ch.sources.append((m._Q.unpack_from(body, 6)[0], -1, body[22:]))
        elif op == m.Op.CHUNK:
            self._chunk(pos, body)
            return
        elif op == m.Op.MESSAGE_INDEX:
            self._message_index(body)
            return
        elif op == m.Op.ATTACHMENT:
            rec = m.parse_attachment(body)
            if rec.crc != 0 and rec.crc != rec.computed_crc:
                self.report.lost.append(f"attachment {rec.name!r} at byte {pos}: CRC mismatch (damaged), dropped")
            else:
                self.order.append(("attachment", (pos, pos + 9 + len(body))))  # data read again when written
                self.attachment_sha[rec.name] = sha256_of(unpack(rec.data, rec.media_type))  # the original's
        elif op == m.Op.METADATA:
            c = m.Cursor(body)
            name, items = c.string(), c.str_map()
            if c.pos != len(body):
                raise m.McapFormatError("metadata record longer than its content")
            self.order.append(("metadata", (name, items, pos, pos + 9 + len(body))))
        self.failed_chunk = None

    # ------------------------------------------------------------------ scanning
    def _next_start(self, after: int) -> int | None:
        """The next offset after ``after`` where a record plausibly starts (summary hints, then patterns)."""
        best = None
        for h in self.hints:
            if h > after:
                best = h
                break
        buf = self.buf
        for pattern, back, op in (
            (b"\x04\x00\x00\x00zstd", _CHUNK_FIXED + 9, m.Op.CHUNK),
            (b"\x03\x00\x00\x00lz4", _CHUNK_FIXED + 9, m.Op.CHUNK),
            (b"imulog.", 4 + 9, m.Op.METADATA),
        ):
            start = after + back + 1
            limit = best if best is not None else self.size
            while start < limit:
                k = _find(buf, pattern, start, limit)
                if k < 0:
                    break
                cand = k - back
                if buf[cand] == op and self._plausible(cand):
                    if best is None or cand < best:
                        best = cand
                    break
                start = k + 1
        return best

    def _plausible(self, pos: int) -> bool:
        if pos + 9 > self.size:
            return False
        op, length = m._REC.unpack_from(self.buf, pos)
        return op in _KNOWN_OPS and pos + 9 + length <= self.size

    def run(self) -> None:
        pos = len(m.MAGIC)
        size = self.size
        while pos < size:
            if pos + 9 > size:
                self.report.lost.append(f"file ends inside a record header at byte {pos}")
                break
            op, length = m._REC.unpack_from(self.buf, pos)
            end = pos + 9 + length
            if op == m.Op.DATA_END or op == m.Op.FOOTER:
                self._data_end(pos, op)
                break  # the summary follows: everything in it is rebuilt
            if op not in _KNOWN_OPS or end > size:
                why = "truncated" if op in _KNOWN_OPS else f"unknown opcode {op:#04x}"
                nxt = self._next_start(pos)
                self._lost_range(pos, nxt, why, op)
                if nxt is None:
                    break
                pos = nxt
                continue
            try:
                ok = self._record(op, pos, self.buf[pos + 9 : end])
            except (m.McapFormatError, struct.error, ValueError, UnicodeDecodeError) as exc:
                self.report.lost.append(f"{m.OP_NAMES.get(op, hex(op))} record at byte {pos}: {exc}")
                ok = False
                if op == m.Op.METADATA:  # named by the summary's index when it has one
                    names = [x.name for x in self.summary.metadata_indexes if x.offset == pos] if self.summary else []
                    self.report.dropped_metadata.append(f"{(names or ['?'])[0]} at byte {pos}: {exc}")
            if ok:
                last = self.regions[-1] if self.regions else None
                if op == m.Op.MESSAGE and last is not None and last[2] == op and last[1] == pos:
                    self.regions[-1] = (last[0], end, op)  # messages outside chunks: one region per run of them
                else:
                    self.regions.append((pos, self._unchecked_end(op, pos, end), op))
            if not ok and not (end == size or self._plausible(end)):
                # its length field may be what is damaged: find the next record instead of trusting it
                nxt = self._next_start(pos)
                if nxt is None:
                    break
                end = nxt
            elif self.crc_upto == pos:
                self.crc = zlib.crc32(self.buf[pos:end], self.crc)
                self.crc_upto = end
            if end - self.released > RELEASE_BYTES:
                release(self.buf, self.released, end)
                self.released = end
            pos = end

    def _unchecked_end(self, op: int, pos: int, end: int) -> int:
        """End of the part of a good record that no CRC of its own covers (a chunk's or attachment's head)."""
        if op == m.Op.ATTACHMENT:
            return pos + 9  # the attachment's CRC covers the rest of it
        if op == m.Op.CHUNK and self.failed_chunk is None:
            n = m._I.unpack_from(self.buf, pos + 9 + _CHUNK_FIXED)[0]
            return min(end, pos + 9 + _CHUNK_FIXED + 4 + n + 8)  # the compressed data are checked by the chunk CRC
        return end

    def _data_end(self, pos: int, op: int) -> None:
        if op != m.Op.DATA_END or pos + 13 > self.size:
            return
        self.data_end = pos
        stored = m._I.unpack_from(self.buf, pos + 9)[0]
        self.stored_crc = stored
        if stored == 0:
            self.report.data_crc = "not recorded"
            self.report.notes.append("the data section CRC was not recorded")
        elif self.crc_upto == pos and self.crc == stored:
            self.report.data_crc = "ok"
            self.report.notes.append("data section CRC ok: every record was read as written")
        else:
            self.report.data_crc = "mismatch"
            self.report.notes.append(
                "data section CRC mismatch: chunks and attachments were checked by their own CRCs; "
                "schema, channel and metadata records have none, so a damaged one cannot be ruled out"
            )

    def _lost_range(self, pos: int, nxt: int | None, why: str, op: int) -> None:
        what = m.OP_NAMES.get(op, "record") if op in _KNOWN_OPS else "record"
        stop = f"up to byte {nxt}" if nxt is not None else "to the end of the file"
        self.report.lost.append(f"{what} at byte {pos} {why}: bytes {stop} skipped")


def _find(buf: memoryview, pattern: bytes, start: int, end: int) -> int:
    return buf.obj.find(pattern, start, end) if hasattr(buf.obj, "find") else bytes(buf[start:end]).find(pattern)


__all__ = ["LOST_SOURCE", "SalvageReport", "release"]
