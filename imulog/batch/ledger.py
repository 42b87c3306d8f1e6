"""The batch ledger: a cheap pre-check so files already processed by the same plan do no work at all.

After every file a batch finishes (processed or up to date), one JSON line is appended to the ledger
(default ``.imulog-batch.jsonl`` in the archive's top folder): the file's absolute path, size, mtime (ns),
inode and the plan's fingerprint (steps, options, imulog version). A later batch with the same plan skips a
file whose size, mtime and inode are unchanged without opening it. Any change to the file (a step run by
hand, a re-conversion) changes its mtime or inode, and the file goes through the steps again, where
:func:`imulog.steps.base.run_step` still skips each step whose inputs and parameters are recorded.

The ledger is append-only and written by the batch's driver process only; a torn last line (a killed
batch) is ignored. Deleting it is always safe: it only costs the pre-check.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path

LEDGER_NAME = ".imulog-batch.jsonl"


def file_key(path: str | os.PathLike[str]) -> tuple[int, int, int] | None:
    """``(size, mtime_ns, inode)`` of a file, or None if it cannot be stat'ed."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns, st.st_ino


def plan_hash(fingerprint: str) -> str:
    return hashlib.sha256(fingerprint.encode()).hexdigest()[:16]


def default_ledger_path(paths: list[str]) -> Path | None:
    """``.imulog-batch.jsonl`` in the deepest folder holding every path (None without paths)."""
    if not paths:
        return None
    dirs = [os.path.dirname(os.path.abspath(p)) for p in paths]
    try:
        return Path(os.path.commonpath(dirs)) / LEDGER_NAME
    except ValueError:  # different drives
        return None


class Ledger:
    """Read the ledger once, then ask :meth:`is_current` and :meth:`record` per file."""

    def __init__(self, path: str | os.PathLike[str] | None) -> None:
        self.path = Path(path) if path is not None else None
        self._entries: dict[str, tuple[int, int, int, str]] = {}
        if self.path is not None and self.path.is_file():
            with open(self.path, encoding="utf-8", errors="replace") as f:
                for line in f:
                    try:
                        e = json.loads(line)
                        self._entries[e["path"]] = (int(e["size"]), int(e["mtime_ns"]), int(e["ino"]), str(e["plan"]))
                    except (ValueError, KeyError, TypeError):
                        continue  # torn or foreign line
        self._fh = None

    def __len__(self) -> int:
        return len(self._entries)

    def is_current(self, path: str, plan: str) -> bool:
        """True when ``path`` was finished by ``plan`` (a plan hash) and has not changed since."""
        entry = self._entries.get(os.path.abspath(path))
        if entry is None or entry[3] != plan:
            return False
        return file_key(path) == entry[:3]

    def record(self, path: str, plan: str) -> None:
        """Append ``path``'s current size/mtime/inode as finished by ``plan`` (flushed and fsynced)."""
        if self.path is None:
            return
        key = file_key(path)
        if key is None:
            return
        apath = os.path.abspath(path)
        self._entries[apath] = (*key, plan)
        line = json.dumps({"path": apath, "size": key[0], "mtime_ns": key[1], "ino": key[2], "plan": plan})
        if self._fh is None:
            self._fh = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self._fh.write(line + "\n")
        self._fh.flush()
        with contextlib.suppress(OSError):
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
