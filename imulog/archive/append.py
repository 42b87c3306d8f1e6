"""Append derived channels to an existing trial, and replace them (DESIGN.md, "Appending").

Append: the data section of the old file (every byte before its DataEnd record) is copied unchanged into a
temporary file beside it while its CRC is verified; the new Schema/Channel/Chunk/MessageIndex/Metadata
records follow; then a new DataEnd (the data CRC continued over the new records), the summary (old + new
schemas, channels, chunk/attachment/metadata indexes, recomputed statistics), summary offsets and footer.
The temporary file is fsynced and moved over the original with ``os.replace``: a crash at any point leaves
the original untouched.

Replace: when a derived topic already exists, the data section is copied record by record, leaving out the
old channel's Channel, Chunk and MessageIndex records (imulog writes one channel per chunk, so every other
chunk is copied byte for byte without recompressing); indexes of the kept records are shifted to their new
offsets. Raw channels always precede derived ones, so the raw bytes stay identical in both cases.
"""

from __future__ import annotations

import json
import os
import time
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any, BinaryIO

from imulog import __version__
from imulog.archive import _mcap as m
from imulog.archive._builder import McapBuilder
from imulog.archive.errors import ArchiveCorruptError, ArchiveError
from imulog.archive.files import atomic_output, target_path, writer_lock
from imulog.archive.metadata import encode_record, to_json
from imulog.archive.writer import payload_hash, write_stream
from imulog.model import DERIVED_PREFIX, Stream

COPY_BLOCK = 8 * 1024 * 1024


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


def _copy_prefix(f: BinaryIO, summary: m.Summary, out: BinaryIO, drop: set[int], path: Path) -> McapBuilder:
    """Copy the whole old data section verbatim, verifying its CRC."""
    builder = McapBuilder(out, 0, 0, summary)
    _copy_range(f, builder, 0, summary.data_end_offset)
    if summary.data_section_crc not in (0, builder.crc):
        raise ArchiveCorruptError(
            f"{path}: data section CRC mismatch (file damaged?); run 'imulog doctor {path}' - nothing was written"
        )
    return builder


def _copy_without(f: BinaryIO, summary: m.Summary, out: BinaryIO, drop: set[int], path: Path) -> McapBuilder:
    """Copy the data section leaving out the records of channels ``drop``; shift the kept indexes."""
    chunk_by_offset = {ci.chunk_start_offset: ci for ci in summary.chunk_indexes}
    limit = summary.data_end_offset
    keep: list[tuple[int, int]] = []  # kept byte ranges [start, end) in the old file
    shift: list[tuple[int, int]] = []  # (old offset of a kept record, bytes removed before it)
    removed = 0
    dropped_chunks: set[int] = set()
    in_dropped_chunk = False
    pos = len(m.MAGIC)
    keep.append((0, pos))
    while pos < limit:
        f.seek(pos)
        head = f.read(11)
        if len(head) < 9:
            raise ArchiveCorruptError(f"{path}: truncated record at byte {pos}")
        op, length = m._REC.unpack_from(head, 0)
        end = pos + 9 + length
        if end > limit:
            raise ArchiveCorruptError(f"{path}: record at byte {pos} runs past the data section")
        drop_it = False
        if op == m.Op.CHUNK:
            ci = chunk_by_offset.get(pos)
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
            if op in (m.Op.CHANNEL, m.Op.MESSAGE):
                drop_it = m._H.unpack_from(head, 9)[0] in drop
        if drop_it:
            removed += end - pos
        else:
            shift.append((pos, removed))
            if keep and keep[-1][1] == pos:
                keep[-1] = (keep[-1][0], end)
            else:
                keep.append((pos, end))
        pos = end
    new_offset = {old: old - rem for old, rem in shift}

    def moved(offset: int) -> int:
        if offset not in new_offset:
            raise ArchiveCorruptError(f"{path}: summary points at byte {offset}, which is not a record start")
        return new_offset[offset]

    builder = McapBuilder(out, 0, 0, summary)
    for a, b in keep:
        _copy_range(f, builder, a, b)
    for cid in drop:
        builder.channels.pop(cid, None)
        builder.channel_counts.pop(cid, None)
    builder.chunk_indexes = []
    for ci in summary.chunk_indexes:
        if ci.chunk_start_offset in dropped_chunks:
            continue
        ci = m.ChunkIndexRec(**vars(ci))
        ci.chunk_start_offset = moved(ci.chunk_start_offset)
        ci.message_index_offsets = {k: moved(v) for k, v in ci.message_index_offsets.items()}
        builder.chunk_indexes.append(ci)
    builder.attachment_indexes = [m.AttachmentIndexRec(**vars(a)) for a in summary.attachment_indexes]
    for ai in builder.attachment_indexes:
        ai.offset = moved(ai.offset)
    builder.metadata_indexes = [m.MetadataIndexRec(**vars(x)) for x in summary.metadata_indexes]
    for mi in builder.metadata_indexes:
        mi.offset = moved(mi.offset)
    return builder


def _raw_topics(f: BinaryIO, summary: m.Summary) -> set[str]:
    """Topics recorded as raw in the ``imulog.raw`` metadata record (empty when there is none)."""
    for idx in reversed(summary.metadata_indexes):
        if idx.name == "imulog.raw":
            try:
                _, items = m.parse_metadata(m.read_record_at(f, idx.offset, m.Op.METADATA, summary.data_end_offset))
                return set(json.loads(items.get("channels", "{}")))
            except (m.McapFormatError, ValueError) as exc:
                raise ArchiveCorruptError(f"unreadable imulog.raw record: {exc}") from exc
    return set()


def _run_number(f: BinaryIO, summary: m.Summary) -> int:
    numbers = [0]
    for idx in summary.metadata_indexes:
        if idx.name.startswith("imulog.run."):
            try:
                numbers.append(int(idx.name.rsplit(".", 1)[1]))
            except ValueError:
                continue
    return max(numbers) + 1


def _input_hashes(f: BinaryIO, summary: m.Summary, inputs: Any, path: Path) -> dict[str, str]:
    """``inputs`` as {topic: hash}: a dict is taken as is, a list of topics is hashed from the file."""
    if inputs is None:
        return {}
    if isinstance(inputs, dict):
        return {str(k): str(v) for k, v in inputs.items()}
    from imulog.archive.reader import TrialReader

    with TrialReader(path) as trial:
        return {t: trial.channel_hash(t) for t in inputs}


def append_derived(
    path: str | os.PathLike[str],
    streams: list[Stream],
    *,
    run: dict[str, Any],
    metadata: dict[str, dict[str, Any]] | None = None,
    replace: bool = True,
    remove: Sequence[str] = (),
) -> Path:
    """Append derived ``streams`` (topics under ``/derived/``) and ``metadata`` records to the trial at ``path``.

    ``run`` describes the provenance: ``step``, ``algorithm``, ``params`` (JSON-able), ``inputs`` ({topic:
    content hash} or a list of topics to hash). Each new channel records ``algorithm``, ``params``,
    ``inputs``, ``step``, ``run`` and ``imulog_version``; an ``imulog.run.<n>`` metadata record lists the
    run. An existing topic is replaced when ``replace`` (else ArchiveError); derived topics in ``remove`` are
    deleted. Raw channels are never touched. Returns the path.
    """
    path = target_path(path)
    metadata = dict(metadata or {})
    topics = [s.topic for s in streams]
    for t in topics:
        if not t.startswith(DERIVED_PREFIX):
            raise ArchiveError(f"{path}: derived topics must start with {DERIVED_PREFIX!r}, got {t!r}")
    if len(set(topics)) != len(topics):
        raise ArchiveError(f"{path}: two derived streams share a topic")
    for name in metadata:
        if name in ("imulog.raw",) or name.startswith("imulog.run."):
            raise ArchiveError(f"{path}: metadata record {name!r} is reserved")
    with writer_lock(path):
        try:
            f = open(path, "rb")  # noqa: SIM115
        except OSError as exc:
            raise ArchiveError(f"{path}: {exc.strerror or exc}") from exc
        with f:
            try:
                summary = m.read_summary(f, os.fstat(f.fileno()).st_size)
            except m.McapFormatError as exc:
                raise ArchiveCorruptError(f"{path}: {exc}") from exc
            existing = {c.topic: c for c in summary.channels.values()}
            raw_topics = _raw_topics(f, summary)
            for t in topics:
                if t in raw_topics:
                    raise ArchiveError(
                        f"{path}: {t!r} is a raw channel written at conversion; raw channels are never modified"
                    )
            drop = set()
            for t in remove:
                if t in raw_topics or not t.startswith(DERIVED_PREFIX):
                    raise ArchiveError(f"{path}: only derived channels can be removed, not {t!r}")
                if t not in existing:
                    raise ArchiveError(f"{path}: no channel {t!r} to remove")
                drop.add(existing[t].id)
            for t in topics:
                if t in existing:
                    if not replace:
                        raise ArchiveError(f"{path}: channel {t!r} exists (use replace=True)")
                    drop.add(existing[t].id)
            n = _run_number(f, summary)
            inputs = _input_hashes(f, summary, run.get("inputs"), path)
            for topic, digest in inputs.items():  # provenance must describe the file being written
                recorded = existing[topic].metadata.get("sha256") if topic in existing else None
                if recorded and recorded != digest:
                    raise ArchiveError(
                        f"{path}: input {topic} changed while the step ran (another writer?); run the step again"
                    )
            params = run.get("params", {})
            params_json = params if isinstance(params, str) else to_json(params)
            provenance = {
                "step": str(run.get("step", "")),
                "algorithm": str(run.get("algorithm", "")),
                "params": params_json,
                "inputs": to_json(inputs),
                "run": str(n),
                "imulog_version": __version__,
            }
            with atomic_output(path) as out:
                copy = _copy_without if drop else _copy_prefix
                builder = copy(f, summary, out, drop, path)
                outputs = {}
                for stream in streams:
                    topic, digest = write_stream(builder, stream, provenance)
                    outputs[topic] = digest
                for name, values in metadata.items():
                    builder.add_metadata(name, encode_record(dict(values)))
                record = {
                    **{k: v for k, v in run.items() if k not in ("inputs", "params")},
                    "step": provenance["step"],
                    "algorithm": provenance["algorithm"],
                    "params": json.loads(params_json),
                    "inputs": inputs,
                    "outputs": outputs,
                    "metadata": sorted(metadata),
                    "replaced": sorted(existing[t].topic for t in topics if t in existing),
                    "removed": sorted(remove),
                    "imulog_version": __version__,
                    "time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                }
                builder.add_metadata(f"imulog.run.{n}", encode_record(record))
                builder.finish()
    return path


def remove_derived(path: str | os.PathLike[str], topics: Sequence[str], *, run: dict[str, Any] | None = None) -> Path:
    """Delete derived channels (rewriting the file, untouched chunks copied verbatim); recorded as a run."""
    return append_derived(path, [], run=run or {"step": "remove"}, remove=list(topics))


__all__ = ["append_derived", "payload_hash", "remove_derived"]
