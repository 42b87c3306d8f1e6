"""Write a Recording as one self-describing MCAP trial file (atomically, under the writer lock)."""

from __future__ import annotations

import hashlib
import mimetypes
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from imulog import __version__
from imulog.archive import codec
from imulog.archive._builder import McapBuilder
from imulog.archive.errors import ArchiveError, ArchiveExistsError
from imulog.archive.files import atomic_output, target_path, writer_lock
from imulog.archive.hashing import payload_hash, rows_hash  # noqa: F401  (re-exported: callers import them here)
from imulog.archive.metadata import encode_record
from imulog.archive.packing import pack
from imulog.archive.timeline import IDENTITY, TIMELINE_RECORD, LogMap, TimelineError, TrialAxis, timeline_record
from imulog.archive.twins import Origin, Twin, twin_topic, twins_for
from imulog.model import Recording, Stream
from imulog.workers import in_background

LIBRARY = f"imulog {__version__}"
PROFILE = ""  # plain MCAP profile: Foxglove and Rerun treat the protobuf channels generically
WRITE_TWINS = os.environ.get("IMULOG_VIEWER_TWINS", "1") != "0"  # viewer twins next to block channels


def raw_digest(channels: dict[str, str], attachments: dict[str, str]) -> str:
    """The trial's raw-data hash: SHA-256 over the sorted raw channel hashes and attachment hashes."""
    h = hashlib.sha256()
    for topic in sorted(channels):
        h.update(f"channel\0{topic}\0{channels[topic]}\n".encode())
    for name in sorted(attachments):
        h.update(f"attachment\0{name}\0{attachments[name]}\n".encode())
    return h.hexdigest()


def write_stream(
    builder: McapBuilder,
    stream: Stream,
    extra_meta: dict[str, str] | None = None,
    log_map: LogMap = IDENTITY,
) -> tuple[str, str]:
    """Encode and write one stream as a channel; return (topic, content hash).

    ``log_map`` places its messages on the trial's time axis (:class:`imulog.archive.timeline.TrialAxis`).
    """
    schema_name, meta, times, payloads = codec.encode(stream, log_map)
    digest = payload_hash(payloads)
    meta["sha256"] = digest
    if extra_meta:
        meta.update(extra_meta)
    schema_id = builder.add_schema(schema_name, "protobuf", codec.file_descriptor_set(schema_name))
    channel_id = builder.add_channel(stream.topic, schema_id, meta)
    builder.add_messages(channel_id, times, payloads)
    return stream.topic, digest


def twin_hash(twin: Twin) -> str:
    """Content hash of a viewer twin's messages (:func:`payload_hash`, with numpy for twins held as rows)."""
    return payload_hash(twin.payloads) if twin.rows is None else rows_hash(twin.rows, twin.mask)


def write_twin(
    builder: McapBuilder, twin: Twin, extra_meta: dict[str, str] | None = None, sha256: str | None = None
) -> tuple[str, str]:
    """Write one viewer twin channel (:mod:`imulog.archive.twins`); return (topic, content hash).

    ``sha256``: the twin's :func:`twin_hash` when already computed."""
    meta = dict(twin.metadata)
    meta["sha256"] = sha256 or twin_hash(twin)
    if extra_meta:
        meta.update(extra_meta)
    schema_id = builder.add_schema(twin.schema_name, twin.schema_encoding, twin.schema_data)
    channel_id = builder.add_channel(twin.topic, schema_id, meta, encoding=twin.message_encoding)
    if twin.rows is None:
        builder.add_messages(channel_id, twin.log_times, twin.payloads)
    else:
        builder.add_message_rows(channel_id, np.asarray(twin.log_times), twin.rows, twin.mask)
    return twin.topic, meta["sha256"]


def stream_twins(
    stream: Stream, axis: TrialAxis, metadata: dict[str, Any] | None = None, origin: Origin | None = None
) -> list[Twin]:
    """The viewer twins of ``stream`` on ``axis`` (empty when twins are switched off or the kind has none)."""
    if not WRITE_TWINS:
        return []
    clock = axis.clock_of(stream.topic)
    return twins_for(stream, axis.map_for(stream.topic), clock, metadata, origin)


CLUSTER_TOPIC = "/derived/vicon/cluster_pose"


def _imu_origin(trial: Any, streams: list[Stream], records: dict[str, Any]) -> Origin | None:
    """Where the IMU frames sit in the viewer: the Vicon cluster's position on the device clock, once aligned."""
    alignment = records.get("imulog.alignment")
    if not alignment:
        return None
    pose = next((s for s in streams if s.topic == CLUSTER_TOPIC), None)
    if pose is None and CLUSTER_TOPIC in trial.topics():
        pose = trial.read(CLUSTER_TOPIC)
    if pose is None or not len(pose):
        return None
    from imulog.process.alignment import reference_to_device

    return np.asarray(reference_to_device(pose.t_ns, dict(alignment)), np.int64), pose.position


def _stored_retwin(
    trial: Any, info: Any, kind: str, axis: TrialAxis, records: dict[str, Any], origin: Origin | None
) -> list[Twin]:
    """The twins of a stored channel (``kind``: orientation, markers, intervals) on ``axis``, read block by block
    (:func:`.twin_blocks.stored_twins`): a week's channel is never decoded whole (issue 24)."""
    if not WRITE_TWINS:
        return []
    from functools import partial

    from imulog.archive.twin_blocks import stored_twins

    clock = axis.clock_of(info.topic)  # as stream_twins places a stream read whole
    blocks = partial(trial.iter_blocks, info.topic)
    return stored_twins(kind, blocks, info.sample_count, axis.map_for(info.topic), clock, records, origin)


def plan_append(
    path: Path, streams: list[Stream], metadata: dict[str, dict[str, Any]], remove: Iterable[str] = ()
) -> tuple[TrialAxis, list[Twin], list[str]]:
    """For ``append_derived``: the trial's time axis and the viewer twins to write, and twin topics to drop.

    The axis comes from the file's ``imulog.timeline`` (none: a file from before it, log time = t_ns) with
    the records being written now taking precedence (a new ``imulog.alignment``). Each new stream gets its
    twins; when the alignment changes, the twins of the raw reference-clock channels (markers, events) and
    of the orientations are rewritten on the aligned axis. Twins of removed channels are removed.
    """
    from imulog.archive.reader import TrialReader

    with TrialReader(path) as trial:
        records = {**trial.metadata, **metadata}
        channels = {c.topic: c for c in trial.channels}
        imu_names = {t.split("/")[2] for t in channels if t.startswith("/imu/") and t.count("/") == 2}
        axis = TrialAxis(records, imu_names)
        origin = _imu_origin(trial, streams, records)
        twins = [tw for stream in streams for tw in stream_twins(stream, axis, records, origin)]
        if "imulog.alignment" in metadata and axis.known:
            new = {s.topic for s in streams}
            for topic, info in channels.items():
                if topic in new or info.metadata.get("twin_of") or info.schema_name not in codec.SCHEMA_KIND:
                    continue
                retwin = axis.clock_of(topic, info.metadata) == "reference" and not topic.startswith("/derived/")
                if topic.startswith("/derived/orientation/"):
                    twins.extend(_stored_retwin(trial, info, "orientation", axis, records, origin))
                elif retwin and info.kind in ("markers", "intervals"):
                    twins.extend(_stored_retwin(trial, info, info.kind, axis, records, origin))
        dropped = [twin_topic(t) for t in remove if twin_topic(t) in channels]
    return axis, twins, dropped


#: ``--attach-original auto`` attaches originals up to this size; larger ones are recorded by name, size, SHA-256
ATTACH_MAX_BYTES = 64 * 1024 * 1024
ATTACH_MODES = ("always", "never", "auto")


def attach_mode(value: bool | str) -> str:
    """``always``, ``never`` or ``auto`` from a mode name or the older bool (True: auto, False: never)."""
    if value is True:
        return "auto"
    if value is False or value is None:
        return "never"
    if value not in ATTACH_MODES:
        raise ArchiveError(f"attach-original must be one of {', '.join(ATTACH_MODES)}, got {value!r}")
    return str(value)


def attached_here(src: Path, mode: str, max_bytes: int | None = None) -> bool:
    """Whether ``src`` is attached under ``mode`` (``auto``: when at most ``max_bytes``, default
    :data:`ATTACH_MAX_BYTES`)."""
    limit = ATTACH_MAX_BYTES if max_bytes is None else max_bytes
    return mode == "always" or (mode == "auto" and src.stat().st_size <= limit)


def original_record(src: Path, name: str, block: int = 1 << 20) -> dict[str, Any]:
    """What identifies an original that is not attached: file name, size in bytes and SHA-256 (read in blocks)."""
    h = hashlib.sha256()
    with open(src, "rb") as f:
        while chunk := f.read(block):
            h.update(chunk)
    return {"name": name, "size": src.stat().st_size, "sha256": h.hexdigest()}


def _attachment_names(sources: list[str]) -> list[tuple[Path, str]]:
    out, used = [], set()
    for src in sources:
        p = Path(src)
        name = p.name
        k = 2
        while name in used:
            name = f"{p.stem}({k}){p.suffix}"
            k += 1
        used.add(name)
        out.append((p, name))
    return out


def _device_records(recording: Recording) -> dict[str, dict[str, Any]]:
    extra = {}
    for imu in recording.imus:
        key = f"imulog.device.{imu.name}"
        if key not in recording.metadata:
            extra[key] = {"name": imu.name, **{k: v for k, v in imu.meta.items()}}
    return extra


def write_trial(
    path: str | os.PathLike[str],
    recording: Recording,
    *,
    attach_sources: bool | str = True,
    overwrite: bool = False,
) -> Path:
    """Write ``recording`` to ``path`` as an MCAP trial; return the path.

    Raw channels (one per stream, topics from the streams), metadata records (the recording's, plus an
    ``imulog.device.<name>`` per IMU when missing, ``imulog.timeline`` with the trial's time axis and
    ``imulog.raw`` with the raw-data hash), and the source files as attachments (``attach_sources``: ``always``,
    ``never`` or ``auto``, True meaning auto: files above :data:`ATTACH_MAX_BYTES` are recorded in
    ``imulog.raw["originals"]`` by name, size and SHA-256 instead, for ``imulog doctor --original``). Message log times start
    at ``imulog.trial["start_time"]`` (see :mod:`imulog.archive.timeline`). The file appears atomically; on any error nothing is left behind.
    """
    path = target_path(path)
    streams = recording.streams()
    topics = [s.topic for s in streams]
    dup = sorted({t for t in topics if topics.count(t) > 1})
    if dup:
        raise ArchiveError(f"{path}: two streams share the topic(s) {', '.join(dup)}")
    try:
        timeline = timeline_record(recording.metadata.get("imulog.trial"), streams)
    except TimelineError as exc:
        raise ArchiveError(f"{path}: {exc}") from None
    axis = TrialAxis({TIMELINE_RECORD: timeline}, {s.name for s in recording.imus})
    mode = attach_mode(attach_sources)
    sources = _attachment_names(recording.sources)
    if mode == "never":  # recorded by name, size and hash where the file is at hand
        sources = [(src, name) for src, name in sources if src.is_file()]
    for src, _ in sources:
        if not src.is_file():
            raise ArchiveError(f"{path}: source file to attach not found: {src}")
    originals = [original_record(src, name) for src, name in sources if not attached_here(src, mode)]
    sources = [(src, name) for src, name in sources if attached_here(src, mode)]
    path.parent.mkdir(parents=True, exist_ok=True)
    with writer_lock(path):
        if path.exists() and not overwrite:
            raise ArchiveExistsError(f"{path} exists (use overwrite=True / --overwrite)")
        with atomic_output(path) as f:
            builder = McapBuilder.new(f, LIBRARY, PROFILE)
            twins = [tw for stream in streams for tw in stream_twins(stream, axis, recording.metadata)]
            # the twins' hashes on a worker thread (hashlib releases the GIL) while the raw channels are encoded
            twin_hashes = [in_background(twin_hash, tw) for tw in twins]
            hashes: dict[str, str] = {}
            for stream in streams:
                topic, digest = write_stream(builder, stream, log_map=axis.map_for(stream.topic))
                hashes[topic] = digest
            for twin, digest in zip(twins, twin_hashes, strict=True):  # after every raw channel: raw data first
                write_twin(builder, twin, sha256=digest.result())
            attached: dict[str, str] = {}
            for src, name in sources:
                data = src.read_bytes()
                media_type = mimetypes.guess_type(name)[0] or "application/octet-stream"
                mtime = max(src.stat().st_mtime_ns, 0)
                stored, stored_type = pack(data, media_type)  # zstd when it pays: read back as the original
                builder.add_attachment(name, stored_type, stored, log_time=mtime, create_time=mtime)
                attached[name] = hashlib.sha256(data).hexdigest()
            # imulog.raw and imulog.timeline describe this file's raw data: always recomputed (e.g. when
            # re-writing a read trial)
            records = {
                k: v
                for k, v in {**recording.metadata, **_device_records(recording)}.items()
                if k not in ("imulog.raw", TIMELINE_RECORD)
            }
            records[TIMELINE_RECORD] = timeline
            for name, values in records.items():
                builder.add_metadata(name, encode_record(dict(values)))
            raw = {
                "sha256": raw_digest(hashes, attached),
                "channels": hashes,
                "attachments": attached,
                "sources": [str(src) for src, _ in sources] + [o["name"] for o in originals],
                "imulog_version": __version__,
            }
            if originals:
                raw["originals"] = originals
            builder.add_metadata("imulog.raw", encode_record(raw))
            builder.finish()
    return path


__all__ = [
    "ATTACH_MAX_BYTES",
    "attach_mode",
    "original_record",
    "write_trial",
    "payload_hash",
    "rows_hash",
    "raw_digest",
]
