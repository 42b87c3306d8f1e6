"""Write a Recording as one self-describing MCAP trial file (atomically, under the writer lock)."""

from __future__ import annotations

import hashlib
import mimetypes
import os
import struct
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from imulog import __version__
from imulog.archive import codec
from imulog.archive._builder import McapBuilder
from imulog.archive.errors import ArchiveError, ArchiveExistsError
from imulog.archive.files import atomic_output, target_path, writer_lock
from imulog.archive.metadata import encode_record
from imulog.model import Recording, Stream

LIBRARY = f"imulog {__version__}"
PROFILE = ""  # plain MCAP profile: Foxglove and Rerun treat the protobuf channels generically


def payload_hash(payloads: Iterable[bytes | memoryview]) -> str:
    """Content hash of a channel: SHA-256 over its messages (8-byte length + bytes each, in log order)."""
    h = hashlib.sha256()
    for p in payloads:
        h.update(struct.pack("<Q", len(p)))
        h.update(p)
    return h.hexdigest()


def raw_digest(channels: dict[str, str], attachments: dict[str, str]) -> str:
    """The trial's raw-data hash: SHA-256 over the sorted raw channel hashes and attachment hashes."""
    h = hashlib.sha256()
    for topic in sorted(channels):
        h.update(f"channel\0{topic}\0{channels[topic]}\n".encode())
    for name in sorted(attachments):
        h.update(f"attachment\0{name}\0{attachments[name]}\n".encode())
    return h.hexdigest()


def write_stream(builder: McapBuilder, stream: Stream, extra_meta: dict[str, str] | None = None) -> tuple[str, str]:
    """Encode and write one stream as a channel; return (topic, content hash)."""
    schema_name, meta, times, payloads = codec.encode(stream)
    digest = payload_hash(payloads)
    meta["sha256"] = digest
    if extra_meta:
        meta.update(extra_meta)
    schema_id = builder.add_schema(schema_name, "protobuf", codec.file_descriptor_set(schema_name))
    channel_id = builder.add_channel(stream.topic, schema_id, meta)
    builder.add_messages(channel_id, times, payloads)
    return stream.topic, digest


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
    path: str | os.PathLike[str], recording: Recording, *, attach_sources: bool = True, overwrite: bool = False
) -> Path:
    """Write ``recording`` to ``path`` as an MCAP trial; return the path.

    Raw channels (one per stream, topics from the streams), metadata records (the recording's, plus an
    ``imulog.device.<name>`` per IMU when missing, plus ``imulog.raw`` with the raw-data hash), and the
    source files as attachments. The file appears atomically; on any error nothing is left behind.
    """
    path = target_path(path)
    streams = recording.streams()
    topics = [s.topic for s in streams]
    dup = sorted({t for t in topics if topics.count(t) > 1})
    if dup:
        raise ArchiveError(f"{path}: two streams share the topic(s) {', '.join(dup)}")
    sources = _attachment_names(recording.sources) if attach_sources else []
    for src, _ in sources:
        if not src.is_file():
            raise ArchiveError(f"{path}: source file to attach not found: {src}")
    path.parent.mkdir(parents=True, exist_ok=True)
    with writer_lock(path):
        if path.exists() and not overwrite:
            raise ArchiveExistsError(f"{path} exists (use overwrite=True / --overwrite)")
        with atomic_output(path) as f:
            builder = McapBuilder.new(f, LIBRARY, PROFILE)
            hashes: dict[str, str] = {}
            for stream in streams:
                topic, digest = write_stream(builder, stream)
                hashes[topic] = digest
            attached: dict[str, str] = {}
            for src, name in sources:
                data = src.read_bytes()
                media_type = mimetypes.guess_type(name)[0] or "application/octet-stream"
                mtime = max(src.stat().st_mtime_ns, 0)
                builder.add_attachment(name, media_type, data, log_time=mtime, create_time=mtime)
                attached[name] = hashlib.sha256(data).hexdigest()
            # imulog.raw describes this file's raw data: always recomputed (e.g. when re-writing a read trial)
            records = {
                k: v for k, v in {**recording.metadata, **_device_records(recording)}.items() if k != "imulog.raw"
            }
            for name, values in records.items():
                builder.add_metadata(name, encode_record(dict(values)))
            raw = {
                "sha256": raw_digest(hashes, attached),
                "channels": hashes,
                "attachments": attached,
                "sources": [str(src) for src, _ in sources],
                "imulog_version": __version__,
            }
            builder.add_metadata("imulog.raw", encode_record(raw))
            builder.finish()
    return path


__all__ = ["write_trial", "payload_hash", "raw_digest"]
