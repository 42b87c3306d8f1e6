"""Chunk decompression with bounds: a declared size is checked before anything is allocated (a decompression
bomb is refused), the output never exceeds it, the CRC is verified. Part of :mod:`imulog.archive._mcap`."""

from __future__ import annotations

import contextlib
import zlib

from imulog.archive.mcap_records import ChunkRec, McapFormatError

MAX_CHUNK_BYTES = 256 * 1024 * 1024  # refuse chunks declaring more than this uncompressed (bytes)
MAX_CHUNK_RATIO = 1024  # ... or more than this many times their compressed size, above RATIO_FREE_BYTES
RATIO_FREE_BYTES = 4 * 1024 * 1024  # chunks up to this uncompressed size may have any ratio


def check_chunk_size(compressed_size: int, uncompressed_size: int) -> None:
    """Refuse a chunk whose declared uncompressed size is implausible (huge, or a decompression bomb)."""
    if uncompressed_size > MAX_CHUNK_BYTES:
        raise McapFormatError(
            f"chunk declares {uncompressed_size} bytes uncompressed, above the {MAX_CHUNK_BYTES >> 20} MiB limit"
        )
    if uncompressed_size > RATIO_FREE_BYTES and uncompressed_size > MAX_CHUNK_RATIO * max(compressed_size, 1):
        raise McapFormatError(
            f"chunk declares {uncompressed_size} bytes from {compressed_size} compressed "
            f"(ratio above {MAX_CHUNK_RATIO}: a decompression bomb?)"
        )


def _read_bounded(reader, limit: int) -> bytes:
    """Read at most ``limit`` bytes from a decompressing reader (stops early at its end)."""
    parts, total = [], 0
    while total < limit:
        block = reader.read(limit - total)
        if not block:
            break
        parts.append(block)
        total += len(block)
    return parts[0] if len(parts) == 1 else b"".join(parts)


def decompress(compression: str, data: bytes | memoryview, uncompressed_size: int) -> bytes:
    """Decompress chunk data, never producing more than ``uncompressed_size`` + 1 bytes.

    Raises McapFormatError when the declared size is implausible (:func:`check_chunk_size`) or the output
    is not exactly ``uncompressed_size`` bytes.
    """
    check_chunk_size(len(data), uncompressed_size)
    if compression == "":
        out = bytes(data)
    elif compression == "zstd":
        import zstandard

        try:
            out = b""
            if zstandard.frame_content_size(data) == uncompressed_size:  # one frame says its exact size (imulog,
                with contextlib.suppress(zstandard.ZstdError):  # the mcap library): decompress at once
                    out = zstandard.ZstdDecompressor().decompress(data, allow_extra_data=False)
            if len(out) != uncompressed_size:  # several frames, no size in the header, or a lie: bounded reads
                reader = zstandard.ZstdDecompressor().stream_reader(bytes(data), read_across_frames=True)
                out = _read_bounded(reader, uncompressed_size + 1)
        except zstandard.ZstdError as exc:
            raise McapFormatError(f"zstd data does not decompress ({exc})") from None
    elif compression == "lz4":
        import lz4.frame

        try:
            d = lz4.frame.LZ4FrameDecompressor()
            out = d.decompress(bytes(data), max_length=uncompressed_size + 1)
        except (RuntimeError, ValueError, TypeError) as exc:
            raise McapFormatError(f"lz4 data does not decompress ({exc})") from None
        if len(out) <= uncompressed_size and not d.eof:
            raise McapFormatError("lz4 data ends before its frame does (truncated)")
    else:
        raise McapFormatError(f"unsupported chunk compression {compression!r}")
    if len(out) != uncompressed_size:
        more = "more than" if len(out) > uncompressed_size else f"{len(out)}, not"
        raise McapFormatError(f"chunk decompresses to {more} the declared {uncompressed_size} bytes")
    return out


def decompress_chunk(chunk: ChunkRec) -> bytes:
    """Decompress a chunk record and verify its uncompressed CRC (when recorded); McapFormatError if damaged."""
    out = decompress(chunk.compression, chunk.data, chunk.uncompressed_size)
    if chunk.uncompressed_crc != 0 and zlib.crc32(out) != chunk.uncompressed_crc:
        raise McapFormatError("chunk CRC mismatch (damaged data)")
    return out
