"""The summary against the data section from the record heads alone, for writers (no chunk is decompressed).

``doctor`` checks that every index of the summary points at the record it describes (chunks, message indexes,
attachments, metadata), that the schema and channel records match and that the statistics count what the data
holds; it reads every chunk to do so. A write of an existing trial copies the data section and writes a new
summary: :func:`summary_problems` runs doctor's own summary checks on what the heads of the records say (chunk
times and sizes from the chunk header, message counts from the message indexes), so a writer can refuse, with
doctor's message, a file whose summary disagrees with its data, instead of copying the disagreement or, when
the records concerned are the ones it replaces, silently dropping it.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

from imulog.archive import _mcap as m
from imulog.archive.chunk_check import ChunkSeen, ChunkTally


def _body(f: BinaryIO, pos: int, n: int) -> bytes:
    f.seek(pos + 9)
    return f.read(n)


def _string(data: bytes, at: int) -> tuple[str, int]:
    n = m._I.unpack_from(data, at)[0]
    return bytes(data[at + 4 : at + 4 + n]).decode(), at + 4 + n


def walk_heads(f: BinaryIO, summary: m.Summary) -> dict | None:
    """What doctor's walk finds, read from record heads; None when the heads cannot tell (a chunk without
    message indexes, a record that does not parse: the data-section CRC check of the copy decides then).

    Chunks are compared with the summary's index as the walk passes them (``found["tally"]``,
    :class:`~imulog.archive.chunk_check.ChunkTally`): one chunk and its message indexes are held at a time, not
    a dict of every chunk (issue 24). A chunk index must point at message indexes that follow its chunk."""
    from imulog.archive.doctor import empty_found

    found = empty_found()
    tally = found["tally"] = ChunkTally()
    limit, pos, last = summary.data_end_offset, len(m.MAGIC), None
    indexes: dict[int, int] = {}  # the current chunk's message indexes: offset -> channel id

    def close() -> bool:  # the chunk before ``pos`` is complete: check it; False when the heads cannot tell
        if last is None:
            return True
        if not last.counts:
            return False
        tally.add(summary, last, indexes.get)
        return True

    try:
        while pos < limit:
            f.seek(pos)
            head = f.read(9)
            if len(head) < 9:
                return None
            op, length = m._REC.unpack(head)
            if pos + 9 + length > limit:
                return None
            if op == m.Op.SCHEMA:
                rec = m.parse_schema(_body(f, pos, length))
                found["schemas"][rec.id] = rec
            elif op == m.Op.CHANNEL:
                rec = m.parse_channel(_body(f, pos, length))
                found["channels"][rec.id] = rec
            elif op == m.Op.CHUNK:
                h = _body(f, pos, min(length, 1024))
                start, end, usize = struct.unpack_from("<QQQ", h, 0)
                compression, at = _string(h, 28)
                (csize,) = m._Q.unpack_from(h, at)
                if not close():
                    return None
                last = ChunkSeen(pos, 9 + length, start, end, csize, usize, compression, {})
                indexes = {}
            elif op == m.Op.MESSAGE_INDEX:
                h = _body(f, pos, 6)
                cid, n = m._H.unpack_from(h, 0)[0], m._I.unpack_from(h, 2)[0]
                if last is None:
                    return None
                indexes[pos] = cid
                last.message_index_length += 9 + length
                if n // 16:
                    last.counts[cid] = last.counts.get(cid, 0) + n // 16
                    found["counts"][cid] += n // 16
            elif op == m.Op.MESSAGE:
                found["counts"][m._H.unpack_from(_body(f, pos, 2), 0)[0]] += 1
            elif op == m.Op.ATTACHMENT:
                h = _body(f, pos, min(length, 1 << 16))
                log_time, create_time = struct.unpack_from("<QQ", h, 0)
                name, at = _string(h, 16)
                media_type, at = _string(h, at)
                (size,) = m._Q.unpack_from(h, at)
                found["attachments"][pos] = ((name, media_type, size, log_time, create_time), 9 + length)
            elif op == m.Op.METADATA:
                name, _ = _string(_body(f, pos, min(length, 1 << 16)), 0)
                found["metadata"][pos] = (name, 9 + length)
            pos += 9 + length
    except (m.McapFormatError, struct.error, ValueError, UnicodeDecodeError):
        return None
    if not close():
        return None
    # schemas and channels inside chunks (another writer's) are not seen without decompressing: the summary's
    for sid, rec in summary.schemas.items():
        found["schemas"].setdefault(sid, rec)
    for cid, rec in summary.channels.items():
        found["channels"].setdefault(cid, rec)
    return found


def summary_problems(f: BinaryIO, summary: m.Summary, repaired: set[str]) -> list[str]:
    """Doctor's messages for the summary's disagreements with the data section that a rewrite would not repair
    (``repaired``: the messages of :func:`imulog.archive.summary_check.summary_defects` it repairs)."""
    from imulog.archive.doctor import DoctorReport, _check_summary

    found = walk_heads(f, summary)
    if found is None:
        return []
    report = DoctorReport(Path(""))
    _check_summary(summary, found, report)
    st = summary.statistics
    counts_ok = st is not None and all(
        st.channel_message_counts.get(cid) == found["counts"].get(cid, 0) for cid in found["channels"]
    )
    out = []
    for p in report.problems:
        if p in repaired or p.startswith("statistics ") and not p.startswith("statistics per-channel"):
            continue  # recounted from the summary's indexes (an index that disagrees with the data is refused)
        if p.startswith("statistics per-channel") and counts_ok:
            continue  # only counts of channels the summary does not have: dropped by the rewrite
        out.append(p)
    return out


__all__ = ["summary_problems", "walk_heads"]
