"""Append in place, crash-safe: the old summary is kept in a journal until the new footer is durable.

An append adds records after the data section; every byte before the old DataEnd stays where it is. Instead of
copying those bytes into a new file (DESIGN.md's copy-then-rename; on a week's trial gigabytes per step), the
new records are written into the file itself, over its old tail (DataEnd, summary, footer):

1. the old tail (from DataEnd to the end of the file) is written to ``.NAME.journal`` beside the trial, with
   the old size and a CRC, fsynced and renamed into place (so a journal is whole or absent);
2. the old closing magic is zeroed: from now on the file does not parse as MCAP on its own;
3. the new records, DataEnd, summary and footer are written from the old DataEnd on, the file is cut at its new
   end and fsynced;
4. the journal is removed (and the folder fsynced): the append is done.

A reader that meets a file without a valid footer and a journal beside it reads the file as it was before the
append (the journal's tail over the file's unchanged data section: :func:`read_summary`). A writer that finds a
journal (the appending process died) settles it first (:func:`recover`, run by the writer lock): if the file is
whole (it parses, and its new DataEnd's CRC is the old one continued over the new records) the append is kept,
as a reader already sees it; otherwise the old tail is restored, so the trial is exactly as it was, byte for
byte. A failed append in a live process restores the old tail before it raises.
"""

from __future__ import annotations

import contextlib
import os
import struct
import sys
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from imulog.archive import _mcap as m
from imulog.archive.errors import ArchiveCorruptError

JOURNAL_MAGIC = b"IMULOGJ1"
_HEAD = struct.Struct("<8sQQI")  # magic, old file size (bytes), old DataEnd offset (bytes), CRC-32 of the tail
MAX_TAIL = 1 << 31  # a summary larger than this is not one imulog wrote: refuse rather than hold it in memory


def journal_path(path: Path) -> Path:
    """The journal of an append in progress on ``path``: ``.NAME.journal`` beside it."""
    return path.with_name(f".{path.name}.journal")


def fsync_dir(directory: Path) -> None:
    """fsync a folder, so that a rename or unlink in it is durable (ignored where folders cannot be opened)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@dataclass(frozen=True)
class Journal:
    """The old tail of a trial whose append has not finished: ``tail`` belongs at byte ``data_end``."""

    old_size: int
    data_end: int
    tail: bytes


def load(path: Path) -> Journal | None:
    """The journal of ``path``, or None when there is none; ArchiveCorruptError if it is damaged."""
    jp = journal_path(path)
    try:
        raw = jp.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise ArchiveCorruptError(f"{jp}: {exc.strerror or exc}") from None
    if len(raw) < _HEAD.size:
        raise ArchiveCorruptError(f"{jp}: append journal too short ({len(raw)} bytes)")
    magic, old_size, data_end, crc = _HEAD.unpack_from(raw)
    tail = raw[_HEAD.size :]
    if magic != JOURNAL_MAGIC or data_end + len(tail) != old_size or zlib.crc32(tail) != crc:
        raise ArchiveCorruptError(f"{jp}: damaged append journal (bad magic, size or CRC)")
    return Journal(old_size, data_end, tail)


def _write_journal(path: Path, journal: Journal) -> None:
    """Write the journal atomically (temporary file, fsync, rename, folder fsync)."""
    jp = journal_path(path)
    tmp = jp.with_name(jp.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(_HEAD.pack(JOURNAL_MAGIC, journal.old_size, journal.data_end, zlib.crc32(journal.tail)))
        f.write(journal.tail)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, jp)
    fsync_dir(path.parent)


def _restore(f: BinaryIO, journal: Journal) -> None:
    """Put the old tail back and cut the file at its old size (then it is the file before the append)."""
    f.seek(journal.data_end)
    f.write(journal.tail)
    f.truncate(journal.old_size)
    f.flush()
    os.fsync(f.fileno())


def _drop(path: Path) -> None:
    with contextlib.suppress(FileNotFoundError):
        journal_path(path).unlink()
    fsync_dir(path.parent)


def recover(path: Path) -> bool:
    """Undo an append that did not finish (its process died); True if there was one. Call with the writer lock."""
    with contextlib.suppress(FileNotFoundError):
        journal_path(path).with_name(journal_path(path).name + ".tmp").unlink()  # died while writing the journal
    journal = load(path)
    if journal is None:
        return False
    try:
        f = open(path, "r+b")  # noqa: SIM115 - closed below
    except FileNotFoundError:  # the trial is gone: its journal describes nothing
        _drop(path)
        return False
    with f:
        size = os.fstat(f.fileno()).st_size
        if size < journal.data_end:
            raise ArchiveCorruptError(
                f"{path}: shorter ({size} bytes) than the data section its append journal keeps "
                f"({journal.data_end} bytes); run 'imulog doctor {path}'"
            )
        done = _finished(f, size, journal)
        if done:
            os.fsync(f.fileno())
        else:
            _restore(f, journal)
    _drop(path)
    if done:
        print(f"{path}: an append whose process died had written everything; kept", file=sys.stderr)
    else:
        print(f"{path}: an interrupted append was undone (the trial is as before it)", file=sys.stderr)
    return True


def _finished(f: BinaryIO, size: int, journal: Journal) -> bool:
    """True if the append had written its whole file (only the journal's removal was missing): the file parses,
    and the data CRC of its new DataEnd is the old one continued over the new records (read: only those)."""
    try:
        s = m.read_summary(f, size)
    except m.McapFormatError:
        return False
    old_crc = struct.unpack_from("<I", journal.tail, 9)[0] if len(journal.tail) >= m.DATA_END_SIZE else 0
    if s.data_end_offset < journal.data_end or old_crc == 0 or s.data_section_crc == 0:
        return False  # nothing to check the new records against: undo
    crc, pos = old_crc, journal.data_end
    f.seek(pos)
    while pos < s.data_end_offset:
        block = f.read(min(8 << 20, s.data_end_offset - pos))
        if not block:
            return False
        crc = zlib.crc32(block, crc)
        pos += len(block)
    return crc == s.data_section_crc


@contextlib.contextmanager
def append_in_place(path: Path, summary: m.Summary, source: BinaryIO) -> Iterator[BinaryIO]:
    """Yield ``path`` opened for writing at its old DataEnd, the old tail kept in the journal (steps 1-4 above).

    The caller writes the new records and finishes the file (DataEnd, summary, footer). On success the file is
    cut at the caller's last byte and fsynced, then the journal goes; on any error the old tail is restored.
    ``source`` is the trial already open for reading (its old tail is read from it).
    """
    data_end, old_size = summary.data_end_offset, summary.file_size
    if old_size - data_end > MAX_TAIL:
        raise ArchiveCorruptError(f"{path}: summary of {old_size - data_end} bytes is too large to journal")
    source.seek(data_end)
    tail = source.read(old_size - data_end)
    if len(tail) != old_size - data_end:
        raise ArchiveCorruptError(f"{path}: unexpected end of file at byte {data_end + len(tail)}")
    journal = Journal(old_size, data_end, tail)
    _write_journal(path, journal)
    try:
        out = open(path, "r+b")  # noqa: SIM115 - closed below
    except BaseException:
        _drop(path)
        raise
    try:
        out.seek(old_size - len(m.MAGIC))
        out.write(b"\0" * len(m.MAGIC))  # the old footer no longer closes the file: readers use the journal
        out.flush()
        out.seek(data_end)
        yield out
        out.flush()
        out.truncate(out.tell())
        os.fsync(out.fileno())
    except BaseException:
        with contextlib.suppress(OSError):
            out.flush()
        _restore(out, journal)
        out.close()
        _drop(path)
        raise
    out.close()
    _drop(path)


class _Overlay:
    """A read-only file view: the trial's bytes before ``data_end``, the journal's tail from there on."""

    def __init__(self, f: BinaryIO, journal: Journal) -> None:
        self._f, self._j, self._pos = f, journal, 0

    def seek(self, pos: int, whence: int = 0) -> int:
        self._pos = pos if whence == 0 else (self._pos + pos if whence == 1 else self._j.old_size + pos)
        return self._pos

    def tell(self) -> int:
        return self._pos

    def read(self, n: int = -1) -> bytes:
        end = self._j.old_size if n < 0 else min(self._pos + n, self._j.old_size)
        out = b""
        if self._pos < self._j.data_end:
            self._f.seek(self._pos)
            out = self._f.read(min(end, self._j.data_end) - self._pos)
        lo = max(self._pos, self._j.data_end) - self._j.data_end
        if end > self._j.data_end:
            out += self._j.tail[lo : end - self._j.data_end]
        self._pos += len(out)
        return out


def read_summary_view(f: BinaryIO, size: int, path: Path) -> tuple[m.Summary, BinaryIO]:
    """:func:`imulog.archive._mcap.read_summary` and the file to read the trial through: ``f`` itself, or, while
    an append is in progress or after one died, a view of the trial as it was before the append (the journal's
    old tail over the unchanged data section)."""
    try:
        return m.read_summary(f, size), f
    except m.McapFormatError as exc:
        first = exc
    path = Path(path)
    journal = load(path.resolve() if path.is_symlink() else path)  # the writer journals the link's target
    if journal is None:  # no append under way, or one just finished: read the file once more
        now = os.fstat(f.fileno()).st_size
        if now == size:
            raise first
        return m.read_summary(f, now), f
    if os.fstat(f.fileno()).st_size < journal.data_end:
        raise first
    view = _Overlay(f, journal)
    return m.read_summary(view, journal.old_size), view  # type: ignore[arg-type]


def read_summary(f: BinaryIO, size: int, path: Path) -> m.Summary:
    """The summary of the trial in ``f`` as :func:`read_summary_view` finds it."""
    return read_summary_view(f, size, path)[0]
