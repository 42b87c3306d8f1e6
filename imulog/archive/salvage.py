"""Recover the intact parts of a truncated or damaged MCAP file into a new, sound trial file.

    report = salvage("broken.mcap", "fixed.mcap")
    print(report.lines())            # what was recovered, what was lost

The input is only read (memory-mapped, pages handed back as the scan passes them: memory about one chunk). Its records are scanned linearly from the start, so a missing or
damaged summary does not matter; after a damaged record the scan resynchronises on the next record that
the summary (when readable) indexes, or on the next plausible Chunk / Metadata record header. Every chunk
is decompressed within its declared size and checked against its CRC before any of its messages is kept;
attachments are checked against their CRC. Schemas and channels may sit at top level (imulog) or inside
chunks (the ``mcap`` library's writer). The output is written like every imulog file (temporary file,
fsync, rename): raw and derived channels, attachments and metadata records in their original order, plus
an ``imulog.salvage`` record listing what was lost (``data_crc`` "mismatch" there makes ``imulog doctor`` reject
the output: its schema, channel and metadata records, which have no CRC of their own, may be damaged). Channels that lost chunks keep only their intact
messages; their ``sha256`` (and ``sample_count`` for imulog schemas) are recomputed and ``salvaged`` says
how many chunks were lost, so ``imulog doctor`` on the output then reports the raw-data hash recorded at
conversion as changed: the recording is no longer complete.
"""

from __future__ import annotations

import contextlib
import hashlib
import mmap
import os
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imulog import __version__
from imulog.archive import _mcap as m
from imulog.archive import codec
from imulog.archive._builder import CHUNK_TARGET_BYTES, McapBuilder
from imulog.archive.errors import ArchiveError, ArchiveExistsError
from imulog.archive.files import atomic_output, target_path, writer_lock
from imulog.archive.metadata import encode_record

_KNOWN_OPS = set(range(m.Op.HEADER, m.Op.DATA_END + 1))
RELEASE_BYTES = 32 << 20  # hand mapped pages back to the kernel every this many bytes


def release(buf: memoryview, start: int, end: int) -> None:
    """Drop the mapped pages of ``buf[start:end]`` from this process's RSS (they are re-read if touched)."""
    page = mmap.PAGESIZE
    lo, hi = -(-start // page) * page, end // page * page
    if hi > lo:
        with contextlib.suppress(AttributeError, OSError, ValueError):  # not a map, or no madvise here
            buf.obj.madvise(mmap.MADV_DONTNEED, lo, hi - lo)


_CHUNK_FIXED = 8 + 8 + 8 + 4  # start, end, uncompressed size, crc before the compression string


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
    channels: dict[str, dict[str, int]] = field(default_factory=dict)  # topic -> messages, chunks kept/lost
    attachments: list[str] = field(default_factory=list)
    metadata: list[str] = field(default_factory=list)
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
            "lost": self.lost,
            "notes": self.notes,
        }


class _Scan:
    """One linear pass over the records of a (possibly damaged) MCAP file."""

    def __init__(self, buf: memoryview, size: int, report: SalvageReport, hints: list[int]) -> None:
        self.buf = buf
        self.size = size
        self.report = report
        self.hints = sorted(set(hints))
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
            return
        self.failed_chunk = None
        kept: set[int] = set()
        for cid, _, payload in found:
            ch = self.channels.get(cid)
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
        if cid in self.failed_channels:
            return
        self.failed_channels.add(cid)
        ch = self.channels.get(cid)
        if ch is not None:
            ch.chunks_lost += 1
            ch.messages_lost += n // 16
        self.report.lost[-1] += f"; held {n // 16} messages of channel {ch.rec.topic if ch else cid}"

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
            ch = self.channels.get(cid)
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
        elif op == m.Op.METADATA:
            c = m.Cursor(body)
            name, items = c.string(), c.str_map()
            if c.pos != len(body):
                raise m.McapFormatError("metadata record longer than its content")
            self.order.append(("metadata", (name, items)))
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

    def _data_end(self, pos: int, op: int) -> None:
        if op != m.Op.DATA_END or pos + 13 > self.size:
            return
        stored = m._I.unpack_from(self.buf, pos + 9)[0]
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


def _summary_hints(f, size: int, report: SalvageReport) -> list[int]:
    """Record offsets the summary indexes (empty when the summary is missing or damaged)."""
    try:
        s = m.read_summary(f, size)
    except m.McapFormatError as exc:
        report.notes.append(f"summary not usable ({exc}): records found by scanning")
        return []
    report.summary_found = True
    return (
        [ci.chunk_start_offset for ci in s.chunk_indexes]
        + [a.offset for a in s.attachment_indexes]
        + [x.offset for x in s.metadata_indexes]
    )


def _messages(buf: memoryview, ch: _Channel):
    """The channel's intact (log time, payload) pairs, one source chunk decompressed at a time."""
    for first, end, payload in ch.sources:
        if end < 0:
            yield first, payload
            continue
        data = m.decompress_chunk(m.parse_chunk(buf[first + 9 : end]))  # checked in the scan: same bytes
        release(buf, first, end)
        for cid, log_time, p in m.chunk_messages(data, ch.rec.id):
            if cid == ch.rec.id:
                yield log_time, p


def _channel_meta(buf: memoryview, ch: _Channel, schema: m.SchemaRec | None) -> dict[str, str]:
    """Channel metadata for the output: as found, or recomputed where chunks were lost."""
    meta = dict(ch.rec.metadata)
    if not ch.chunks_lost:
        return meta
    meta["salvaged"] = f"partial: {ch.chunks_lost} chunk(s), {ch.messages_lost} message(s) lost"
    if "sha256" in meta:
        meta["salvaged_original_sha256"] = meta["sha256"]
        meta["sha256"] = ch.hasher.hexdigest()
    if schema is not None and schema.name in codec.MESSAGE_CLASSES and "sample_count" in meta:
        try:
            n = 0
            for batch in _batches(_messages(buf, ch), 1 << 20):
                n += len(codec.decode(schema.name, ch.rec.topic, ch.rec.metadata, [p for _, p in batch]))
            meta["sample_count"] = str(n)
        except Exception:  # noqa: BLE001 - the count is informative; keep the data even if it will not decode
            meta.pop("sample_count")
    return meta


def _batches(pairs, target_bytes: int):
    """Group (log time, payload) pairs into lists of about ``target_bytes`` of payload."""
    batch, size = [], 0
    for pair in pairs:
        batch.append(pair)
        size += len(pair[1])
        if size >= target_bytes:
            yield batch
            batch, size = [], 0
    if batch:
        yield batch


def salvage(src: str | os.PathLike[str], dst: str | os.PathLike[str], *, overwrite: bool = False) -> SalvageReport:
    """Write every intact channel, attachment and metadata record of ``src`` to ``dst``; report the losses.

    ``src`` is never modified. ``dst`` appears atomically (or not at all); ArchiveError when ``dst`` is
    ``src``, exists without ``overwrite``, or nothing at all could be recovered.
    """
    src_path, dst_path = Path(src), target_path(dst)
    report = SalvageReport(src_path)
    try:
        f = open(src_path, "rb")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise ArchiveError(f"{src_path}: {exc.strerror or exc}") from None
    with f:
        if dst_path.exists() and os.path.samefile(src_path, dst_path):
            raise ArchiveError(f"{dst_path}: the output must not be the input (salvage never modifies it)")
        size = os.fstat(f.fileno()).st_size
        head = f.read(len(m.MAGIC))
        if head != m.MAGIC:
            raise ArchiveError(f"{src_path}: not an MCAP file (no magic at the start): nothing to salvage")
        hints = _summary_hints(f, size, report)
        mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        scan = _Scan(memoryview(mm), size, report, hints)
        scan.run()
        _write(scan, scan.buf, dst_path, report, overwrite)
        del scan  # views into the map go with it; the map itself is unmapped when collected
    return report


def _write(scan: _Scan, buf: memoryview, dst: Path, report: SalvageReport, overwrite: bool) -> None:
    if not scan.order:
        raise ArchiveError(f"{report.source}: no intact channel, attachment or metadata record found")
    for ch in scan.channels.values():
        if ch.rec.schema_id != 0 and ch.rec.schema_id not in scan.schemas:
            report.lost.append(f"channel {ch.rec.topic}: its schema {ch.rec.schema_id} was lost; channel dropped")
    dst.parent.mkdir(parents=True, exist_ok=True)
    with writer_lock(dst):
        if dst.exists() and not overwrite:
            raise ArchiveExistsError(f"{dst} exists (use overwrite=True / --overwrite)")
        with atomic_output(dst) as out:
            profile, library = scan.header
            b = McapBuilder.new(out, f"imulog {__version__} salvage of {library or 'unknown writer'}", profile)
            for kind, item in scan.order:
                if kind == "channel":
                    ch = scan.channels[item]
                    schema = scan.schemas.get(ch.rec.schema_id)
                    if ch.rec.schema_id != 0 and schema is None:
                        continue
                    sid = b.add_schema(schema.name, schema.encoding, schema.data) if schema is not None else 0
                    meta = _channel_meta(buf, ch, schema)
                    new_id = b.add_channel(ch.rec.topic, sid, meta, ch.rec.message_encoding)
                    for batch in _batches(_messages(buf, ch), CHUNK_TARGET_BYTES):  # memory: about one chunk
                        b.add_messages(new_id, [t for t, _ in batch], [bytes(p) for _, p in batch])
                    report.channels[ch.rec.topic] = {
                        "messages": ch.messages,
                        "chunks_kept": ch.chunks_kept,
                        "chunks_lost": ch.chunks_lost,
                    }
                elif kind == "attachment":
                    a = m.parse_attachment(buf[item[0] + 9 : item[1]])  # CRC-checked in the scan
                    b.add_attachment(a.name, a.media_type, a.data, a.log_time, a.create_time)
                    report.attachments.append(a.name)
                else:
                    name, items = item
                    b.add_metadata(name, dict(items))
                    report.metadata.append(name)
            record = {
                "source": str(report.source),
                "summary_found": report.summary_found,
                "data_crc": report.data_crc,
                "lost": report.lost[:1000],
                "partial_channels": sorted(t for t, c in report.channels.items() if c["chunks_lost"]),
                "imulog_version": __version__,
            }
            b.add_metadata("imulog.salvage", encode_record(record))
            b.finish()
    report.output = dst


def lines(report: SalvageReport) -> list[str]:
    """A human summary of a salvage report, one line each."""
    out = [
        f"recovered {len(report.channels)} channels, {len(report.attachments)} attachments, "
        f"{len(report.metadata)} metadata records" + (f" into {report.output}" if report.output else "")
    ]
    for topic, c in report.channels.items():
        if c["chunks_lost"]:
            out.append(f"  partial: {topic}: {c['messages']} messages kept, {c['chunks_lost']} chunk(s) lost")
    out += [f"  lost: {x}" for x in report.lost]
    out += [f"  note: {x}" for x in report.notes]
    return out


__all__ = ["SalvageReport", "lines", "salvage"]
