"""Reading source files: the head, the whole bytes with their SHA-256 remembered, text lines and cells."""

from __future__ import annotations

import hashlib
import os
from concurrent.futures import Future
from pathlib import Path

from imulog.converters.errors import ConversionError

HEAD_BYTES = 256 * 1024


# ------------------------------------------------------------------------------------------ text input
def read_head(path: Path, n: int = HEAD_BYTES) -> bytes:
    with open(path, "rb") as f:
        return f.read(n)


_DIGESTS: dict[tuple[str, int, int], str | Future[str]] = {}  # (resolved path, size, mtime ns) -> SHA-256


_DIGESTS_KEPT = 256


BACKGROUND_HASH_BYTES = 1 << 20  # smaller sources are hashed at once

# a forked child (batch workers) gets its own worker threads; digests still being computed by the parent's never end
os.register_at_fork(after_in_child=_DIGESTS.clear)


def _stat_key(path: Path, st: os.stat_result) -> tuple[str, int, int]:
    return str(Path(path).resolve()), st.st_size, st.st_mtime_ns


def _sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def read_source(path: Path) -> bytes:
    """A source file's bytes, read once; their SHA-256 is computed from them and remembered (size and mtime
    checked) so that the conversion record does not read and hash the file a second time (:func:`known_sha256`).

    Sources of 1 MiB and more are hashed on the package's worker threads (:mod:`imulog.workers`, shared with the archive writer) while the caller parses them
    (hashlib releases the GIL): the SHA-256 of a 57 MB export takes ~45 ms, which then overlaps the parse.
    """
    with open(path, "rb") as f:
        data = f.read()
        st = os.fstat(f.fileno())
    if st.st_size == len(data):
        if len(data) < BACKGROUND_HASH_BYTES:
            remember_sha256(path, st, _sha256_hex(data))
        else:
            from imulog.workers import in_background

            remember_sha256(path, st, in_background(_sha256_hex, data))
    return data


def remember_sha256(path: Path, st: os.stat_result, digest: str | Future[str]) -> None:
    """Remember the SHA-256 of ``path`` as read while it had the size and mtime of ``st`` (:func:`known_sha256`);
    ``digest`` may still be being computed (a Future)."""
    if len(_DIGESTS) >= _DIGESTS_KEPT:
        _DIGESTS.pop(next(iter(_DIGESTS)))
    _DIGESTS[_stat_key(path, st)] = digest


def known_sha256(path: Path) -> str | None:
    """The SHA-256 :func:`read_source` computed for ``path`` when the file has not changed since (else None)."""
    try:
        digest = _DIGESTS.get(_stat_key(path, os.stat(path)))
    except OSError:
        return None
    return digest.result() if isinstance(digest, Future) else digest


def looks_binary(head: bytes) -> bool:
    """True for data that is not a text export (NUL bytes or many control characters)."""
    if not head:
        return False
    if b"\x00" in head:
        return True
    sample = head[:8192]
    controls = sum(1 for b in sample if b < 32 and b not in (9, 10, 13, 12))
    return controls > max(2, len(sample) // 100)


def decode(data: bytes) -> str:
    """Text of a header (UTF-8 with optional BOM, else Latin-1, which never fails)."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def head_lines(path: Path, head: bytes | None = None, max_lines: int = 200) -> list[str]:
    """The first lines of a text file (without line endings); raises for empty or binary files."""
    head = read_head(path) if head is None else head
    if not head.strip():
        raise ConversionError(path, "empty file")
    if looks_binary(head):
        raise ConversionError(path, "binary data, not a text export")
    lines = decode(head).splitlines()
    if len(head) == HEAD_BYTES and len(lines) > 1:
        lines = lines[:-1]  # the last one may be cut
    return lines[:max_lines]


# (head, its lines or None): detection hands the same head to every converter; one tuple, replaced whole, so
# that threads detecting at once never pair one head with another's lines
_SNIFFED: tuple[bytes | None, list[str] | None] = (None, None)


def text_head_lines(head: bytes, max_lines: int = 50) -> list[str] | None:
    """Like :func:`head_lines` for sniffing: None instead of raising. The head's lines are computed once for all
    the converters sniffing the same head (decoding 256 KiB and testing for binary data takes ~0.7 ms each)."""
    global _SNIFFED
    cached, lines = _SNIFFED
    if cached is not head:
        lines = None if not head.strip() or looks_binary(head) else decode(head).splitlines()
        _SNIFFED = (head, lines)
    return None if lines is None else lines[:max_lines]


def split_row(line: str, delimiter: str) -> list[str]:
    """Split one header/data row; strips whitespace and surrounding double quotes of each cell."""
    cells = line.split() if delimiter == " " else line.split(delimiter)
    return [c.strip().strip('"').strip() for c in cells]


def is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True
