"""Append derived channels to an existing trial, and replace them (DESIGN.md, "Appending").

Append: the new Schema/Channel/Chunk/MessageIndex/Metadata records follow the old data section (every byte
before its DataEnd record, unchanged); then a new DataEnd (the data CRC continued over the new records), the
summary (old + new schemas, channels, chunk/attachment/metadata indexes, recomputed statistics), summary offsets
and footer. They are written into the trial itself, the old summary kept in a journal until the new footer is
durable, so a crash at any point leaves the trial as it was (:mod:`imulog.archive.journal`; a departure from
the DESIGN's copy-then-rename, docs/architecture.md).

Replace: when a derived topic already exists, the file is rewritten without the old channel's records
(:mod:`imulog.archive.append_output`). Raw channels always precede derived ones, so the raw bytes stay
identical in both cases.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, BinaryIO

from imulog import __version__
from imulog.archive import _mcap as m
from imulog.archive.append_output import append_output
from imulog.archive.errors import ArchiveCorruptError, ArchiveError
from imulog.archive.files import target_path, writer_lock
from imulog.archive.metadata import MetadataError, decode_record, encode_record, loads, record_hash, to_json
from imulog.archive.streaming import STATS_RECORD, StreamPieces, write_pieces
from imulog.archive.summary_check import summary_defects
from imulog.archive.summary_walk import summary_problems
from imulog.archive.writer import payload_hash, plan_append, write_stream, write_twin
from imulog.model import DERIVED_PREFIX, Stream

REPAIR_RECORD = "imulog.repair"  # imulog.repair.<run>: the summary defects a run's rewrite repaired


def _raw_topics(f: BinaryIO, summary: m.Summary, path: Path | None = None) -> set[str]:
    """Topics recorded as raw in the ``imulog.raw`` metadata record (empty when there is none)."""
    for idx in reversed(summary.metadata_indexes):
        if idx.name == "imulog.raw":
            try:
                _, items = m.parse_metadata(m.read_record_at(f, idx.offset, m.Op.METADATA, summary.data_end_offset))
                channels = loads(items.get("channels", "{}"), "imulog.raw: 'channels'")
                if not isinstance(channels, dict | list):
                    raise ValueError("'channels' is not an object")
                return {str(t) for t in channels}
            except (m.McapFormatError, ValueError) as exc:  # (MetadataError is a ValueError)
                raise ArchiveCorruptError(f"{path}: unreadable imulog.raw record: {exc}") from None
    return set()


METADATA_INPUT = "metadata:"  # provenance key prefix of a metadata record a step read


def _metadata_record(f: BinaryIO, summary: m.Summary, name: str, path: Path) -> dict[str, Any] | None:
    """The last metadata record called ``name`` (typed), or None when there is none."""
    for idx in reversed(summary.metadata_indexes):
        if idx.name == name:
            try:
                _, items = m.parse_metadata(m.read_record_at(f, idx.offset, m.Op.METADATA, summary.data_end_offset))
                return decode_record(items, name)
            except (m.McapFormatError, MetadataError) as exc:
                raise ArchiveCorruptError(f"{path}: unreadable metadata record {name!r}: {exc}") from None
    return None


def _summary_repairs(f: BinaryIO, summary: m.Summary, path: Path) -> list[str]:
    """The summary defects the rewrite repairs (:mod:`imulog.archive.summary_check`); ArchiveCorruptError, with
    the message ``doctor`` gives, for one it refuses, or for an index that disagrees with the data section
    (:mod:`imulog.archive.summary_walk`, from the record heads)."""
    defects = summary_defects(summary)
    refused = [d.message for d in defects if not d.repaired]
    repaired = [d.message for d in defects if d.repaired]
    refused += summary_problems(f, summary, set(repaired))
    if refused:
        raise ArchiveCorruptError(f"{path}: {refused[0]}; run 'imulog doctor {path}' - nothing was written")
    return repaired


def _salvage_provenance(f: BinaryIO, summary: m.Summary, inputs: dict[str, str], path: Path) -> dict[str, Any] | None:
    """What a run on a salvaged trial keeps of its ``imulog.salvage`` record: the source, the data-CRC verdict,
    the metadata dropped and, for each input channel recovered in part, the time spans it lost."""
    record = _metadata_record(f, summary, "imulog.salvage", path)
    if record is None:
        return None
    spans = record.get("lost_spans") if isinstance(record.get("lost_spans"), dict) else {}
    return {
        "source": record.get("source"),
        "data_crc": record.get("data_crc"),
        "dropped_metadata": record.get("dropped_metadata") or [],
        "partial_inputs": {t: spans[t] for t in inputs if t in spans},
    }


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
    wait_s: float = 0.0,
) -> Path:
    """Append derived ``streams`` (topics under ``/derived/``) and ``metadata`` records to the trial at ``path``.

    ``run`` describes the provenance: ``step``, ``algorithm``, ``params`` (JSON-able), ``inputs`` ({topic:
    content hash} or a list of topics to hash). Each new channel records ``algorithm``, ``params``,
    ``inputs``, ``step``, ``run`` and ``imulog_version``; an ``imulog.run.<n>`` metadata record lists the
    run. An existing topic is replaced when ``replace`` (else ArchiveError); derived topics in ``remove`` are
    deleted. Raw channels are never touched. ``inputs`` keys ``metadata:NAME`` give the hash of a metadata
    record the step read (:func:`imulog.archive.metadata.record_hash`): the append is refused when that
    record, or an input channel, changed meanwhile. ``wait_s``: how long to wait for another writer's lock.
    Returns the path.
    """
    path = target_path(path)
    metadata = dict(metadata or {})
    topics = [t for s in streams for t in (s.topics if isinstance(s, StreamPieces) else [s.topic])]
    for t in topics:
        if not t.startswith(DERIVED_PREFIX):
            raise ArchiveError(f"{path}: derived topics must start with {DERIVED_PREFIX!r}, got {t!r}")
    if len(set(topics)) != len(topics):
        raise ArchiveError(f"{path}: two derived streams share a topic")
    for name in metadata:
        if name in ("imulog.raw",) or name.startswith("imulog.run."):
            raise ArchiveError(f"{path}: metadata record {name!r} is reserved")
    with writer_lock(path, wait_s=wait_s):
        try:
            f = open(path, "rb")  # noqa: SIM115
        except OSError as exc:
            raise ArchiveError(f"{path}: {exc.strerror or exc}") from exc
        with f:
            try:
                summary = m.read_summary(f, os.fstat(f.fileno()).st_size)
            except m.McapFormatError as exc:
                raise ArchiveCorruptError(f"{path}: {exc}") from exc
            repairs = _summary_repairs(f, summary, path)
            existing = {c.topic: c for c in summary.channels.values()}
            raw_topics = _raw_topics(f, summary, path)
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
            whole = [s for s in streams if not isinstance(s, StreamPieces)]  # pieces write their own twins
            axis, twins, twins_removed = plan_append(path, whole, metadata, remove)  # time axis, viewer twins
            for t in [tw.topic for tw in twins] + twins_removed:
                if t in existing and t not in raw_topics:
                    drop.add(existing[t].id)
            pieces = {t for s in streams if isinstance(s, StreamPieces) for t in s.topics}
            for info in existing.values():  # twins of channels written piece by piece: rewritten with them
                if info.metadata.get("twin_of") in pieces and info.topic not in raw_topics:
                    drop.add(info.id)
            n = _run_number(f, summary)
            inputs = _input_hashes(f, summary, run.get("inputs"), path)
            for topic, digest in inputs.items():  # provenance must describe the file being written
                if topic.startswith(METADATA_INPUT):
                    name = topic[len(METADATA_INPUT) :]
                    if record_hash(_metadata_record(f, summary, name, path)) != digest:
                        raise ArchiveError(
                            f"{path}: metadata record {name} changed while the step ran (another writer?); "
                            "nothing was written, run the step again"
                        )
                    continue
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
            with append_output(f, summary, drop, path) as builder:
                outputs = {}
                piece_stats: dict[str, dict[str, str]] = {}
                late: dict[str, Any] = {}  # run-record keys the pieces filled while they were written
                for stream in streams:
                    if isinstance(stream, StreamPieces):  # produced and written piece by piece (long recordings)
                        stats_name = f"{STATS_RECORD}.{n}"
                        digests, stats = write_pieces(builder, stream, provenance, axis, metadata, stats_name)
                        outputs.update(digests)
                        piece_stats.update(stats)
                        late.update(stream.provenance)
                        continue
                    topic, digest = write_stream(builder, stream, provenance, log_map=axis.map_for(stream.topic))
                    outputs[topic] = digest
                if piece_stats:
                    builder.add_metadata(f"{STATS_RECORD}.{n}", encode_record(piece_stats))
                while twins:  # each twin's rows freed once written (a week's orientation twins: tens of MB)
                    write_twin(builder, twins.pop(0), provenance)
                for name, values in metadata.items():
                    builder.add_metadata(name, encode_record(dict(values)))
                record = {
                    **{k: v for k, v in run.items() if k not in ("inputs", "params")},
                    **late,
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
                salvaged = _salvage_provenance(f, summary, inputs, path)
                if salvaged is not None:
                    record["salvage"] = salvaged
                if repairs:
                    record["repair"] = f"{REPAIR_RECORD}.{n}"
                    repair = {"run": n, "repaired": repairs, "imulog_version": __version__, "time": record["time"]}
                    builder.add_metadata(f"{REPAIR_RECORD}.{n}", encode_record(repair))
                builder.add_metadata(f"imulog.run.{n}", encode_record(record))
                builder.finish()
    for line in repairs:  # the file doctor rejected passes now: say so
        print(f"{path}: repaired the summary: {line} ({REPAIR_RECORD}.{n})", file=sys.stderr)
    return path


def remove_derived(path: str | os.PathLike[str], topics: Sequence[str], *, run: dict[str, Any] | None = None) -> Path:
    """Delete derived channels (rewriting the file, untouched chunks copied verbatim); recorded as a run."""
    return append_derived(path, [], run=run or {"step": "remove"}, remove=list(topics))


__all__ = ["append_derived", "payload_hash", "remove_derived"]
