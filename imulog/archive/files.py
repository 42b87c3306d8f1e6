"""Atomic file replacement and the writer lock.

Every write goes to a temporary file beside the target (``.NAME.PID.tmp``), is fsynced and then moved over
the target with :func:`os.replace`, so a reader or a crash never sees a half-written archive. A lock file
(``.NAME.lock``, held with ``flock``) refuses a second writer; the kernel releases it when the holder dies,
so a killed writer never leaves a stale lock. Appends write in place instead, their old summary kept in a
journal until the new footer is durable (:mod:`imulog.archive.journal`); the writer lock undoes one that died.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import stat
import time
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from imulog.archive.errors import ArchiveLockedError
from imulog.archive.journal import fsync_dir, recover


def target_path(path: str | os.PathLike[str]) -> Path:
    """The file to replace: a symlink is followed so that the link keeps pointing at the new file."""
    path = Path(path)
    return path.resolve() if path.is_symlink() else path


def lock_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.lock")


def temp_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def step_lock_path(path: Path, step: str) -> Path:
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", step)[:80]
    return path.with_name(f".{path.name}.step-{safe}.lock")


@contextlib.contextmanager
def step_lock(path: str | os.PathLike[str], step: str, timeout_s: float = 3600.0) -> Iterator[None]:
    """Hold the lock of one step on one trial, waiting (up to ``timeout_s``) while another process runs it.

    A second run of the same step thus starts after the first has written, and finds its result up to
    date instead of computing it again. The kernel releases the lock if the holder dies.
    """
    path = Path(path)
    lp = step_lock_path(path, step)
    try:
        os.close(os.open(lp, os.O_RDWR | os.O_CREAT, 0o644))
    except OSError as exc:
        if exc.errno not in (errno.EACCES, errno.EPERM, errno.EROFS):
            raise
        yield  # a read-only folder: nothing can be written anyway, so there is no race to prevent
        return
    with _flock(lp, path, timeout_s, what=f"step {step!r} of"):
        yield


@contextlib.contextmanager
def writer_lock(path: str | os.PathLike[str], wait_s: float = 0.0) -> Iterator[None]:
    """Hold the exclusive writer lock of ``path``; raise ArchiveLockedError if another process holds it
    (after waiting up to ``wait_s`` seconds for it to finish)."""
    path = Path(path)
    with _flock(lock_path(path), path, wait_s, what="writing"):
        # Temporary files of writers that died (SIGKILL) can be removed now: nobody else writes.
        for stale in path.parent.glob(f".{path.name}.*.tmp"):
            with contextlib.suppress(OSError):
                stale.unlink()
        recover(path)  # an append that died midway (imulog.archive.journal) is undone before anything else
        yield


@contextlib.contextmanager
def _flock(lp: Path, path: Path, wait_s: float, what: str) -> Iterator[None]:
    """Hold an flock on lock file ``lp`` (unlinked on release), waiting up to ``wait_s`` for it."""
    deadline = time.monotonic() + wait_s
    while True:
        fd = os.open(lp, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            if time.monotonic() < deadline:
                time.sleep(0.05)
                continue
            try:
                holder = lp.read_text().strip() or "?"
            except OSError:
                holder = "?"
            if what == "writing":
                message = f"{path}: another process (pid {holder}) is writing this archive"
            else:
                message = f"{path}: another process (pid {holder}) is running {what} this archive"
            raise ArchiveLockedError(f"{message}; try again when it has finished") from None
        # The previous holder may have unlinked the lock file between our open and flock: retry then.
        try:
            same = os.fstat(fd).st_ino == os.stat(lp).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        yield
    finally:
        with contextlib.suppress(OSError):
            lp.unlink()
        os.close(fd)


@contextlib.contextmanager
def atomic_output(path: Path) -> Iterator[BinaryIO]:
    """Yield a file object for ``path``'s temp file; on success fsync + os.replace, on error remove it."""
    tmp = temp_path(path)
    f = open(tmp, "wb")  # noqa: SIM115 - closed below on every path
    try:
        with contextlib.suppress(OSError):  # keep the permissions of the file being replaced
            os.chmod(tmp, stat.S_IMODE(os.stat(path).st_mode))
        yield f
        f.flush()
        os.fsync(f.fileno())
        f.close()
        os.replace(tmp, path)
        fsync_dir(path.parent)
    except BaseException:
        f.close()
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
