"""Recover the intact parts of a truncated or damaged MCAP file into a new trial file that passes ``doctor``.

    report = salvage("broken.mcap", "fixed.mcap")
    print(lines(report))            # what was recovered, what was lost

The input is only read (memory-mapped, pages handed back as the scan passes them: memory about one chunk);
:mod:`imulog.archive.salvage_scan` finds every intact record. Schema and channel records have no CRC of their
own: when the summary is readable its CRC-checked copies are used. A data-section CRC mismatch that no
damaged chunk, attachment or record explains is located to one damaged byte (:mod:`imulog.archive.crc_locate`);
a metadata record holding it is dropped, and when it cannot be located every metadata record is dropped (none
can be trusted). Metadata records that fail imulog's checks (types, nesting, size, the summary's index) are
dropped and listed. Channels that lost samples get their channel records recomputed from what was recovered
(sample count, start and end, rate, gaps, content hash; the old hash kept as ``salvaged_original_sha256``)
and ``imulog.raw`` is rewritten to the recovered raw channels (the original hash kept in the salvage record),
so the output is a sound, smaller trial. The ``imulog.salvage`` record lists what was lost, per channel the
time spans lost, and the metadata dropped. The output is checked with ``doctor`` before it replaces
anything: ArchiveError (nothing written) when it would not pass, or when nothing is recoverable.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from imulog import __version__
from imulog.archive import _mcap as m
from imulog.archive._builder import CHUNK_TARGET_BYTES, McapBuilder
from imulog.archive.channel_info import FINAL_META_KEYS
from imulog.archive.crc_locate import crc_field_damage, locate_byte_error
from imulog.archive.errors import ArchiveError, ArchiveExistsError
from imulog.archive.files import atomic_output, target_path, temp_path, writer_lock
from imulog.archive.metadata import decode_record, encode_record
from imulog.archive.salvage_records import LOST, metadata_problem, raw_record, recompute
from imulog.archive.salvage_scan import LOST_SOURCE, SalvageReport, Scan, _Channel, release
from imulog.archive.summary_check import summary_defects

SALVAGE_RECORD = "imulog.salvage"


def _summary(f, size: int, report: SalvageReport) -> tuple[list[int], m.Summary | None]:
    """Record offsets the summary indexes, and the summary (empty and None when missing or damaged)."""
    try:
        s = m.read_summary(f, size)
    except m.McapFormatError as exc:
        report.notes.append(f"summary not usable ({exc}): records found by scanning")
        return [], None
    report.summary_found = True
    for d in summary_defects(s):  # the output's summary is written anew: say what was wrong with this one
        report.notes.append(f"summary defect, not carried over: {d.message}")
    hints = (
        [ci.chunk_start_offset for ci in s.chunk_indexes]
        + [a.offset for a in s.attachment_indexes]
        + [x.offset for x in s.metadata_indexes]
    )
    return hints, s


def _reconcile(scan: Scan) -> None:
    """Use the summary's CRC-checked copies of schema and channel records where the data section's differ."""
    s, report = scan.summary, scan.report
    if s is None:
        return
    for sid, rec in s.schemas.items():
        if sid in scan.schemas and scan.schemas[sid] != rec:
            report.lost.append(
                f"schema {sid} ({rec.name}) differs from the summary's copy (damaged): the summary's used"
            )
        scan.schemas[sid] = rec
    for cid, ch in scan.channels.items():
        rec = s.channels.get(cid)
        if rec is not None and rec != ch.rec:
            report.lost.append(
                f"channel {cid} ({rec.topic}) differs from the summary's copy (damaged): the summary's used"
            )
            ch.rec = rec


def _locate(scan: Scan, detected: bool) -> dict[int, str]:
    """Metadata records (by offset) to drop because the data-section CRC places damage in them."""
    report = scan.report
    if report.data_crc != "mismatch" or scan.crc_upto != scan.data_end:
        return {}
    syndrome = scan.crc ^ scan.stored_crc
    if crc_field_damage(syndrome):
        report.notes.append("the damaged byte is in the stored data-section CRC itself: every record is intact")
        return {}
    p = locate_byte_error(syndrome, scan.data_end, [(a, b) for a, b, _ in scan.regions])
    if p is not None:
        start, end, op = next(r for r in scan.regions if r[0] <= p < r[1])
        what = m.OP_NAMES.get(op, hex(op))
        report.lost.append(f"data-section CRC: damaged byte at {p}, in the {what} record at byte {start}")
        if op == m.Op.METADATA:
            return {start: f"damaged byte at {p} (located by the data-section CRC)"}
        if op in (m.Op.SCHEMA, m.Op.CHANNEL) and scan.summary is None:
            raise ArchiveError(
                f"{report.source}: the {what} record at byte {start} is damaged and there is no summary copy of it"
            )
        if op == m.Op.MESSAGE:
            raise ArchiveError(
                f"{report.source}: a message outside chunks (bytes {start}-{end}) is damaged at byte {p}"
            )
        report.notes.append(f"the damaged {what} record is not copied (rebuilt or replaced by the summary's copy)")
        return {}
    if detected:
        report.notes.append("data-section CRC mismatch put down to the damaged records listed (one damaged region)")
        return {}
    why = "data-section CRC mismatch that no single damaged byte explains: no metadata record can be trusted"
    report.lost.append(why)
    return {pos: why for kind, item in scan.order if kind == "metadata" for pos in [item[2]]}


def _pieces(buf: memoryview, ch: _Channel) -> Iterator[Any]:
    """Per source of the channel, in file order: its intact (log time, payload) pairs, or LOST."""
    for first, end, payload in ch.sources:
        if end == LOST_SOURCE:
            yield LOST
        elif end < 0:
            yield [(first, payload)]
        else:
            data = m.decompress_chunk(m.parse_chunk(buf[first + 9 : end]))  # checked in the scan: same bytes
            release(buf, first, end)
            yield [(t, p) for cid, t, p in m.chunk_messages(data, ch.rec.id) if cid == ch.rec.id]


def _messages(buf: memoryview, ch: _Channel) -> Iterator[tuple[int, Any]]:
    for piece in _pieces(buf, ch):
        if piece is not LOST:
            yield from piece


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

    ``src`` is never modified. ``dst`` appears atomically, and only when it passes ``doctor``; ArchiveError
    (one line) when ``dst`` is ``src``, exists without ``overwrite``, nothing is recoverable (no intact
    message: the first chunk cut or damaged), or the output would not pass ``doctor``.
    """
    import mmap

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
        hints, summary = _summary(f, size, report)
        mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        scan = Scan(memoryview(mm), size, report, hints, summary)
        scan.run()
        _reconcile(scan)
        drop = _locate(scan, detected=bool(report.lost))  # damage found by a record's own check, or none
        _write(scan, scan.buf, dst_path, report, overwrite, drop)
        del scan  # views into the map go with it; the map itself is unmapped when collected
    return report


def _metadata_to_keep(scan: Scan, drop: dict[int, str]) -> dict[int, tuple[str, dict[str, str]]]:
    """Metadata records (by offset) that pass their checks; the others are listed as dropped."""
    report = scan.report
    indexed = None
    if scan.summary is not None:
        indexed = {(x.offset, x.length, x.name) for x in scan.summary.metadata_indexes}
    keep = {}
    for kind, item in scan.order:
        if kind != "metadata":
            continue
        name, items, pos, end = item
        why = drop.get(pos) or metadata_problem(name, items, end - pos)
        if why is None and indexed is not None and (pos, end - pos, name) not in indexed:
            why = "not the record the summary indexes there (damaged name or length)"
        if why is not None:
            report.dropped_metadata.append(f"{name} at byte {pos}: {why}")
            continue
        keep[pos] = (name, items)
    return keep


def _write(
    scan: Scan, buf: memoryview, dst: Path, report: SalvageReport, overwrite: bool, drop: dict[int, str]
) -> None:
    for ch in scan.channels.values():
        if ch.rec.schema_id != 0 and ch.rec.schema_id not in scan.schemas:
            report.lost.append(f"channel {ch.rec.topic}: its schema {ch.rec.schema_id} was lost; channel dropped")
    usable = [ch for ch in scan.channels.values() if ch.rec.schema_id == 0 or ch.rec.schema_id in scan.schemas]
    if not scan.channels and not report.lost:
        raise ArchiveError(f"{report.source}: nothing recoverable: cut before any channel was written")
    if not any(ch.messages for ch in usable):
        why = f" ({report.lost[0]})" if report.lost else ""
        raise ArchiveError(f"{report.source}: nothing recoverable: no intact message of any channel{why}")
    metadata = _metadata_to_keep(scan, drop)
    stats = {  # the closing statistics of streamed channels: a converted trial's and every appended run's
        name: decode_record(items, name)
        for name, items in metadata.values()
        if name == "imulog.channel_stats" or name.startswith("imulog.channel_stats.")
    }
    # channel records: as found when complete, recomputed from what was recovered otherwise
    metas: dict[int, dict[str, str]] = {}
    spans: dict[str, Any] = {}
    hashes: dict[str, str] = {}
    for ch in usable:
        schema = scan.schemas.get(ch.rec.schema_id)
        meta = dict(ch.rec.metadata)
        closing = (stats.get(meta.get("stats_record", "")) or {}).get(ch.rec.topic, {})
        recorded = meta.get("sha256") or closing.get("sha256")
        digest = ch.hasher.hexdigest()
        hashes[ch.rec.topic] = digest
        if ch.chunks_lost or recorded != digest:
            final = {k: str(closing[k]) for k in FINAL_META_KEYS if k in closing}  # the stream meta at its end
            meta, lost_spans, clock = recompute(
                schema.name if schema else None, ch.rec.topic, {**meta, **final}, _pieces(buf, ch)
            )
            partial = bool(ch.chunks_lost or lost_spans or (recorded is not None and recorded != digest))
            if partial:
                meta["salvaged"] = f"partial: {len(lost_spans)} span(s) lost"
                spans[ch.rec.topic] = {"clock": clock, "spans": lost_spans, "chunks_lost": ch.chunks_lost}
        else:
            partial = False
        metas[ch.rec.id] = meta
        report.channels[ch.rec.topic] = {
            "messages": ch.messages,
            "chunks_kept": ch.chunks_kept,
            "chunks_lost": ch.chunks_lost,
            "partial": partial,
            "lost_spans": spans.get(ch.rec.topic, {}).get("spans", []),
        }
    raw_original = None
    attached = {a: scan.attachment_sha[a] for a in scan.attachment_sha}
    for pos, (name, items) in metadata.items():
        if name == "imulog.raw":
            values, changed = raw_record(decode_record(items, name), hashes, attached)
            if changed is not None:
                metadata[pos] = (name, encode_record(values))
                raw_original = changed
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
                    if ch.rec.id not in metas:
                        continue
                    schema = scan.schemas.get(ch.rec.schema_id)
                    sid = b.add_schema(schema.name, schema.encoding, schema.data) if schema is not None else 0
                    new_id = b.add_channel(ch.rec.topic, sid, metas[ch.rec.id], ch.rec.message_encoding)
                    for batch in _batches(_messages(buf, ch), CHUNK_TARGET_BYTES):  # memory: about one chunk
                        b.add_messages(new_id, [t for t, _ in batch], [bytes(p) for _, p in batch])
                elif kind == "attachment":
                    a = m.parse_attachment(buf[item[0] + 9 : item[1]])  # CRC-checked in the scan
                    b.add_attachment(a.name, a.media_type, a.data, a.log_time, a.create_time)
                    report.attachments.append(a.name)
                elif item[2] in metadata:
                    name, items = metadata[item[2]]
                    b.add_metadata(name, dict(items))
                    report.metadata.append(name)
            record: dict[str, Any] = {
                "source": str(report.source),
                "summary_found": report.summary_found,
                "data_crc": report.data_crc,
                "lost": report.lost[:1000],
                "partial_channels": sorted(spans),
                "lost_spans": spans,
                "dropped_metadata": report.dropped_metadata,
                "notes": report.notes[:1000],
                "imulog_version": __version__,
            }
            if raw_original is not None:
                record["raw_original"] = raw_original
            b.add_metadata(SALVAGE_RECORD, encode_record(record))
            b.finish()
            out.flush()
            _check_output(temp_path(dst), report)
    report.output = dst


def _check_output(path: Path, report: SalvageReport) -> None:
    """Refuse (nothing written) an output ``doctor`` would reject."""
    from imulog.archive.doctor import check_file

    problems = check_file(path).problems
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise ArchiveError(
            f"{report.source}: the salvaged file would not pass doctor: {problems[0]}{more}; nothing written"
        )


def lines(report: SalvageReport) -> list[str]:
    """A human summary of a salvage report, one line each."""
    out = [
        f"recovered {len(report.channels)} channels, {len(report.attachments)} attachments, "
        f"{len(report.metadata)} metadata records" + (f" into {report.output}" if report.output else "")
    ]
    for topic, c in report.channels.items():
        if c.get("partial"):
            out.append(
                f"  partial: {topic}: {c['messages']} messages kept, {c['chunks_lost']} chunk(s) and "
                f"{len(c['lost_spans'])} time span(s) lost"
            )
    out += [f"  dropped: {x}" for x in report.dropped_metadata]
    out += [f"  lost: {x}" for x in report.lost]
    out += [f"  note: {x}" for x in report.notes]
    return out


__all__ = ["SalvageReport", "lines", "release", "salvage"]
