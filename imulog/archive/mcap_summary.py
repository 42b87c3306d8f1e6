"""An MCAP file's summary section: where it is (footer, data end), its records (schemas, channels, chunk
indexes kept as bytes until a read needs them, attachment and metadata indexes, statistics) and single records
read at an offset. Part of :mod:`imulog.archive._mcap`."""

from __future__ import annotations

import struct
import zlib
from array import array
from bisect import bisect_left
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import BinaryIO

from imulog.archive.mcap_parse import (
    _CI_ENTRY,
    _CI_HEAD,
    _chunk_index_is_plain,
    _parse_chunk_index_fields,
    iter_records,
    parse_attachment_index,
    parse_channel,
    parse_chunk_index,
    parse_metadata_index,
    parse_schema,
    parse_statistics,
)
from imulog.archive.mcap_records import (
    _I,
    _Q,
    _REC,
    DATA_END_SIZE,
    FOOTER_SIZE,
    MAGIC,
    OP_NAMES,
    AttachmentIndexRec,
    ChannelRec,
    ChunkIndexRec,
    McapFormatError,
    MetadataIndexRec,
    Op,
    SchemaRec,
    StatisticsRec,
)

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
    _by_offset: tuple[array, array] | None = field(default=None, repr=False)  # chunk offsets sorted, their order

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
        self._by_offset = None

    @property
    def chunk_count(self) -> int:
        """How many chunks the summary indexes (duplicates dropped), without parsing their indexes."""
        if self._chunk_indexes is not None:
            return len(self._chunk_indexes)
        return len(self._chunk_spans) // 2

    def iter_chunk_indexes(self) -> Iterator[ChunkIndexRec]:
        """Every ChunkIndex in summary order, one at a time: parsed from the kept bytes and not kept (a pass
        over a week's ~10,000 indexes holds one), or the parsed list once ``chunk_indexes`` was used."""
        if self._chunk_indexes is not None:
            yield from self._chunk_indexes
            return
        spans, section = self._chunk_spans, memoryview(self._section)
        for i in range(0, len(spans), 2):
            yield parse_chunk_index(section[spans[i] : spans[i] + spans[i + 1]])

    def chunk_index_at(self, offset: int) -> ChunkIndexRec | None:
        """The ChunkIndex of the chunk starting at byte ``offset`` (None: not indexed), parsed alone; the lookup
        table is 16 bytes a chunk (two arrays sorted by offset), built on first use."""
        if self._by_offset is None:
            if self._chunk_indexes is not None:
                offsets = array("Q", [ci.chunk_start_offset for ci in self._chunk_indexes])
            else:
                spans, section = self._chunk_spans, self._section
                offsets = array("Q", [_Q.unpack_from(section, spans[i] + 16)[0] for i in range(0, len(spans), 2)])
            order = array("Q", sorted(range(len(offsets)), key=offsets.__getitem__))
            self._by_offset = (array("Q", [offsets[i] for i in order]), order)
        offsets, order = self._by_offset
        k = bisect_left(offsets, offset)
        if k == len(offsets) or offsets[k] != offset:
            return None
        i = order[k]
        if self._chunk_indexes is not None:
            return self._chunk_indexes[i]
        lo, n = self._chunk_spans[2 * i], self._chunk_spans[2 * i + 1]
        return parse_chunk_index(memoryview(self._section)[lo : lo + n])

    def _chunk_heads(self) -> Iterator[tuple[int, int, int, int, list[int]]]:
        """(message start and end time in ns, chunk offset, chunk length in bytes, channel ids) of every ChunkIndex
        in summary order: from the parsed list when built, else straight from the kept bytes (nothing kept)."""
        if self._chunk_indexes is not None:
            for ci in self._chunk_indexes:
                ids = list(ci.message_index_offsets)
                yield ci.message_start_time, ci.message_end_time, ci.chunk_start_offset, ci.chunk_length, ids
            return
        spans, section = self._chunk_spans, self._section
        for i in range(0, len(spans), 2):
            lo = spans[i]
            start, end, offset, length, map_len = _CI_HEAD.unpack_from(section, lo)
            entries = section[lo + _CI_HEAD.size : lo + _CI_HEAD.size + map_len]
            yield start, end, offset, length, [cid for cid, _ in _CI_ENTRY.iter_unpack(entries)]

    def channel_chunks(self, channel_id: int) -> tuple[array, array, array, array]:
        """Chunk offsets, message start and end times (ns) and numbers (for :meth:`chunk_index_number`) of the
        chunks holding ``channel_id``, in summary order, read without building ChunkIndex records (32 bytes a
        chunk of the channel)."""
        offsets, starts, ends, numbers = array("Q"), array("Q"), array("Q"), array("Q")
        for k, (start, end, offset, _, ids) in enumerate(self._chunk_heads()):
            if channel_id in ids:
                offsets.append(offset)
                starts.append(start)
                ends.append(end)
                numbers.append(k)
        return offsets, starts, ends, numbers

    def chunk_index_number(self, k: int) -> ChunkIndexRec:
        """The ``k``-th ChunkIndex in summary order (duplicates dropped), parsed alone unless the list is parsed."""
        if self._chunk_indexes is not None:
            return self._chunk_indexes[k]
        lo, n = self._chunk_spans[2 * k], self._chunk_spans[2 * k + 1]
        return parse_chunk_index(memoryview(self._section)[lo : lo + n])

    @property
    def summary_records(self) -> list[tuple[int, int, int]]:
        """(opcode, file offset, total length) of every record of the summary section, in order."""
        r = self._records
        return [(r[i], r[i + 1], r[i + 2]) for i in range(0, len(r), 3)]

    def stored_bytes_by_channel(self) -> dict[int, int]:
        """Compressed chunk bytes per channel id (a chunk's length shared evenly among its channels), read
        straight from the ChunkIndex records without building them."""
        out: dict[int, int] = {}
        for *_, length, ids in self._chunk_heads():
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
