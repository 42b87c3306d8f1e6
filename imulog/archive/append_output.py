"""Where an append's bytes go: into the trial in place, or into a rewritten copy without replaced channels.

A plain append (no channel replaced or removed) writes after the old data section, in the file itself
(:func:`imulog.archive.journal.append_in_place`): no existing byte is copied. The old data section's CRC is
verified meanwhile on a second thread, from a memory map, and the append is undone if it does not match.

Replacing or removing a channel rewrites the file into a temporary file beside it (DESIGN.md's
copy-then-rename, :func:`imulog.archive.files.atomic_output`): the data section is copied record by record,
leaving out the old channel's Channel, Chunk and MessageIndex records (imulog writes one channel per chunk, so
every other chunk is copied byte for byte without recompressing); indexes of the kept records are shifted to
their new offsets.
"""

from __future__ import annotations

import contextlib
import threading
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from imulog.archive import _mcap as m
from imulog.archive._builder import McapBuilder
from imulog.archive.errors import ArchiveCorruptError, ArchiveError
from imulog.archive.files import atomic_output
from imulog.archive.journal import append_in_place
from imulog.archive.streaming import STATS_RECORD

COPY_BLOCK = 8 * 1024 * 1024


def _crc_mismatch(path: Path) -> ArchiveCorruptError:
    return ArchiveCorruptError(
        f"{path}: data section CRC mismatch (file damaged?); run 'imulog doctor {path}' - nothing was written"
    )


@contextlib.contextmanager
def append_output(f: BinaryIO, summary: m.Summary, drop: set[int], path: Path) -> Iterator[McapBuilder]:
    """A builder positioned after the old data section (minus the records of channels ``drop``), whose
    finished file replaces the trial when the block ends without an error, and leaves it untouched otherwise."""
    if drop:
        with atomic_output(path) as out:
            yield _copy_without(f, summary, out, drop, path)
        return
    end, recorded = summary.data_end_offset, summary.data_section_crc
    if recorded == 0:  # no CRC recorded (allowed by MCAP): continue one computed now
        with append_in_place(path, summary, f) as out:
            yield McapBuilder(out, end, _crc_of(f, end), summary)
        return
    result: list[int | BaseException] = []

    def check() -> None:
        try:
            result.append(_crc_of(f, end))
        except BaseException as exc:  # handed to the writing thread
            result.append(exc)

    checker = threading.Thread(target=check, name="imulog-data-crc", daemon=True)
    checker.start()
    try:
        with append_in_place(path, summary, f) as out:
            yield McapBuilder(out, end, recorded, summary)
            checker.join()
            if isinstance(result[0], BaseException):
                raise result[0]
            if result[0] != recorded:
                raise _crc_mismatch(path)
    finally:
        checker.join()


def _copy_range(src: BinaryIO, dst: McapBuilder, start: int, end: int, crc: int | None = None) -> int:
    """Copy src[start:end] into the builder (which continues the data CRC); return the CRC of the range."""
    src.seek(start)
    remaining = end - start
    while remaining > 0:
        block = src.read(min(COPY_BLOCK, remaining))
        if not block:
            raise ArchiveCorruptError(f"unexpected end of file at byte {end - remaining}")
        dst.write(block)
        if crc is not None:
            crc = zlib.crc32(block, crc)
        remaining -= len(block)
    return crc if crc is not None else 0


def _crc_of(f: BinaryIO, end: int) -> int:
    """CRC-32 of the first ``end`` bytes of ``f`` (memory-mapped, in blocks: zlib releases the GIL)."""
    import mmap

    from imulog.archive.salvage import release

    if end == 0:
        return 0
    crc = 0
    with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        if len(mm) < end:
            raise ArchiveCorruptError(f"unexpected end of file at byte {len(mm)}")
        view = memoryview(mm)
        try:
            for a in range(0, end, COPY_BLOCK):
                b = min(end, a + COPY_BLOCK)
                crc = zlib.crc32(view[a:b], crc)
                release(view, a, b)  # mapped file pages count as resident memory: a week's trial is GBs
        finally:
            view.release()
    return crc


def _copy_without(f: BinaryIO, summary: m.Summary, out: BinaryIO, drop: set[int], path: Path) -> McapBuilder:
    """Copy the data section leaving out the records of channels ``drop``; shift the kept indexes.

    One pass: every byte of the old data section is read once, counted in the data-section CRC (checked
    against the recorded one before the file is finished: a damaged input is refused, nothing written)
    and, unless dropped, written once.
    """
    # closing statistics of streamed channels (imulog.channel_stats.N) that no kept channel refers to any more
    referenced = {c.metadata.get("stats_record") for cid, c in summary.channels.items() if cid not in drop}
    orphaned = {
        x.offset for x in summary.metadata_indexes if x.name.startswith(f"{STATS_RECORD}.") and x.name not in referenced
    }
    limit = summary.data_end_offset
    shift: list[tuple[int, int]] = []  # (old offset of a kept record, bytes removed before it)
    removed = 0
    dropped_chunks: set[int] = set()
    in_dropped_chunk = False
    builder = McapBuilder(out, 0, 0, summary)
    f.seek(0)
    magic = f.read(len(m.MAGIC))
    crc = zlib.crc32(magic)
    builder.write(magic)
    pos = len(m.MAGIC)
    while pos < limit:
        head = f.read(9)
        if len(head) < 9 or pos + 9 > limit:
            raise ArchiveCorruptError(f"{path}: truncated record at byte {pos}; nothing was written")
        op, length = m._REC.unpack_from(head, 0)
        end = pos + 9 + length
        if end > limit:
            raise ArchiveCorruptError(f"{path}: record at byte {pos} runs past the data section; nothing was written")
        first = f.read(min(length, COPY_BLOCK))
        drop_it = False
        if op == m.Op.CHUNK:
            ci = summary.chunk_index_at(pos)  # parsed alone: no dict of every chunk's index (issue 24)
            if ci is None:
                raise ArchiveCorruptError(f"{path}: chunk at byte {pos} is not in the summary index")
            chans = set(ci.message_index_offsets)
            in_dropped_chunk = bool(chans) and chans <= drop
            if chans & drop and not in_dropped_chunk:
                raise ArchiveError(
                    f"{path}: the chunk at byte {pos} mixes the replaced channel with others; "
                    "cannot replace it without recompressing (file not written by imulog?)"
                )
            drop_it = in_dropped_chunk
            if drop_it:
                dropped_chunks.add(pos)
        elif op == m.Op.MESSAGE_INDEX:
            drop_it = in_dropped_chunk  # message indexes follow their chunk
        else:
            in_dropped_chunk = False
            if op in (m.Op.CHANNEL, m.Op.MESSAGE) and len(first) >= 2:
                drop_it = m._H.unpack_from(first, 0)[0] in drop
            elif op == m.Op.METADATA:
                drop_it = pos in orphaned
        crc = zlib.crc32(first, zlib.crc32(head, crc))
        if drop_it:
            removed += end - pos
        else:
            shift.append((pos, removed))
            builder.write(head)
            builder.write(first)
        remaining = length - len(first)
        while remaining > 0:
            block = f.read(min(COPY_BLOCK, remaining))
            if not block:
                raise ArchiveCorruptError(f"{path}: unexpected end of file at byte {end - remaining}")
            crc = zlib.crc32(block, crc)
            if not drop_it:
                builder.write(block)
            remaining -= len(block)
        pos = end
    if summary.data_section_crc not in (0, crc):
        raise _crc_mismatch(path)
    new_offset = {old: old - rem for old, rem in shift}

    def moved(offset: int) -> int:
        if offset not in new_offset:
            raise ArchiveCorruptError(f"{path}: summary points at byte {offset}, which is not a record start")
        return new_offset[offset]

    for cid in drop:
        builder.channels.pop(cid, None)
        builder.channel_counts.pop(cid, None)
    builder.chunk_indexes = []
    for ci in summary.iter_chunk_indexes():
        if ci.chunk_start_offset in dropped_chunks:
            continue
        ci = m.ChunkIndexRec(**vars(ci))
        ci.chunk_start_offset = moved(ci.chunk_start_offset)
        ci.message_index_offsets = {k: moved(v) for k, v in ci.message_index_offsets.items()}
        builder.chunk_indexes.append(ci)
    builder.attachment_indexes = [m.AttachmentIndexRec(**vars(a)) for a in summary.attachment_indexes]
    for ai in builder.attachment_indexes:
        ai.offset = moved(ai.offset)
    builder.metadata_indexes = [
        m.MetadataIndexRec(**vars(x)) for x in summary.metadata_indexes if x.offset not in orphaned
    ]
    for mi in builder.metadata_indexes:
        mi.offset = moved(mi.offset)
    return builder
