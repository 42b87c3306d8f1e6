"""Attached originals stored compressed (issue 28).

An original (the converted CSV, .cwa, .c3d, ...) is stored as one MCAP Attachment record whose data is
compressed when that makes it at least 10 % smaller: bzip2 for text (CSV, JSON, TSV: about 6x on exported
numbers, 1.5x better than zstd at the same speed), zstd for binary files. The attachment keeps the file's
name; its media type says how it is packed and names the file's own media type::

    application/x-bzip2; imulog-packed=text/csv
    application/zstd; imulog-packed=application/octet-stream

imulog's readers (:meth:`TrialReader.iter_attachments`, ``doctor``, ``salvage``, exports that read the
original) give back the original bytes and their SHA-256, which is what ``imulog.raw`` records; a generic MCAP
tool sees a bzip2 or zstd file (``mcap get attachment`` then ``bunzip2`` / ``zstd -d``). Attachments without
the marker (older archives, files that do not compress) are read as they are.
"""

from __future__ import annotations

import bz2

import zstandard

MARK = "; imulog-packed="
ZSTD = "application/zstd"
BZIP2 = "application/x-bzip2"
ZSTD_LEVEL = 9  # binary originals: about 20 MB/s here, decompressed at hundreds of MB/s
MAX_BYTES = 256 << 20  # larger originals are stored as they are (compressing would hold both in memory)
_GAIN = 0.9  # packed only when the compressed file is at most this fraction of the original
_TEXT = ("text/", "application/json", "application/xml")


def _is_text(media_type: str, data: bytes) -> bool:
    return media_type.startswith(_TEXT) or (media_type == "application/octet-stream" and b"\0" not in data[:4096])


def pack(data: bytes, media_type: str) -> tuple[bytes, str]:
    """(stored bytes, stored media type) of one original: compressed when it pays, else the bytes as they are."""
    if not data or len(data) > MAX_BYTES:
        return data, media_type
    if _is_text(media_type, data):
        packed, how = bz2.compress(data, 9), BZIP2
    else:
        packed, how = zstandard.ZstdCompressor(level=ZSTD_LEVEL, write_content_size=True).compress(data), ZSTD
    if len(packed) > _GAIN * len(data):
        return data, media_type
    return packed, how + MARK + media_type


def is_packed(media_type: str) -> bool:
    """True when an attachment's data is the compressed original (imulog's marker in the media type)."""
    return media_type.startswith((ZSTD + MARK, BZIP2 + MARK))


def original_media_type(media_type: str) -> str:
    """The file's own media type of a stored attachment."""
    return media_type.split(MARK, 1)[1] if is_packed(media_type) else media_type


def unpack(data: bytes | memoryview, media_type: str) -> bytes:
    """The original bytes of a stored attachment (``data`` itself when it is not packed)."""
    if not is_packed(media_type):
        return bytes(data)
    if media_type.startswith(BZIP2):
        return bz2.decompress(bytes(data))
    return zstandard.ZstdDecompressor().decompress(bytes(data))
