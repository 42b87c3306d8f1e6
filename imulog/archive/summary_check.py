"""Defects of an MCAP summary that a rewrite would hide, and what a writer does about each.

Every write of an existing trial (a step's append, a replace, a removal) copies the data section and writes
a new summary from the old one. Some summary defects the new summary no longer has: without a word, a file
``imulog doctor`` rejects would then pass it. :func:`summary_defects` finds them from the summary alone (no
read of the data section) and says, per defect, whether the rewrite repairs it (the writer goes on, prints one
line on stderr and writes an ``imulog.repair.<n>`` record) or refuses it (with the message ``doctor`` gives):

| defect | decision | why |
|---|---|---|
| a chunk indexed more than once | repaired | the copies add nothing: readers read the chunk once, the new summary lists it once |
| an attachment or metadata record indexed more than once | repaired | the same |
| summary offsets that do not match the summary | repaired | they only point into the summary, which is written anew |
| statistics totals that disagree with the summary's own records (schema, channel, chunk, attachment, metadata and message counts, message start and end) | repaired | the new totals are counted from those records |
| statistics that count a channel the summary does not have | repaired | the new statistics list the summary's channels |
| no statistics record | refused | per-channel message counts cannot be rebuilt without reading every chunk |
| statistics without a count for one of the summary's channels | refused | the same |

Defects between the summary and the data section (an index pointing at the wrong record, a channel record
that differs, a chunk left out of the index, a wrong per-channel count) are refused as well, with doctor's
message: :mod:`imulog.archive.summary_walk` finds them from the record heads before the rewrite.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from imulog.archive import _mcap as m

DUPLICATE_RECORDS = "summary indexes the same attachment or metadata record more than once ({n} extra entries)"
DUPLICATE_CHUNKS = "summary indexes the same chunk more than once ({n} extra entries)"
SUMMARY_OFFSET = "summary offset for {op} records does not match the summary"
NO_STATISTICS = "summary has no statistics record"
CHANNEL_COUNTS = "statistics per-channel message counts disagree with the data"


@dataclass(frozen=True)
class SummaryDefect:
    """One defect: ``message`` as ``doctor`` words it; ``repaired`` when a rewrite rebuilds what it concerns."""

    message: str
    repaired: bool


def chunk_time_span(chunks: Iterable[m.ChunkIndexRec]) -> tuple[int, int]:
    """The earliest message start and latest message end time (ns) of ``chunks``, one pass; (0, 0) for none."""
    start = end = None
    for c in chunks:
        start = c.message_start_time if start is None else min(start, c.message_start_time)
        end = c.message_end_time if end is None else max(end, c.message_end_time)
    return (0, 0) if start is None else (start, end)


def offsets_problems(summary: m.Summary) -> list[str]:
    """Summary offset records that do not span the records of their opcode (doctor's wording)."""
    out = []
    starts = {off: (op, ln) for op, off, ln in summary.summary_records}
    for op, start, length in summary.summary_offsets:
        pos, end = start, start + length
        while pos < end and pos in starts and starts[pos][0] == op:
            pos += starts[pos][1]
        if pos != end:
            out.append(SUMMARY_OFFSET.format(op=m.OP_NAMES.get(op, hex(op))))
    return out


def summary_defects(summary: m.Summary) -> list[SummaryDefect]:
    """Every defect of ``summary`` that a rewrite would remove or hide (see the module's table)."""
    out = []
    if summary.duplicate_chunk_indexes:
        out.append(SummaryDefect(DUPLICATE_CHUNKS.format(n=summary.duplicate_chunk_indexes), True))
    if summary.duplicate_record_indexes:
        out.append(SummaryDefect(DUPLICATE_RECORDS.format(n=summary.duplicate_record_indexes), True))
    out += [SummaryDefect(p, True) for p in offsets_problems(summary)]
    st = summary.statistics
    if st is None:
        return [*out, SummaryDefect(NO_STATISTICS, False)]
    counts = st.channel_message_counts
    if set(summary.channels) - set(counts):
        out.append(SummaryDefect(CHANNEL_COUNTS, False))
    extra = sorted(set(counts) - set(summary.channels))
    if extra:
        out.append(
            SummaryDefect(f"statistics count messages of channels {extra}, which the summary does not have", True)
        )
    expect = {
        "message_count": sum(counts.get(cid, 0) for cid in summary.channels),
        "schema_count": len(summary.schemas),
        "channel_count": len(summary.channels),
        "attachment_count": len(summary.attachment_indexes),
        "metadata_count": len(summary.metadata_indexes),
        "chunk_count": summary.chunk_count,
    }
    if summary.chunk_count:  # (messages outside chunks, another writer's, are not in the chunk indexes)
        # one index at a time (issue 24: a week's ~10,000 ChunkIndex objects, ~0.9 KB each, are not built)
        start, end = chunk_time_span(summary.iter_chunk_indexes())
        expect["message_start_time"], expect["message_end_time"] = start, end
    for key, value in expect.items():
        if getattr(st, key) != value:
            out.append(
                SummaryDefect(f"statistics {key} = {getattr(st, key)}, the summary's records give {value}", True)
            )
    return out


__all__ = ["SummaryDefect", "chunk_time_span", "offsets_problems", "summary_defects"]
