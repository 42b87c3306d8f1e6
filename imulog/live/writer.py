"""The streaming trial writer for a live recording: every channel's chunk is closed and flushed every second.

:class:`LiveTrialWriter` is :class:`imulog.archive.streaming.StreamingTrialWriter` writing into a visible
``<trial>.part`` file instead of a hidden temporary one, so that a recorder killed by SIGKILL, a power cut or a
full disk leaves a file ``imulog salvage`` turns into a trial. :meth:`LiveTrialWriter.flush` closes the pending
chunk of every channel, writes it out and fsyncs the file (the recorder calls it at least once a second).
Metadata records known early (the trial's, each stream's device record and LSL header, the time axis) are
written as soon as they are known, also for salvage; the statistics, the raw-data hash and the recording summary
(``imulog.record``) at the end, when the ``.part`` file is renamed to the trial.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any

from imulog.archive._builder import McapBuilder
from imulog.archive.errors import ArchiveError, ArchiveExistsError
from imulog.archive.files import fsync_dir, writer_lock
from imulog.archive.metadata import encode_record
from imulog.archive.streaming import STATS_RECORD, StreamingTrialWriter
from imulog.archive.timeline import TIMELINE_RECORD
from imulog.model import Recording

SUMMARY_RECORD = "imulog.record"


def part_path(path: Path) -> Path:
    """Where a recording into ``path`` is written until it stops: ``trial.mcap.part``."""
    return path.with_name(path.name + ".part")


class LiveTrialWriter(StreamingTrialWriter):
    """``with LiveTrialWriter(path, metadata=...) as w: w.write(piece); w.flush()``.

    Refuses an existing ``path`` (or a ``.part`` left by a killed recording) unless ``overwrite``. On a clean
    exit the ``.part`` file is finished, fsynced and renamed to ``path``; on an exception it is flushed and kept
    for ``imulog salvage`` when it holds samples (``kept_part``), else removed.
    """

    def __init__(self, path: str | os.PathLike[str], **kwargs: Any) -> None:
        super().__init__(path, **kwargs)
        self.part = part_path(self.path)
        self._file: Any = None
        self._written: set[str] = set()
        self.kept_part = False  # an error stopped the recording: what it had is in ``part``

    def __enter__(self) -> LiveTrialWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        lock = writer_lock(self.path)
        lock.__enter__()
        self._stack.append(lock)
        for existing in (self.path, self.part):
            if existing.exists() and not self.overwrite:
                self._unwind(None)
                hint = f"; recover it with: imulog salvage {existing} -o OUT.mcap" if existing == self.part else ""
                raise ArchiveExistsError(f"{existing} exists (use --overwrite){hint}")
        self._file = open(self.part, "wb")  # noqa: SIM115 - closed in __exit__
        from imulog.archive.writer import LIBRARY, PROFILE

        self._builder = McapBuilder.new(self._file, LIBRARY, PROFILE)
        self._sync()  # the magic and header on disk: a kill from now on leaves an MCAP start
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self._abandon()
            self._unwind(None)
            return
        try:
            self._finish()
            self._sync()
            self._file.close()
            os.replace(self.part, self.path)
            fsync_dir(self.path.parent)
        except BaseException:
            self._abandon()
            self._unwind(None)
            raise
        self._unwind(None)

    def _abandon(self) -> None:
        """On an error: a recording that has samples keeps its ``.part`` (flushed, for salvage); else it goes."""
        if self.started:
            with contextlib.suppress(Exception):
                self.flush()
            with contextlib.suppress(OSError):
                self._file.close()
            self.kept_part = True
        else:
            self._discard()

    def _discard(self) -> None:
        with contextlib.suppress(OSError):
            self._file.close()
        with contextlib.suppress(OSError):
            self.part.unlink()

    # ------------------------------------------------------------------ writing
    @property
    def started(self) -> bool:
        return self._topics is not None

    def write(self, piece: Recording) -> None:
        """Append one piece; its metadata records not yet in the file are written now (once)."""
        first = not self.started
        records = {k: v for k, v in piece.metadata.items() if k not in self._written}
        piece.metadata = {}
        for key, values in records.items():
            self.metadata[key] = {**self.metadata.get(key, {}), **values}
        super().write(piece)
        if first:
            self.metadata[TIMELINE_RECORD] = dict(self._timeline or {})
        self._write_records()

    def add_records(self, records: dict[str, dict[str, Any]]) -> None:
        """Metadata records to write with the next piece (or now, once the trial has started)."""
        for key, values in records.items():
            if key not in self._written:
                self.metadata[key] = {**self.metadata.get(key, {}), **values}
        if self.started:
            self._write_records()

    def _write_records(self) -> None:
        for name, values in self.metadata.items():
            if name not in self._written and name not in ("imulog.raw", STATS_RECORD, SUMMARY_RECORD):
                self._builder.add_metadata(name, encode_record(dict(values)))
                self._written.add(name)

    def flush(self) -> None:
        """Close every channel's pending chunk, write it out and fsync: a kill now loses nothing written so far."""
        for ch in [*self._channels.values(), *self._twins.values()]:
            self._flush(ch)
        self._sync()

    def _sync(self) -> None:
        self._builder.offset  # noqa: B018 - writes out the chunks still being compressed
        self._file.flush()
        os.fsync(self._file.fileno())

    def _finish(self) -> None:
        """Statistics, the recording summary and the raw-data hash (other records are in the file already)."""
        from imulog import __version__
        from imulog.archive.writer import raw_digest

        if not self.started:
            raise ArchiveError(f"{self.path}: nothing to write (no stream sent a sample)")
        for ch in [*self._channels.values(), *self._twins.values()]:
            self._flush(ch)
        self._write_records()
        stats = {topic: ch.stats.to_meta() for topic, ch in self._channels.items()}
        hashes = {topic: s["sha256"] for topic, s in stats.items()}
        for topic, ch in self._twins.items():
            stats[topic] = {k: v for k, v in ch.stats.to_meta().items() if k != "nan_samples"}
        if SUMMARY_RECORD in self.metadata:
            self._builder.add_metadata(SUMMARY_RECORD, encode_record(dict(self.metadata[SUMMARY_RECORD])))
        self._builder.add_metadata(STATS_RECORD, encode_record(stats))
        raw = {
            "sha256": raw_digest(hashes, {}),
            "channels": hashes,
            "attachments": {},
            "sources": [],
            "imulog_version": __version__,
        }
        self._builder.add_metadata("imulog.raw", encode_record(raw))
        self._builder.finish()


def cut_file(path: Path) -> Path | None:
    """The ``.part`` file a killed recording into ``path`` left, if any."""
    part = part_path(Path(path))
    return part if part.exists() else None
