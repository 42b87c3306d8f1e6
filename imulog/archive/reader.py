"""Read a trial: channels, metadata, attachments, and any channel as numpy / pandas / pyarrow.

Only the chunks holding the requested channel (and overlapping the requested time range) are read and
decompressed; the messages' packed arrays are joined once and viewed with ``numpy.frombuffer``.
"""

from __future__ import annotations

import hashlib
import os
from array import array
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from imulog._lazy import LazyModule
from imulog.archive import _mcap as m
from imulog.archive import journal, staleness
from imulog.archive.channel_info import FINAL_META_KEYS, Attachment, ChannelInfo, _float, _int
from imulog.archive.errors import ArchiveCorruptError, ArchiveError
from imulog.archive.metadata import (
    MAX_RECORD_BYTES,
    MetadataError,
    check_depth,
    decode_record,
    validate_record,
)
from imulog.archive.packing import is_packed, original_media_type, unpack
from imulog.archive.tables import stream_columns
from imulog.model import Stream

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

np = LazyModule("numpy", __name__)  # imported on first use: imulog info never needs numpy

_POOL = None


def _codec():
    """:mod:`imulog.archive.codec`, imported when data is first decoded (listing a trial needs no protobuf)."""
    from imulog.archive import codec

    return codec


def _pool():
    """A small shared thread pool for chunk decompression."""
    global _POOL
    if _POOL is None:
        from concurrent.futures import ThreadPoolExecutor

        _POOL = ThreadPoolExecutor(max_workers=min(2, os.cpu_count() or 1), thread_name_prefix="imulog-zstd")
    return _POOL


def _forget_pool() -> None:  # a forked child does not inherit the pool's threads
    global _POOL
    _POOL = None


os.register_at_fork(after_in_child=_forget_pool)


SALVAGE_HINT = "; `imulog salvage` recovers its intact channels"  # a summary that cannot be read (cut, unfinished)
SALVAGE_MIN_BYTES = 64  # smaller than an MCAP header and one record: nothing to salvage


class TrialReader:
    """Open a trial file for reading: ``with TrialReader(path) as trial: trial.read("/imu/wrist")``."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        try:
            self._f = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise ArchiveError(f"{self.path}: {exc.strerror or exc}") from exc
        try:
            size = os.fstat(self._f.fileno()).st_size
            self.summary = journal.read_summary(self._f, size, self.path)
        except m.McapFormatError as exc:
            self._f.close()
            hint = SALVAGE_HINT if size >= SALVAGE_MIN_BYTES else ""
            raise ArchiveCorruptError(f"{self.path}: {exc}{hint}") from exc
        self._metadata: dict[str, dict[str, Any]] | None = None
        self._chunk_tables: dict[int, tuple[array, ...]] = {}  # by channel id: _chunk_table
        self._by_topic = {c.topic: c for c in self.summary.channels.values()}
        try:  # channel metadata is parsed as JSON in many places: refuse hostile nesting once, here
            for c in self.summary.channels.values():
                for key, value in c.metadata.items():
                    check_depth(value, f"channel {c.topic} metadata {key!r}")
        except MetadataError as exc:
            self._f.close()
            raise ArchiveCorruptError(f"{self.path}: {exc}") from None
        self._merge_channel_stats()

    def _merge_channel_stats(self) -> None:
        """Channels written piece by piece (:mod:`imulog.archive.streaming`) keep their sample count, time span,
        rate, gaps and content hash in one closing metadata record: merge it into their metadata here, so every
        reader sees them as if they were in the Channel record; the stream meta its later pieces changed
        (:data:`~imulog.archive.channel_info.FINAL_META_KEYS`) replaces the Channel record's."""
        names = {c.metadata.get("stats_record") for c in self.summary.channels.values()} - {None, ""}
        for name in names:
            try:
                record = self.metadata.get(name) or {}
            except ArchiveError:
                self._f.close()
                raise
            for c in self.summary.channels.values():
                if c.metadata.get("stats_record") != name:
                    continue
                stats = record.get(c.topic)
                if isinstance(stats, dict):  # the stream meta that later pieces changed replaces the first piece's
                    c.metadata.update(
                        {k: str(v) for k, v in stats.items() if k not in c.metadata or k in FINAL_META_KEYS}
                    )

    # ------------------------------------------------------------------ context manager
    def __enter__(self) -> TrialReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._f.close()

    # ------------------------------------------------------------------ listing
    @property
    def channels(self) -> list[ChannelInfo]:
        stats = self.summary.statistics
        counts = stats.channel_message_counts if stats else {}
        out = []
        for c in sorted(self.summary.channels.values(), key=lambda c: c.id):
            schema = self.summary.schemas.get(c.schema_id)
            meta = dict(c.metadata)
            rate = meta.get("rate_hz")
            out.append(
                ChannelInfo(
                    topic=c.topic,
                    schema_name=schema.name if schema else "",
                    message_count=int(counts.get(c.id, 0)),
                    sample_count=_int(meta, "sample_count") or int(counts.get(c.id, 0)),
                    start_ns=_int(meta, "start_ns"),
                    end_ns=_int(meta, "end_ns"),
                    rate_hz=_float(rate),
                    metadata=meta,
                    channel_id=c.id,
                )
            )
        return out

    def topics(self) -> list[str]:
        """Topics of the imulog channels (viewer twins under ``/derived/viewer/`` are in ``channels`` only)."""
        return [c.topic for c in self.channels if not c.metadata.get("twin_of")]

    def channel(self, topic: str) -> ChannelInfo:
        for c in self.channels:
            if c.topic == topic:
                return c
        known = ", ".join(self.topics()) or "none"
        raise ArchiveError(f"{self.path}: no channel {topic!r} (channels: {known})")

    # ------------------------------------------------------------------ metadata & attachments
    @property
    def metadata(self) -> dict[str, dict[str, Any]]:
        """Metadata records by name; when a name was written more than once the last record wins."""
        if self._metadata is None:
            out: dict[str, dict[str, Any]] = {}
            for idx in sorted(self.summary.metadata_indexes, key=lambda i: i.offset):
                name, items = self._read_metadata(idx)
                try:
                    values = decode_record(items, name)
                    validate_record(name, values)
                except MetadataError as exc:
                    raise ArchiveCorruptError(f"{self.path}: {exc}") from None
                out[name] = values
            self._metadata = out
        return self._metadata

    def _read_metadata(self, idx: m.MetadataIndexRec) -> tuple[str, dict[str, str]]:
        if idx.length > MAX_RECORD_BYTES:
            raise ArchiveCorruptError(
                f"{self.path}: metadata {idx.name!r} is {idx.length} bytes, above the {MAX_RECORD_BYTES >> 20} MiB limit"
            )
        try:
            body = m.read_record_at(self._f, idx.offset, m.Op.METADATA, self.summary.data_end_offset)
            return m.parse_metadata(body)
        except m.McapFormatError as exc:
            raise ArchiveCorruptError(f"{self.path}: metadata {idx.name!r}: {exc}") from exc

    def runs(self) -> dict[int, dict[str, Any]]:
        """The ``imulog.run.<n>`` provenance records, by run number."""
        out = {}
        for name, rec in self.metadata.items():
            if name.startswith("imulog.run."):
                try:
                    out[int(name.rsplit(".", 1)[1])] = rec
                except ValueError:
                    continue
        return dict(sorted(out.items()))

    def stale_channels(self) -> dict[str, dict[str, Any]]:
        """Derived channels out of date against the trial's current inputs, by topic (no data read):
        :func:`imulog.archive.staleness.stale_channels`."""
        return staleness.stale_channels(self.summary.channels, self.metadata)

    def stale_steps(self) -> dict[str, dict[str, Any]]:
        """Steps whose latest run is out of date, by step (no data read):
        :func:`imulog.archive.staleness.stale_steps`."""
        return staleness.stale_steps(self.summary.channels, self.metadata, self.runs())

    def attachment_infos(self) -> list[dict[str, Any]]:
        """Name, media type and size of every attachment, from the summary (no attachment is read).

        ``sha256`` comes from the ``imulog.raw`` record (None for attachments it does not list).
        """
        raw = self.metadata.get("imulog.raw", {}).get("attachments", {})
        return [
            {
                "name": a.name,
                "media_type": original_media_type(a.media_type),
                "bytes": a.data_size,  # as stored (zstd frame when packed)
                "packed": is_packed(a.media_type),
                "sha256": raw.get(a.name),
            }
            for a in sorted(self.summary.attachment_indexes, key=lambda i: i.offset)
        ]

    def attachments(self) -> list[Attachment]:
        """Every attachment with its data (CRC-checked) and SHA-256."""
        return list(self.iter_attachments())

    def iter_attachments(self) -> Iterator[Attachment]:
        """The attachments one at a time (each read and CRC-checked when reached)."""
        for idx in sorted(self.summary.attachment_indexes, key=lambda i: i.offset):
            try:
                body = m.read_record_at(self._f, idx.offset, m.Op.ATTACHMENT, self.summary.data_end_offset)
                rec = m.parse_attachment(body)
            except m.McapFormatError as exc:
                raise ArchiveCorruptError(f"{self.path}: attachment {idx.name!r}: {exc}") from exc
            if rec.crc != 0 and rec.crc != rec.computed_crc:
                raise ArchiveCorruptError(f"{self.path}: attachment {idx.name!r} fails its CRC")
            try:
                data = unpack(rec.data, rec.media_type)  # a zstd-packed original: its own bytes
            except Exception as exc:  # zstandard.ZstdError: a frame the CRC did not catch
                raise ArchiveCorruptError(f"{self.path}: attachment {idx.name!r} does not decompress: {exc}") from exc
            media_type = original_media_type(rec.media_type)
            yield Attachment(rec.name, media_type, data, hashlib.sha256(data).hexdigest(), rec.log_time)

    # ------------------------------------------------------------------ data
    def _channel_rec(self, topic: str) -> m.ChannelRec:
        rec = self._by_topic.get(topic)
        if rec is None:
            known = ", ".join(sorted(self._by_topic)) or "none"
            raise ArchiveError(f"{self.path}: no channel {topic!r} (channels: {known})")
        return rec

    def _chunk_table(self, channel_id: int) -> tuple[array, ...]:
        """Offsets, message start/end times (ns) and summary numbers of the chunks holding ``channel_id``, in file
        order (= write order, kept as is so even a non-monotonic clock round-trips): 32 bytes a chunk of the
        channel, kept per channel read. Parsed ChunkIndex records (about 600 bytes each with their offsets maps:
        benchmarks/reader_memory.py) are built one at a time, when their chunk is read."""
        table = self._chunk_tables.get(channel_id)
        if table is None:
            table = self.summary.channel_chunks(channel_id)
            offsets = table[0]
            if any(offsets[k] > offsets[k + 1] for k in range(len(offsets) - 1)):  # summary not in file order
                order = sorted(range(len(offsets)), key=offsets.__getitem__)
                table = tuple(array("Q", [column[i] for i in order]) for column in table)
            self._chunk_tables[channel_id] = table
        return table

    def _selected_chunks(self, channel_id: int, start_ns: int | None, end_ns: int | None) -> array:
        """Summary numbers of the chunks holding ``channel_id`` that may overlap ``[start_ns, end_ns)``, in file
        order (:meth:`_chunk_index` parses one)."""
        _, starts, ends, numbers = self._chunk_table(channel_id)
        meta = self.summary.channels[channel_id].metadata  # its log_time map: t_ns -> the trial's time axis
        lo = None if start_ns is None else _codec().channel_log_time(meta, start_ns)
        hi = None if end_ns is None else _codec().channel_log_time(meta, end_ns)
        n = len(numbers)
        monotonic = all(ends[k] <= starts[k + 1] for k in range(n - 1))
        selected = array("Q")  # 8 bytes a chunk (a list: 36)
        for k in range(n):
            if monotonic and hi is not None and starts[k] > hi:
                continue
            # Blocks start at their first sample: a chunk may hold samples up to the next chunk's start.
            if monotonic and lo is not None and k + 1 < n and starts[k + 1] < lo:
                continue
            selected.append(numbers[k])
        return selected

    def _chunk_index(self, number: int) -> m.ChunkIndexRec:
        """The ChunkIndex numbered ``number`` in the summary (one from :meth:`_selected_chunks`), parsed alone."""
        return self.summary.chunk_index_number(number)

    def _select_chunks(self, channel_id: int, start_ns: int | None, end_ns: int | None) -> list[m.ChunkIndexRec]:
        """Chunk indexes holding ``channel_id`` that may overlap ``[start_ns, end_ns)``, in file order."""
        return [self._chunk_index(o) for o in self._selected_chunks(channel_id, start_ns, end_ns)]

    def _where(self, ci: m.ChunkIndexRec, topic: str | None) -> str:
        """``PATH: TOPIC: chunk at byte N (t = a-b s)``: the chunk's place, time relative to the file's first."""
        t0 = min((c.message_start_time for c in self.summary.iter_chunk_indexes()), default=0)
        span = f"{(ci.message_start_time - t0) / 1e9:.3f}-{(ci.message_end_time - t0) / 1e9:.3f} s"
        who = f"{topic}: " if topic else ""
        return f"{self.path}: {who}chunk at byte {ci.chunk_start_offset} (t = {span} into the file)"

    def iter_chunks(
        self, channel_id: int, start_ns: int | None = None, end_ns: int | None = None, *, topic: str | None = None
    ) -> list[bytes]:
        """Decompressed, CRC-checked bytes of the chunks holding ``channel_id`` (time-pruned), in time order.

        Chunks are read sequentially and decompressed on two threads (zstd releases the GIL). A damaged
        chunk raises ArchiveCorruptError naming the channel and the chunk's time range.
        """
        records = [(ci, self._chunk_record(ci, topic)) for ci in self._select_chunks(channel_id, start_ns, end_ns)]
        if len(records) > 1:
            return list(_pool().map(lambda r: self._decompress(*r, topic), records))
        return [self._decompress(*r, topic) for r in records]

    def _chunk_record(self, ci: m.ChunkIndexRec, topic: str | None = None) -> m.ChunkRec:
        try:
            m.check_chunk_size(ci.compressed_size, ci.uncompressed_size)
            body = m.read_record_at(self._f, ci.chunk_start_offset, m.Op.CHUNK, self.summary.data_end_offset)
            return m.parse_chunk(body)
        except m.McapFormatError as exc:
            raise ArchiveCorruptError(f"{self._where(ci, topic)}: {exc}") from None

    def _decompress(self, ci: m.ChunkIndexRec, chunk: m.ChunkRec, topic: str | None = None) -> bytes:
        try:
            return m.decompress_chunk(chunk)
        except Exception as exc:
            raise ArchiveCorruptError(
                f"{self._where(ci, topic)} is damaged: {exc}; nothing was computed from it (imulog doctor {self.path})"
            ) from None

    def messages(self, topic: str, start_ns: int | None = None, end_ns: int | None = None) -> list[memoryview]:
        """Raw serialized messages of a channel in write order (pruned to chunks overlapping the range)."""
        rec = self._channel_rec(topic)
        out: list[memoryview] = []
        try:
            for data in self.iter_chunks(rec.id, start_ns, end_ns, topic=topic):
                out.extend(payload for _, _, payload in m.chunk_messages(data, rec.id))
        except m.McapFormatError as exc:
            raise ArchiveCorruptError(f"{self.path}: {topic}: {exc}") from exc
        return out

    def iter_chunk_messages(
        self, topic: str, start_ns: int | None = None, end_ns: int | None = None
    ) -> Iterator[list[memoryview]]:
        """The channel's raw messages one chunk at a time (each chunk read, CRC-checked, then dropped).

        Memory is bounded by the largest chunk, not the channel (of the channel's chunks only their offsets and
        times are kept, 24 bytes each: :meth:`_chunk_table`); the next chunk is decompressed on a second thread
        while the caller works on the current one.
        """
        rec = self._channel_rec(topic)
        selected = self._selected_chunks(rec.id, start_ns, end_ns)
        pending = None
        ci = self._chunk_index(selected[0]) if selected else None
        for k in range(len(selected)):
            if pending is None:
                current = self._decompress(ci, self._chunk_record(ci, topic), topic)
            else:
                current = pending.result()
            pending = None
            here = ci
            if k + 1 < len(selected):
                ci = self._chunk_index(selected[k + 1])
                pending = _pool().submit(self._decompress, ci, self._chunk_record(ci, topic), topic)
            try:
                payloads = [payload for _, _, payload in m.chunk_messages(current, rec.id)]
            except m.McapFormatError as exc:
                raise ArchiveCorruptError(f"{self._where(here, topic)}: {exc}") from None
            yield payloads

    def iter_blocks(self, topic: str, start_ns: int | None = None, end_ns: int | None = None) -> Iterator[Stream]:
        """The channel as a sequence of imulog.model streams, one per chunk (each about 2 MiB of samples).

        Concatenated, the pieces equal ``read(topic, start_ns, end_ns)``; every chunk is CRC-checked
        before it is decoded, so a damaged chunk raises ArchiveCorruptError (channel and time range in the
        message) before its samples are yielded. Empty pieces (outside the range) are skipped.
        """
        rec = self._channel_rec(topic)
        schema = self.summary.schemas.get(rec.schema_id)
        if schema is None:
            raise ArchiveError(f"{self.path}: channel {topic!r} has no schema")
        for payloads in self.iter_chunk_messages(topic, start_ns, end_ns):
            if not payloads:
                continue
            stream = _codec().select_time(self._decode(schema.name, topic, rec, payloads), start_ns, end_ns)
            if len(stream):
                yield stream

    def read(self, topic: str, start_ns: int | None = None, end_ns: int | None = None) -> Stream:
        """The channel as its imulog.model stream, restricted to ``start_ns <= t < end_ns`` when given."""
        rec = self._channel_rec(topic)
        schema = self.summary.schemas.get(rec.schema_id)
        if schema is None:
            raise ArchiveError(f"{self.path}: channel {topic!r} has no schema")
        payloads = self.messages(topic, start_ns, end_ns)
        return _codec().select_time(self._decode(schema.name, topic, rec, payloads), start_ns, end_ns)

    def _decode(self, schema_name: str, topic: str, rec: m.ChannelRec, payloads: list[memoryview]) -> Stream:
        try:
            return _codec().decode(schema_name, topic, rec.metadata, payloads)
        except _codec().DecodeError as exc:
            raise ArchiveCorruptError(f"{self.path}: {exc}") from exc
        except MemoryError:
            raise
        except Exception as exc:  # a hostile file with valid CRCs must still give one line, not a traceback
            raise ArchiveCorruptError(f"{self.path}: {topic}: does not decode ({type(exc).__name__}: {exc})") from None

    def channel_hash(self, topic: str) -> str:
        """Content hash of a channel (SHA-256 over its messages), as recorded in provenance."""
        rec = self._channel_rec(topic)
        recorded = rec.metadata.get("sha256")
        if recorded:
            return recorded
        from imulog.archive.hashing import payload_hash

        return payload_hash(self.messages(topic))

    def compute_channel_hash(self, topic: str) -> str:
        """Recompute the content hash from the data (what ``doctor`` compares with the recorded one)."""
        from imulog.archive.hashing import payload_hash

        return payload_hash(self.messages(topic))

    # ------------------------------------------------------------------ tables
    def read_columns(self, topic: str, start_ns: int | None = None, end_ns: int | None = None) -> dict[str, Any]:
        """The channel as flat named columns (``t_ns`` first): numpy arrays, labels as lists."""
        return stream_columns(self.read(topic, start_ns, end_ns))

    def read_arrow(self, topic: str, start_ns: int | None = None, end_ns: int | None = None) -> pa.Table:
        """The channel as a ``pyarrow.Table`` (zero-copy from the numpy columns where possible)."""
        import pyarrow as pa

        cols = self.read_columns(topic, start_ns, end_ns)
        info = self.channel(topic)
        table = pa.table({k: pa.array(v) for k, v in cols.items()})
        keep = ("units", "frame_id", "kind", "algorithm", "params", "inputs", "source")
        meta = {"topic": topic, "schema": info.schema_name, **{k: info.metadata[k] for k in keep if k in info.metadata}}
        return table.replace_schema_metadata(meta)

    def read_pandas(
        self, topic: str, start_ns: int | None = None, end_ns: int | None = None, *, clock: str | None = None
    ) -> pd.DataFrame:
        """The channel as a ``pandas.DataFrame`` with a ``t_ns`` column (or ``start_ns``/``end_ns``).

        ``clock="device"`` or ``"reference"``: indexed by time on that clock instead (wall-clock
        ``time`` when the trial records a start time, else a TimedeltaIndex ``t`` from the trial's
        start), through ``imulog.alignment``; see :func:`imulog.archive.display.frame_on_clock`.
        """
        if clock is not None:
            from imulog.archive.display import frame_on_clock

            return frame_on_clock(self, topic, clock, start_ns, end_ns)
        import pandas as pd

        return pd.DataFrame(self.read_columns(topic, start_ns, end_ns))

    def __repr__(self) -> str:
        from imulog.archive.display import trial_repr

        return trial_repr(self)

    def _repr_html_(self) -> str:
        from imulog.archive.display import trial_html

        return trial_html(self)
