"""What a salvaged file records about itself: checked metadata, recomputed channel records, the raw-data hash.

Used by :mod:`imulog.archive.salvage` once the damaged file has been scanned. Pure functions of what the scan
found (the recovered messages are passed in as an iterator of (log time, payload) pairs, one chunk at a time).
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from typing import Any

from imulog.archive import codec
from imulog.archive.metadata import MAX_RECORD_BYTES, MetadataError, decode_record, validate_record
from imulog.archive.reader import _int
from imulog.archive.streaming import STATS_KEYS, ChannelStats, _sample_arrays
from imulog.archive.writer import raw_digest

MAX_SPANS = 1000  # lost time spans listed per channel (the rest are counted)
LOST = object()  # marks, among a channel's sources, where chunks of it were lost


def metadata_problem(name: str, items: dict[str, str], length: int) -> str | None:
    """Why a metadata record fails imulog's checks (typed values, nesting, size), or None when it passes."""
    if length > MAX_RECORD_BYTES:
        return f"{length} bytes, above the {MAX_RECORD_BYTES >> 20} MiB limit"
    try:
        validate_record(name, decode_record(items, name))
    except MetadataError as exc:
        return str(exc)
    return None


def recompute(
    schema_name: str | None,
    topic: str,
    meta: dict[str, str],
    pieces: Iterable[Any],
) -> tuple[dict[str, str], list[list[int | None]], str]:
    """Channel metadata from the recovered messages, and the time spans lost; (metadata, spans, clock).

    ``pieces``: per source in file order, a list of (log time, payload) pairs, or :data:`LOST` where chunks
    were lost. The sample count, start and end, rate, gaps, NaN count and content hash are recomputed (the
    stale ones dropped); ``salvaged_original_sha256`` keeps the hash recorded before. Spans are [after,
    before] in ns: the samples lost lie after ``after`` and before ``before`` (the last and first recovered
    samples around the loss; at either end the channel's recorded start or end when known, else null). The
    clock is ``sample`` (the stream's own times, as ``start_ns``/``end_ns``) for imulog stream types and
    ``log`` (MCAP log times) for the others.
    """
    decodable = schema_name in codec.MESSAGE_CLASSES
    stats = ChannelStats()
    spans: list[list[int | None]] = []
    first: int | None = None
    last: int | None = None
    pending = False
    for piece in pieces:
        if piece is LOST:
            pending = True
            continue
        if not piece:
            continue
        payloads = [p for _, p in piece]
        if decodable:
            try:
                stream = codec.decode(schema_name, topic, meta, payloads)
            except Exception:  # noqa: BLE001 - a chunk that passed its CRC but does not decode: counted as lost
                pending = True
                continue
            t, values = _sample_arrays(stream)
            stats.add_samples(t, values)
            times = [int(x) for x in t[:1]] + [int(x) for x in t[-1:]]
        else:
            times = [piece[0][0], piece[-1][0]]
            stats.count += len(piece)
        stats.add_payloads(payloads)
        if not times:
            continue
        if pending:
            spans.append([last, times[0]])
            pending = False
        first = times[0] if first is None else first
        last = times[-1]
    recorded_start, recorded_end = _int(meta, "start_ns"), _int(meta, "end_ns")
    if decodable and recorded_start is not None and first is not None and recorded_start < first:
        spans.insert(0, [recorded_start, first])
    recorded_count = _int(meta, "sample_count")
    if pending or (recorded_end is not None and last is not None and recorded_end > last):
        spans.append([last, recorded_end if decodable else None])
    elif last is None and (recorded_count or pending):
        spans.append([recorded_start if decodable else None, recorded_end if decodable else None])
    elif decodable and recorded_count is not None and recorded_count > stats.count and not spans:
        spans.append([last, None])  # samples lost past the last recovered chunk, end not recorded
    out = {k: v for k, v in meta.items() if k not in STATS_KEYS and k != "stats_record"}
    new = stats.to_meta()
    if not decodable:
        new = {"sha256": new["sha256"]}
    out.update(new)
    if "sha256" in meta and meta["sha256"] != out["sha256"]:
        out["salvaged_original_sha256"] = meta["sha256"]
    return out, spans[:MAX_SPANS], "sample" if decodable else "log"


def raw_record(
    values: dict[str, Any], hashes: dict[str, str], attachments: dict[str, str]
) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """``imulog.raw`` for the salvaged file, and what of the original changed (None when nothing did).

    ``hashes``: content hash of every recovered channel; ``attachments``: SHA-256 of every recovered one. Raw
    channels and attachments not recovered leave the record; partial ones get their recovered hash, and the
    raw-data hash is recomputed, so ``doctor`` checks the salvaged file against what it now holds.
    """
    chans = values.get("channels") or {}
    atts = values.get("attachments") or {}
    new_chans = {t: hashes[t] for t in chans if t in hashes}
    new_atts = {n: attachments[n] for n in atts if n in attachments}
    if new_chans == chans and new_atts == atts:
        return values, None
    out = dict(values)
    out["channels"], out["attachments"] = new_chans, new_atts
    out["sha256"] = raw_digest(new_chans, new_atts)
    original = {
        "sha256": values.get("sha256"),
        "channels_changed": sorted(t for t in chans if t in new_chans and new_chans[t] != chans[t]),
        "channels_missing": sorted(t for t in chans if t not in new_chans),
        "attachments_missing": sorted(n for n in atts if n not in new_atts),
    }
    return out, original


def sha256_of(data: bytes | memoryview) -> str:
    return hashlib.sha256(data).hexdigest()


__all__ = ["LOST", "metadata_problem", "raw_record", "recompute"]
