"""Validate a trial file: structure, CRCs, summary/statistics consistency, decodability, content hashes.

Every byte of an MCAP file written by imulog is covered by a check: the data section by its CRC (and each
chunk by its own), the summary and footer by the summary CRC, the magic bytes directly. So a single flipped
byte or a truncation anywhere is reported.
"""

from __future__ import annotations

import hashlib
import json
import os
import struct
import zlib
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from imulog.archive import _mcap as m
from imulog.archive import codec, journal
from imulog.archive.chunk_check import ChunkSeen, ChunkTally
from imulog.archive.errors import ArchiveError
from imulog.archive.summary_check import (
    CHANNEL_COUNTS,
    DUPLICATE_CHUNKS,
    DUPLICATE_RECORDS,
    NO_STATISTICS,
    offsets_problems,
)
from imulog.archive.writer import raw_digest

Progress = Callable[[int], None]


@dataclass
class DoctorReport:
    path: Path
    problems: list[str] = field(default_factory=list)
    checks: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def fail(self, message: str) -> None:
        self.problems.append(message)


def empty_found() -> dict:
    """What a walk of the data section collects, empty: records by kind and message counts per channel."""
    return {
        "schemas": {},
        "channels": {},
        "chunks": {},
        "message_indexes": {},
        "attachments": {},
        "metadata": {},
        "counts": defaultdict(int),
    }


def _walk_data_section(f, summary: m.Summary, report: DoctorReport, progress: Progress | None = None) -> dict | None:
    """Read the data section record by record; check CRCs; return what was found (None on a fatal error)."""
    found = empty_found()
    limit = summary.data_end_offset
    f.seek(0)
    crc = zlib.crc32(f.read(len(m.MAGIC)))
    pos = len(m.MAGIC)
    first = True
    last_chunk: ChunkSeen | None = None
    last_chunk_msgs: dict[int, list[tuple[int, int]]] = {}
    while pos < limit:
        head = f.read(9)
        if len(head) < 9 or pos + 9 > limit:
            report.fail(f"truncated record header at byte {pos}")
            return None
        op, length = m._REC.unpack(head)
        if pos + 9 + length > limit:
            report.fail(
                f"{m.OP_NAMES.get(op, hex(op))} record at byte {pos} claims {length} bytes, past the data section"
            )
            return None
        body = f.read(length)
        crc = zlib.crc32(body, zlib.crc32(head, crc))
        where = f"{m.OP_NAMES.get(op, hex(op))} record at byte {pos}"
        try:
            if first and op != m.Op.HEADER:
                report.fail(f"first record is not a Header (byte {pos})")
            first = False
            if op == m.Op.SCHEMA:
                rec = m.parse_schema(body)
                found["schemas"][rec.id] = rec
            elif op == m.Op.CHANNEL:
                rec = m.parse_channel(body)
                found["channels"][rec.id] = rec
            elif op == m.Op.CHUNK:
                ch = m.parse_chunk(body)
                try:
                    raw = m.decompress(ch.compression, ch.data, ch.uncompressed_size)
                except Exception as exc:
                    report.fail(f"{where}: does not decompress ({exc})")
                    raw = None
                counts: dict[int, int] = defaultdict(int)
                msgs: dict[int, list[tuple[int, int]]] = defaultdict(list)
                if raw is not None:
                    if len(raw) != ch.uncompressed_size:
                        report.fail(f"{where}: uncompressed size {len(raw)} != recorded {ch.uncompressed_size}")
                    if ch.uncompressed_crc != 0 and zlib.crc32(raw) != ch.uncompressed_crc:
                        report.fail(f"{where}: chunk CRC mismatch")
                    times = []
                    for op2, off2, body2 in m.iter_records(raw):
                        if op2 == m.Op.SCHEMA:  # other writers put schemas and channels inside chunks
                            rec = m.parse_schema(body2)
                            found["schemas"][rec.id] = rec
                        elif op2 == m.Op.CHANNEL:
                            rec = m.parse_channel(body2)
                            found["channels"][rec.id] = rec
                        if op2 != m.Op.MESSAGE:
                            continue
                        if len(body2) < 22:
                            raise m.McapFormatError("message record too short")
                        cid = m._H.unpack_from(body2, 0)[0]
                        t = m._Q.unpack_from(body2, 6)[0]
                        counts[cid] += 1
                        times.append(t)
                        msgs[cid].append((t, off2))
                    if times and (min(times) != ch.message_start_time or max(times) != ch.message_end_time):
                        report.fail(f"{where}: message times outside the chunk's recorded start/end")
                    for cid, n in counts.items():
                        found["counts"][cid] += n
                last_chunk = ChunkSeen(
                    pos,
                    9 + length,
                    ch.message_start_time,
                    ch.message_end_time,
                    len(ch.data),
                    ch.uncompressed_size,
                    ch.compression,
                    dict(counts),
                )
                last_chunk_msgs = msgs
                found["chunks"][pos] = last_chunk
            elif op == m.Op.MESSAGE_INDEX:
                c = m.Cursor(body)
                cid = c.u16()
                n = c.u32()
                entries = [(c.u64(), c.u64()) for _ in range(n // 16)]
                found["message_indexes"][pos] = (cid, 9 + length)
                if last_chunk is not None:
                    last_chunk.message_index_length += 9 + length
                if last_chunk is None:
                    report.fail(f"{where}: message index without a preceding chunk")
                elif sorted(entries) != sorted(last_chunk_msgs.get(cid, [])):
                    report.fail(f"{where}: message index of channel {cid} disagrees with its chunk")
            elif op == m.Op.MESSAGE:
                found["counts"][m._H.unpack_from(body, 0)[0]] += 1
            elif op == m.Op.ATTACHMENT:
                rec = m.parse_attachment(body)
                if rec.crc != 0 and rec.crc != rec.computed_crc:
                    report.fail(f"{where}: attachment {rec.name!r} CRC mismatch")
                seen = (rec.name, rec.media_type, len(rec.data), rec.log_time, rec.create_time)
                found["attachments"][pos] = (seen, 9 + length)  # not the data: memory stays one record
            elif op == m.Op.METADATA:
                name, items = m.parse_metadata(body)
                found["metadata"][pos] = (name, 9 + length)
            elif op in (m.Op.DATA_END, m.Op.FOOTER):
                report.fail(f"{where}: unexpected {m.OP_NAMES[op]} inside the data section")
        except Exception as exc:  # a damaged record must give a reason, never a traceback
            report.fail(f"{where}: {exc}")
        pos += 9 + length
        if progress is not None:
            progress(9 + length)
    if summary.data_section_crc == 0:
        report.checks.append("data section CRC not recorded (0): skipped")
    elif crc != summary.data_section_crc:
        report.fail(f"data section CRC mismatch (stored {summary.data_section_crc:#010x}, computed {crc:#010x})")
    else:
        report.checks.append("data section CRC ok")
    return found


def _tally(summary: m.Summary, found: dict) -> ChunkTally:
    """The chunks of a whole walk (``found["chunks"]``, ``found["message_indexes"]``) against the summary."""
    tally = ChunkTally()
    mis = found["message_indexes"]
    for seen in found["chunks"].values():
        tally.add(summary, seen, lambda off: mis.get(off, (None,))[0])
    return tally


def _check_summary(summary: m.Summary, found: dict, report: DoctorReport) -> None:
    n0 = len(report.problems)
    for sid, s in summary.schemas.items():
        if sid not in found["schemas"] or found["schemas"][sid] != s:
            report.fail(f"summary schema {sid} ({s.name}) differs from the data section")
    for cid, c in summary.channels.items():
        if cid not in found["channels"] or found["channels"][cid] != c:
            report.fail(f"summary channel {cid} ({c.topic}) differs from the data section")
    for cid in found["channels"]:
        if cid not in summary.channels:
            report.fail(f"channel {cid} of the data section is missing from the summary")
    tally = found.get("tally") or _tally(summary, found)
    if tally.parse_error is not None:
        report.fail(f"summary chunk indexes do not parse: {tally.parse_error}")
        return
    if tally.unindexed or tally.count != summary.chunk_count:
        report.fail(f"summary indexes {summary.chunk_count} chunks, data section has {tally.count}")
    for problem in tally.problems:
        report.fail(problem)
    att = found["attachments"]
    if {(a.offset, a.length) for a in summary.attachment_indexes} != {(o, ln) for o, (_, ln) in att.items()}:
        report.fail("attachment indexes disagree with the attachments in the data section")
    for a in summary.attachment_indexes:
        seen = att.get(a.offset, (None,))[0]
        if seen is not None and seen != (
            a.name,
            a.media_type,
            a.data_size,
            a.log_time,
            a.create_time,
        ):
            report.fail(f"attachment index {a.name!r} disagrees with its attachment")
    for problem in offsets_problems(summary):
        report.fail(problem)
    md = found["metadata"]
    if {(x.offset, x.length, x.name) for x in summary.metadata_indexes} != {(o, ln, nm) for o, (nm, ln) in md.items()}:
        report.fail("metadata indexes disagree with the metadata records in the data section")
    st = summary.statistics
    if st is None:
        report.fail(NO_STATISTICS)
    else:
        counts = {k: v for k, v in found["counts"].items()}
        expect = {cid: counts.get(cid, 0) for cid in found["channels"]}
        if {k: v for k, v in st.channel_message_counts.items()} != expect:
            report.fail(CHANNEL_COUNTS)
        checks = {
            "message_count": sum(counts.values()),
            "schema_count": len(found["schemas"]),
            "channel_count": len(found["channels"]),
            "attachment_count": len(att),
            "metadata_count": len(md),
            "chunk_count": tally.count,
        }
        for key, value in checks.items():
            if getattr(st, key) != value:
                report.fail(f"statistics {key} = {getattr(st, key)}, data section has {value}")
        if tally.count and (st.message_start_time, st.message_end_time) != (tally.start, tally.end):
            report.fail("statistics message start/end times disagree with the chunks")
    if len(report.problems) == n0:
        report.checks.append("summary, indexes and statistics consistent")


def _generic_decode(schema: m.SchemaRec, payload: bytes) -> None:
    """Decode one message with only the FileDescriptorSet embedded in the file (no imulog classes)."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    cls.FromString(payload)


def _check_channel(trial, topic: str, rec: m.ChannelRec, schema: m.SchemaRec, report: DoctorReport) -> str | None:
    """Decode a channel chunk by chunk (memory: one chunk); return its content hash, None if it fails."""
    h = hashlib.sha256()
    samples = 0
    first = True
    try:
        for payloads in trial.iter_chunk_messages(topic):
            if first and payloads:
                first = False
                if schema.encoding == "protobuf":
                    _generic_decode(schema, bytes(payloads[0]))
                elif rec.message_encoding == "json":
                    json.loads(bytes(payloads[0]))
            if schema.name in codec.MESSAGE_CLASSES and payloads:
                samples += len(codec.decode(schema.name, topic, rec.metadata, payloads))
            for p in payloads:
                h.update(struct.pack("<Q", len(p)))
                h.update(p)
    except ArchiveError as exc:
        report.fail(str(exc))
        return None
    except Exception as exc:
        report.fail(f"{topic}: does not decode ({exc})")
        return None
    if schema.name in codec.MESSAGE_CLASSES and rec.metadata.get("sample_count", str(samples)) != str(samples):
        report.fail(f"{topic}: {samples} samples, metadata says {rec.metadata['sample_count']}")
    return h.hexdigest()


def check_length(path: str | os.PathLike[str]) -> int:
    """Total of the units :func:`check_file` reports to its ``progress`` callback (for a progress bar)."""
    return 2 * os.path.getsize(path)


def check_file(path: str | os.PathLike[str], *, decode: bool = True, progress: Progress | None = None) -> DoctorReport:
    """Run every check on ``path``; ``report.problems`` is empty when the file is sound.

    ``progress(n)`` is called as work is done (bytes walked, then bytes of chunks decoded), adding up to
    about :func:`check_length`.
    """
    from imulog.archive.reader import SALVAGE_HINT, SALVAGE_MIN_BYTES, TrialReader

    path = Path(path)
    report = DoctorReport(path)
    try:
        f = open(path, "rb")  # noqa: SIM115
    except OSError as exc:
        report.fail(f"cannot open: {exc.strerror or exc}")
        return report
    with f:
        size = os.fstat(f.fileno()).st_size
        try:
            summary, view = journal.read_summary_view(f, size, path)
        except Exception as exc:  # McapFormatError, or anything a damaged summary provokes
            reason = str(exc) if isinstance(exc, m.McapFormatError) else f"unreadable summary ({exc})"
            report.fail(reason + (SALVAGE_HINT if size >= SALVAGE_MIN_BYTES else ""))
            return report
        report.checks.append("magic, footer and summary CRC ok")
        if view is not f:
            report.checks.append(
                "an append is in progress or was interrupted: checked the trial as before it (the next write undoes it)"
            )
        if summary.duplicate_record_indexes:
            report.fail(DUPLICATE_RECORDS.format(n=summary.duplicate_record_indexes))
        if summary.duplicate_chunk_indexes:
            report.fail(DUPLICATE_CHUNKS.format(n=summary.duplicate_chunk_indexes))
        found = _walk_data_section(view, summary, report, progress)
        if found is None:
            return report
        _check_summary(summary, found, report)
    if report.problems or not decode:
        return report
    try:
        with TrialReader(path) as trial:
            hashes: dict[str, str] = {}
            sizes = trial.summary.stored_bytes_by_channel()
            for info in trial.channels:
                if progress is not None:
                    progress(sizes.get(info.channel_id, 0))
                rec = trial.summary.channels[info.channel_id]
                schema = trial.summary.schemas.get(rec.schema_id)
                if schema is None:
                    report.fail(f"{info.topic}: no schema")
                    continue
                digest = _check_channel(trial, info.topic, rec, schema, report)
                if digest is None:
                    continue
                hashes[info.topic] = digest
                if "sha256" in rec.metadata and rec.metadata["sha256"] != digest:
                    report.fail(f"{info.topic}: content hash differs from the one recorded at write time")
            report.checks.append(f"{len(hashes)} channels decode")
            raw = trial.metadata.get("imulog.raw")
            if raw is None:
                report.checks.append("no imulog.raw record: raw-data hash not checked")
            else:
                attached = {a.name: a.sha256 for a in trial.iter_attachments()}
                for topic, digest in raw.get("channels", {}).items():
                    if topic not in hashes:
                        report.fail(f"raw channel {topic} recorded at conversion is missing")
                    elif hashes[topic] != digest:
                        report.fail(f"raw channel {topic} changed since conversion (hash mismatch)")
                for name, digest in raw.get("attachments", {}).items():
                    if attached.get(name) != digest:
                        report.fail(f"attachment {name!r} changed or missing since conversion")
                now = raw_digest(
                    {t: hashes.get(t, "") for t in raw.get("channels", {})},
                    {n: attached.get(n, "") for n in raw.get("attachments", {})},
                )
                if now != raw.get("sha256"):
                    report.fail("raw-data hash differs from the one recorded at conversion")
                else:
                    report.checks.append("raw-data hash ok")
            salvaged = trial.metadata.get("imulog.salvage")
            if salvaged is not None:  # sound as written; what it lost (and dropped as untrusted) is recorded there
                partial = salvaged.get("partial_channels") or []
                report.checks.append(f"salvaged from {salvaged.get('source')}: {len(partial)} channel(s) partial")
    except ArchiveError as exc:
        report.fail(str(exc))
    except Exception as exc:  # pragma: no cover - every known failure is an ArchiveError
        report.fail(f"unexpected {type(exc).__name__}: {exc}")
    return report


def check_original(path: str | os.PathLike[str], original: str | os.PathLike[str]) -> tuple[bool, str]:
    """Whether the file ``original`` is one the trial was converted from: (ok, one line saying which or why not).

    Compares its SHA-256 with the attachments' hashes and with the originals recorded by name, size and SHA-256
    (``imulog.raw["originals"]``, written for files not attached: ``--attach-original never`` or above 64 MB).
    """
    from pathlib import Path

    from imulog.archive.reader import TrialReader
    from imulog.archive.writer import original_record

    src = Path(original)
    mine = original_record(src, src.name)
    with TrialReader(path) as trial:
        raw = trial.metadata.get("imulog.raw") or {}
    known = [dict(o) for o in raw.get("originals") or []]
    known += [{"name": n, "sha256": h, "size": None} for n, h in (raw.get("attachments") or {}).items()]
    for o in known:
        if o.get("sha256") == mine["sha256"]:
            how = "attached" if o.get("size") is None else "recorded"
            return (
                True,
                f"{src} is the original {o['name']!r} ({mine['size']} bytes, SHA-256 {mine['sha256'][:12]}…, {how})",
            )
    if not known:
        return False, f"{path} records no original files (converted without them?)"
    same_name = [o for o in known if o.get("name") == src.name]
    if same_name:
        o = same_name[0]
        size = f"{o['size']} bytes" if o.get("size") is not None else "attached"
        return False, (
            f"{src} differs from the original {src.name!r} of {path} ({mine['size']} bytes vs {size}; SHA-256 differs)"
        )
    return False, f"{src} is none of the originals of {path} ({', '.join(o['name'] for o in known)})"
