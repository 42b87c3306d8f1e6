"""Exceptions raised by :mod:`imulog.archive` (all subclasses of :class:`ArchiveError`)."""

from __future__ import annotations


class ArchiveError(Exception):
    """A trial archive cannot be read or written; the message is one line naming the file."""


class ArchiveExistsError(ArchiveError, FileExistsError):
    """The output exists and ``overwrite`` was not given."""


class ArchiveLockedError(ArchiveError):
    """Another process is writing the same archive."""


class ArchiveCorruptError(ArchiveError):
    """The file is not a valid (or not a complete) MCAP archive."""
