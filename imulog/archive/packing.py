"""Attached originals compressed with zstd (issue 28).

An original (the converted CSV, .cwa, .c3d, ...) is stored as one MCAP Attachment record whose data is a zstd
frame when that is at least 10 % smaller; its media type then says so and names the file's own media type::

    application/zstd; imulog-packed=text/csv

The attachment keeps the file's name. imulog's readers (:meth:`TrialReader.iter_attachments`, ``doctor``,
``salvage``, exports that read the original) give back the original bytes and their SHA-256, which is what
``imulog.raw`` records; a generic MCAP tool sees a zstd file (``mcap get attachment`` then ``zstd -d``).
Attachments without the marker (older archives, files that do not compress) are read as they are.
"""

from __future__ import annotations

import zstandard

PACKED_PREFIX = "application/zstd; imulog-packed="
LEVEL = 9  # about 4x on CSV text at ~20 MB/s, decompressed at hundreds of MB/s
MAX_BYTES = 256 << 20  # larger originals are stored as they are (compressing would hold both in memory)
_GAIN = 0.9  # packed only when the frame is at most this fraction of the file


def pack(data: bytes, media_type: str) -> tuple[bytes, str]:
    """(stored bytes, stored media type) of one original: a zstd frame when it pays, else the bytes as they are."""
    if not data or len(data) > MAX_BYTES:
        return data, media_type
    frame = zstandard.ZstdCompressor(level=LEVEL, write_content_size=True).compress(data)
    if len(frame) > _GAIN * len(data):
        return data, media_type
    return frame, PACKED_PREFIX + media_type


def is_packed(media_type: str) -> bool:
    """True when an attachment's data is a zstd frame of the original (imulog's marker in the media type)."""
    return media_type.startswith(PACKED_PREFIX)


def original_media_type(media_type: str) -> str:
    """The file's own media type of a stored attachment."""
    return media_type[len(PACKED_PREFIX) :] if is_packed(media_type) else media_type


def unpack(data: bytes | memoryview, media_type: str) -> bytes:
    """The original bytes of a stored attachment (``data`` itself when it is not packed)."""
    if not is_packed(media_type):
        return bytes(data)
    return zstandard.ZstdDecompressor().decompress(bytes(data))
