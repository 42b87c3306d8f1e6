"""Chunks of the data section against the summary's ChunkIndex records, one chunk at a time.

``doctor`` (which reads every chunk) and the writers' walk of record heads
(:mod:`imulog.archive.summary_walk`, run before every append) compare each chunk they pass with the index the
summary gives for its offset. :class:`ChunkTally` keeps only what the summary check needs of the chunks seen
(count, first and last message time, the problems found), so the walk holds one chunk's details at a time:
a week's two-IMU trial has about 10,000 chunks, and a dict of every chunk and message index grew an append's
memory with the recording (issue 24).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from imulog.archive import _mcap as m


@dataclass
class ChunkSeen:
    """A chunk as the data section has it (its header and the message indexes that follow it)."""

    offset: int
    length: int
    start: int
    end: int
    compressed_size: int
    uncompressed_size: int
    compression: str
    counts: dict[int, int]
    message_index_length: int = 0


def chunk_index_problems(
    off: int, ci: m.ChunkIndexRec, seen: ChunkSeen, index_channel: Callable[[int], int | None]
) -> list[str]:
    """Doctor's messages where the ChunkIndex ``ci`` disagrees with the chunk ``seen`` at byte ``off``;
    ``index_channel(offset)``: the channel id of the MessageIndex record at that offset (None: there is none)."""
    out = []
    if (ci.chunk_length, ci.message_start_time, ci.message_end_time, ci.compressed_size, ci.uncompressed_size) != (
        seen.length,
        seen.start,
        seen.end,
        seen.compressed_size,
        seen.uncompressed_size,
    ):
        out.append(f"chunk index for byte {off} disagrees with the chunk")
    if (ci.compression, ci.message_index_length) != (seen.compression, seen.message_index_length):
        out.append(f"chunk index for byte {off} has the wrong compression or message index length")
    if set(ci.message_index_offsets) != set(seen.counts):
        out.append(
            f"chunk index for byte {off} lists channels {sorted(ci.message_index_offsets)}, chunk has {sorted(seen.counts)}"
        )
    for cid, mi_off in ci.message_index_offsets.items():
        if index_channel(mi_off) != cid:
            out.append(f"chunk index for byte {off} points at no message index of channel {cid}")
    return out


@dataclass
class ChunkTally:
    """What the summary check needs of the data section's chunks, gathered chunk by chunk."""

    count: int = 0  # chunks seen
    unindexed: int = 0  # chunks seen that the summary does not index
    start: int | None = None  # earliest message start time of the chunks seen, ns
    end: int | None = None  # latest message end time, ns
    problems: list[str] = field(default_factory=list)  # per-chunk disagreements, in file order
    parse_error: str | None = None  # the summary's chunk indexes do not parse

    def add(self, summary: m.Summary, seen: ChunkSeen, index_channel: Callable[[int], int | None]) -> None:
        """Count ``seen`` and compare it with the summary's index for its offset."""
        self.count += 1
        self.start = seen.start if self.start is None else min(self.start, seen.start)
        self.end = seen.end if self.end is None else max(self.end, seen.end)
        if self.parse_error is not None:
            return
        try:
            ci = summary.chunk_index_at(seen.offset)
        except m.McapFormatError as exc:
            self.parse_error = str(exc)
            return
        if ci is None:
            self.unindexed += 1
            return
        self.problems += chunk_index_problems(seen.offset, ci, seen, index_channel)


__all__ = ["ChunkSeen", "ChunkTally", "chunk_index_problems"]
