"""Write a trial piece by piece, in bounded memory: a week of wrist data converts without holding it.

:class:`StreamingTrialWriter` takes consecutive pieces of one recording (``Recording`` objects with the same
streams, in time order, as the binary readers' ``iter_chunks`` yield them), encodes each piece's blocks at once,
and writes a chunk whenever a channel has gathered ``CHUNK_TARGET_BYTES``: memory is bounded by one piece plus
one pending chunk per channel, not by the recording.

What a whole-file writer puts in each Channel record but only the end of a recording knows (sample count, first
and last time, rate, gaps, NaN samples, content hash) goes into one metadata record written last,
``imulog.channel_stats`` (topic -> those fields), and the channel's metadata says ``stats_record`` so readers
merge it back (:class:`imulog.archive.TrialReader` does; to any other MCAP reader the channels are ordinary).
The file layout is otherwise the one :func:`imulog.archive.write_trial` makes: raw channels first, viewer twins
after them (in the same chunks order), attachments, metadata records, ``imulog.timeline`` and ``imulog.raw``.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from imulog.archive import codec, twin_filter
from imulog.archive._builder import CHUNK_TARGET_BYTES, McapBuilder
from imulog.archive.attach_file import STREAM_PACK_MAX, write_attachment_from_file  # noqa: F401 (re-exported)
from imulog.archive.channel_stats import STATS_KEYS, ChannelStats, _sample_arrays, final_meta  # noqa: F401 (re-exported)
from imulog.archive.errors import ArchiveError, ArchiveExistsError
from imulog.archive.files import atomic_output, target_path, writer_lock
from imulog.archive.metadata import encode_record
from imulog.archive.piece_plan import SpanCheck, declared_spans, meta_problem, split_plan
from imulog.archive.timeline import TIMELINE_RECORD, TimelineError, TrialAxis, timeline_record
from imulog.model import Intervals, Recording, Stream, take_samples

STATS_RECORD = "imulog.channel_stats"


class _Channel:
    def __init__(self, channel_id: int, topic: str) -> None:
        self.id = channel_id
        self.topic = topic
        self.stats = ChannelStats()
        self.times: list[int] = []
        self.payloads: list[bytes] = []
        self.pending = 0
        self.written_meta: dict[str, Any] | None = None  # the stream meta in the Channel record
        self.meta: dict[str, Any] = {}  # every piece's meta merged (what the whole recording's stream holds)
        self.final: dict[str, str] = {}  # the Channel record's meta keys that later pieces changed, final values


class StreamingTrialWriter:
    """``with StreamingTrialWriter(path, metadata=...) as w: for piece in pieces: w.write(piece)``.

    ``metadata``: the trial's records (``imulog.trial`` with ``start_time`` sets the time axis); ``sources``: files
    to attach (read in 1 MiB blocks at the end; ``attach``: ``always``, ``never`` or ``auto``, see
    :func:`imulog.archive.writer.write_trial`); ``expected_duration_s``: about how long the recording is, so its
    viewer twins keep within their message budget (without it they are written at their full rate). The file appears atomically when the block exits without an
    error; on an error nothing is left behind. Every piece must carry the same streams, in time order.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        metadata: dict[str, dict[str, Any]] | None = None,
        sources: Iterable[str | os.PathLike[str]] = (),
        overwrite: bool = False,
        expected_duration_s: float | None = None,
        attach: str = "auto",
    ) -> None:
        from imulog.archive.writer import attach_mode

        self.path = target_path(path)
        self.attach = attach_mode(attach)  # always | never | auto (originals above 64 MB recorded, not attached)
        self.expected_duration_s = expected_duration_s
        self._twins: dict[str, _Channel] = {}
        self._twin_k: dict[str, int] = {}
        self._twin_seen: dict[str, int] = {}
        self._twin_filters: dict[str, twin_filter.PieceFilter] = {}
        self._imus: list[Any] = []
        self._extra: dict[str, str] = {}  # provenance of appended channels
        self._stats_record = STATS_RECORD
        self.metadata = {k: dict(v) for k, v in (metadata or {}).items()}
        self.sources = [Path(s) for s in sources]
        self.overwrite = overwrite
        self._builder: McapBuilder | None = None
        self._channels: dict[str, _Channel] = {}
        self._axis: TrialAxis | None = None
        self._timeline: dict[str, Any] | None = None
        self._topics: list[str] | None = None
        self._stack: list[Any] = []
        self._plan: dict[str, Any] | None = None  # what the first piece declared (imulog.model.PIECES_RECORD)
        self._spans = SpanCheck()
        #: channels whose meta a later piece changed (undeclared): the Channel record keeps the first piece's, the
        #: closing stats record the final one, which readers take (channel_stats.FINAL_META_KEYS)
        self.meta_changes: list[str] = []

    # ------------------------------------------------------------------ context
    def __enter__(self) -> StreamingTrialWriter:
        for src in self.sources:
            if not src.is_file():
                raise ArchiveError(f"{self.path}: source file to attach not found: {src}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        lock = writer_lock(self.path)
        lock.__enter__()
        self._stack.append(lock)
        if self.path.exists() and not self.overwrite:
            self._unwind(None)
            raise ArchiveExistsError(f"{self.path} exists (use overwrite=True / --overwrite)")
        out = atomic_output(self.path)
        f = out.__enter__()
        self._stack.append(out)
        from imulog.archive.writer import LIBRARY, PROFILE

        self._builder = McapBuilder.new(f, LIBRARY, PROFILE)
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            try:
                self._finish()
            except BaseException as error:
                self._unwind(error)
                raise
            self._unwind(None)
        else:
            self._unwind(exc)

    def _unwind(self, exc: BaseException | None) -> None:
        while self._stack:
            ctx = self._stack.pop()
            if exc is None:
                ctx.__exit__(None, None, None)
            else:
                ctx.__exit__(type(exc), exc, exc.__traceback__)

    # ------------------------------------------------------------------ writing
    def write(self, piece: Recording) -> None:
        """Append one piece (the next samples of every stream) to the trial."""
        assert self._builder is not None, "use StreamingTrialWriter as a context manager"
        streams = piece.streams()
        topics = [s.topic for s in streams]
        dup = sorted({t for t in topics if topics.count(t) > 1})
        if dup:
            raise ArchiveError(f"{self.path}: two streams share the topic(s) {', '.join(dup)}")
        records, plan = split_plan(piece.metadata)
        if self._topics is None:
            self._plan = plan
            self._start(piece, streams)
        for key, values in records.items():  # a reader may learn records (e.g. the device) as it goes
            self.metadata[key] = {**self.metadata.get(key, {}), **values}
        for stream in streams:
            self._write_piece(stream)
            self._write_twins(stream)

    def _start(self, piece: Recording, streams: list[Stream]) -> None:
        """The time axis from the spans the first piece declares, else from its samples (checked at the end)."""
        trial = self._trial(piece.metadata)
        spans = declared_spans(self._plan) if self._plan else None
        try:
            self._timeline = timeline_record(trial, streams if spans is None else spans)
        except TimelineError as exc:
            raise ArchiveError(f"{self.path}: {exc}") from None
        self._axis = TrialAxis({TIMELINE_RECORD: self._timeline}, {s.name for s in piece.imus})
        self._topics = [s.topic for s in streams]
        self._imus = list(piece.imus)

    def _trial(self, first: dict[str, dict[str, Any]]) -> dict[str, Any]:
        """The ``imulog.trial`` record the time axis starts at: the first piece's, updated by the writer's own."""
        return {**first.get("imulog.trial", {}), **self.metadata.get("imulog.trial", {})}

    def _declared_meta(self, topic: str) -> dict[str, Any] | None:
        return ((self._plan or {}).get("meta") or {}).get(topic)

    def _open(self, stream: Stream) -> _Channel:
        """The channel record of a stream, on its first piece (a stream may start in a later piece), with the stream
        meta declared up front when the recording declares it."""
        declared = self._declared_meta(stream.topic)
        shown = dataclasses.replace(stream, meta=declared) if declared is not None else stream
        schema_name, meta, _, _ = codec.encode(shown, self._axis.map_for(stream.topic))
        for key in STATS_KEYS:
            meta.pop(key, None)
        meta.update(self._extra)
        meta["stats_record"] = self._stats_record
        schema_id = self._builder.add_schema(schema_name, "protobuf", codec.file_descriptor_set(schema_name))
        ch = self._channels[stream.topic] = _Channel(
            self._builder.add_channel(stream.topic, schema_id, meta), stream.topic
        )
        if hasattr(shown, "meta"):
            ch.written_meta = dict(shown.meta)
        if stream.topic not in self._topics:
            self._topics.append(stream.topic)
        if hasattr(stream, "acc") and all(i.name != stream.name for i in self._imus):
            self._imus.append(stream)
        return ch

    def _write_twins(self, stream: Stream) -> None:
        """The viewer twins of this piece (:mod:`imulog.archive.twins`), every ``k``-th sample of the recording."""
        from imulog.archive import writer

        if not writer.WRITE_TWINS:
            return
        if isinstance(stream, Intervals):  # every interval, as when written whole: one foxglove.Log at its start
            if len(stream):
                self._add_twins(writer.stream_twins(stream, self._axis, self.metadata), stream.start_ns)
            return
        t = getattr(stream, "t_ns", None)
        if t is None or not len(t):
            return
        k = self._twin_step(stream)
        if twin_filter.filtered(stream):  # low-passed before decimation, seamless across pieces
            pf = self._twin_filters.setdefault(stream.topic, twin_filter.PieceFilter(k))
            self._add_filtered(pf.push(stream))
            return
        first = self._twin_seen.get(stream.topic, 0)
        keep = np.flatnonzero((first + np.arange(len(t))) % k == 0)
        self._twin_seen[stream.topic] = first + len(t)
        if not len(keep):
            return
        twins = writer.stream_twins(take_samples(stream, keep), self._axis, self.metadata)
        self._add_twins(twins, np.asarray(stream.t_ns)[keep])

    def _add_filtered(self, kept: Stream | None) -> None:
        """Write the twins of the decimated, low-passed samples a :class:`twin_filter.PieceFilter` gave."""
        from imulog.archive import writer

        if kept is not None and len(kept.t_ns):
            self._add_twins(writer.stream_twins(kept, self._axis, self.metadata), np.asarray(kept.t_ns))

    def _flush_twin_filters(self) -> None:
        """The last samples the twin filters held back (the end of each filtered channel)."""
        for pf in self._twin_filters.values():
            self._add_filtered(pf.flush())
        self._twin_filters.clear()

    def _add_twins(self, twins: list[Any], sample_times: np.ndarray) -> None:
        """Write this piece's ``twins`` (their channels opened on the first piece); ``sample_times``: the canonical
        samples (or interval starts) they show."""
        for twin in twins:
            ch = self._twins.get(twin.topic)
            if ch is None:
                meta = {k_: v for k_, v in twin.metadata.items() if k_ not in STATS_KEYS}
                meta.update(self._extra)
                meta["stats_record"] = self._stats_record
                schema_id = self._builder.add_schema(twin.schema_name, twin.schema_encoding, twin.schema_data)
                cid = self._builder.add_channel(twin.topic, schema_id, meta, encoding=twin.message_encoding)
                ch = self._twins[twin.topic] = _Channel(cid, twin.topic)
            ch.stats.add_samples(sample_times, [])
            self._add_messages(ch, twin.log_times, twin.payload_list())

    def _twin_step(self, stream: Stream) -> int:
        """Every k-th sample: at most the twins' rate, and at most their message budget over the expected length."""
        from imulog.archive.twins import MAX_TWIN_MESSAGES, OVERVIEW_AFTER_S, TWIN_RATE_HZ, overview_step

        if stream.topic not in self._twin_k:
            t = np.asarray(stream.t_ns)
            rate = 1e9 / float(np.median(np.diff(t))) if len(t) > 1 and np.median(np.diff(t)) > 0 else TWIN_RATE_HZ
            k = max(1, int(np.ceil(rate / TWIN_RATE_HZ - 1e-9)))
            if self.expected_duration_s:
                k = max(k, int(np.ceil(rate * self.expected_duration_s / MAX_TWIN_MESSAGES)))
                if self.expected_duration_s > OVERVIEW_AFTER_S:  # days: an epoch-rate overview
                    k = max(k, overview_step(rate))
            self._twin_k[stream.topic] = k
        return self._twin_k[stream.topic]

    def _write_piece(self, stream: Stream) -> None:
        ch = self._channels.get(stream.topic) or self._open(stream)
        _, _, times, payloads = codec.encode(stream, self._axis.map_for(stream.topic))
        if isinstance(stream, Intervals):
            ch.stats.add_intervals(stream.start_ns, stream.end_ns)
        else:
            ch.stats.add_samples(*_sample_arrays(stream))
        self._spans.add(stream)
        if hasattr(stream, "meta"):
            ch.meta = {**ch.meta, **stream.meta}
        self._add_messages(ch, times, payloads)

    def _add_messages(self, ch: _Channel, log_times: Iterable[int], payloads: list[bytes]) -> None:
        """Hash and buffer a channel's messages; write a chunk once it has gathered CHUNK_TARGET_BYTES."""
        ch.stats.add_payloads(payloads)
        ch.times.extend(int(x) for x in log_times)
        ch.payloads.extend(payloads)
        ch.pending += sum(len(p) for p in payloads)
        if ch.pending >= CHUNK_TARGET_BYTES:
            self._flush(ch)

    def _flush(self, ch: _Channel) -> None:
        if ch.payloads:
            self._builder.add_messages(ch.id, ch.times, ch.payloads)
        ch.times, ch.payloads, ch.pending = [], [], 0

    def _finish(self) -> None:
        from imulog import __version__
        from imulog.archive.writer import _device_records, raw_digest

        if self._topics is None:
            raise ArchiveError(f"{self.path}: nothing to write (the source gave no samples)")
        self._check_declared()
        self._flush_twin_filters()
        for ch in [*self._channels.values(), *self._twins.values()]:
            self._flush(ch)
        from imulog.archive.writer import attached_here, original_record

        attached: dict[str, str] = {}
        originals = []
        for src in self.sources:
            if attached_here(src, self.attach):
                attached[src.name] = self._attach(src)
            else:
                originals.append(original_record(src, src.name))
        stats = {topic: {**ch.stats.to_meta(), **ch.final} for topic, ch in self._channels.items()}
        hashes = {topic: s["sha256"] for topic, s in stats.items()}
        for topic, ch in self._twins.items():
            stats[topic] = {k: v for k, v in ch.stats.to_meta().items() if k != "nan_samples"}
        imus = [dataclasses.replace(i, meta=self._channels[i.topic].meta or i.meta) for i in self._imus]
        device = _device_records(Recording(imus=imus, metadata=self.metadata))
        records = {k: v for k, v in {**self.metadata, **device}.items() if k not in ("imulog.raw", TIMELINE_RECORD)}
        records[TIMELINE_RECORD] = self._timeline or {}
        for name, values in records.items():
            self._builder.add_metadata(name, encode_record(dict(values)))
        self._builder.add_metadata(STATS_RECORD, encode_record(stats))
        raw = {
            "sha256": raw_digest(hashes, attached),
            "channels": hashes,
            "attachments": attached,
            "sources": [str(s) for s in self.sources],
            "imulog_version": __version__,
        }
        if originals:
            raw["originals"] = originals
        self._builder.add_metadata("imulog.raw", encode_record(raw))
        self._builder.finish()

    def _check_declared(self) -> None:
        """Refuse a trial whose time axis is not the whole recording's, or whose declared channel meta a piece
        contradicted; note undeclared meta that later pieces changed (:attr:`meta_changes`) and keep its final value
        for the stats record."""
        problem = self._spans.axis_problem(self._timeline or {}, self._trial({}), self._plan is not None)
        if problem:
            raise ArchiveError(f"{self.path}: {problem}")
        for topic, ch in self._channels.items():
            if ch.written_meta is None:
                continue
            problem = meta_problem(topic, ch.written_meta, ch.meta)
            if problem and self._declared_meta(topic) is not None:
                raise ArchiveError(f"{self.path}: {problem}, unlike the meta its first piece declared")
            if problem:
                self.meta_changes.append(problem)
                ch.final = final_meta(ch.meta)

    def _attach(self, src: Path) -> str:
        """Attach ``src`` read in 1 MiB blocks (a week's .cwa is 770 MB: never held at once); its SHA-256."""
        return write_attachment_from_file(self._builder, src)


def write_trial_streaming(
    path: str | os.PathLike[str],
    pieces: Iterable[Recording],
    *,
    metadata: dict[str, dict[str, Any]] | None = None,
    sources: Iterable[str | os.PathLike[str]] = (),
    overwrite: bool = False,
    expected_duration_s: float | None = None,
    attach: str = "auto",
) -> Path:
    """Write ``pieces`` (consecutive parts of one recording) as a trial in bounded memory; return the path."""
    with StreamingTrialWriter(
        path,
        metadata=metadata,
        sources=sources,
        overwrite=overwrite,
        expected_duration_s=expected_duration_s,
        attach=attach,
    ) as writer:
        for piece in pieces:
            writer.write(piece)
    return writer.path


# ---------------------------------------------------------------------------------------------------------
# derived channels appended piece by piece


@dataclass
class StreamPieces:
    """Derived channels given as consecutive pieces, produced while the trial is being appended to.

    ``pieces()`` is called once, during :func:`imulog.archive.append_derived`, and yields streams of the
    ``topics`` (interleaved, each topic in time order: e.g. a week's orientation, acceleration and static mask,
    window by window); memory is bounded by a piece.
    """

    topics: list[str]
    pieces: Callable[[], Iterator[Stream]]
    expected_duration_s: float | None = None
    #: run-record keys known only once the pieces are produced (e.g. the gap report over every window): the
    #: producer fills it while yielding; the append merges it into ``imulog.run.<n>`` after the last piece
    provenance: dict[str, Any] = field(default_factory=dict)


def write_pieces(
    builder: McapBuilder,
    source: StreamPieces,
    extra_meta: dict[str, str],
    axis: TrialAxis,
    metadata: dict[str, dict[str, Any]],
    stats_record: str,
) -> tuple[dict[str, str], dict[str, dict[str, str]]]:
    """Write the channels of one :class:`StreamPieces` (and their viewer twins) into ``builder``.

    Returns ({topic: content hash}, {topic: stats}) for the closing stats record named ``stats_record``.
    """
    writer = _PieceChannels(builder, axis, metadata, extra_meta, stats_record, source.expected_duration_s)
    for piece in source.pieces():
        if piece.topic not in source.topics:
            raise ArchiveError(f"a piece of topic {piece.topic} is not one of {', '.join(source.topics)}")
        writer.write(piece)
    return writer.finish(source.topics)


class _PieceChannels(StreamingTrialWriter):
    """The channel-writing half of :class:`StreamingTrialWriter`, on a builder that an append owns."""

    def __init__(self, builder, axis, metadata, extra_meta, stats_record, expected_duration_s) -> None:
        super().__init__(Path("."), metadata=metadata, expected_duration_s=expected_duration_s)
        self._builder = builder
        self._axis = axis
        self._topics = []
        self._extra = dict(extra_meta)
        self._stats_record = stats_record

    def write(self, piece: Stream) -> None:  # type: ignore[override]
        self._write_piece(piece)
        self._write_twins(piece)

    def finish(self, topics: list[str]) -> tuple[dict[str, str], dict[str, dict[str, str]]]:
        self._flush_twin_filters()
        for ch in [*self._channels.values(), *self._twins.values()]:
            self._flush(ch)
        missing = [t for t in topics if t not in self._channels]
        if missing:
            raise ArchiveError(f"{', '.join(missing)}: the step produced no samples")
        stats = {t: ch.stats.to_meta() for t, ch in self._channels.items()}
        for t, ch in self._twins.items():
            stats[t] = {k: v for k, v in ch.stats.to_meta().items() if k != "nan_samples"}
        return {t: stats[t]["sha256"] for t in topics}, stats
