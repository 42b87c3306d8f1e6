"""XDF chunk structure, checked before anything is parsed: magic, chunk lengths and tags, every Samples chunk's layout
(XDF has no checksums, so damage is named by its chunk index instead of read misaligned)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
from imulog.converters.errors import ConversionError

MAGIC = b"XDF:"
CHUNK_TAGS = {1: "FileHeader", 2: "StreamHeader", 3: "Samples", 4: "ClockOffset", 5: "Boundary", 6: "StreamFooter"}


def _varlen(f, path: Path, index: int, at: int) -> int | None:
    n = f.read(1)
    if not n:
        return None
    size = {1: 1, 4: 4, 8: 8}.get(n[0])
    if size is None:
        raise ConversionError(path, f"chunk {index} (byte {at}): bad chunk length width {n[0]} (damaged chunk header)")
    data = f.read(size)
    if len(data) < size:
        raise ConversionError(path, f"chunk {index} (byte {at}): truncated chunk header")
    return int.from_bytes(data, "little")


def iter_chunk_headers(path: Path) -> Iterator[tuple[int, int, int, int, int]]:
    """(index, byte of the chunk, tag, byte of its content after the tag, content length) of every chunk.

    ConversionError naming the chunk for a missing magic, a bad length or tag, or a chunk cut by the file's end.
    """
    size = path.stat().st_size
    with open(path, "rb") as f:
        if f.read(4) != MAGIC:
            raise ConversionError(path, "not an XDF file (no 'XDF:' magic)")
        index = 0
        while True:
            at = f.tell()
            length = _varlen(f, path, index, at)
            if length is None:
                break
            start = f.tell()
            if length < 2 or start + length > size:
                what = "truncated" if start + length > size and length >= 2 else "bad length"
                raise ConversionError(
                    path, f"chunk {index} (byte {at}): {what} ({length} bytes declared, {size - start} left)"
                )
            tag = int.from_bytes(f.read(2), "little")
            if tag not in CHUNK_TAGS:
                raise ConversionError(
                    path, f"chunk {index} (byte {at}): unknown chunk tag {tag} (damaged chunk header)"
                )
            if index == 0 and tag != 1:
                raise ConversionError(path, "chunk 0 is not the FileHeader")
            yield index, at, tag, start + 2, length - 2
            f.seek(start + length)
            index += 1


def scan_chunks(path: Path) -> dict[str, int]:
    """Walk the chunk headers (lengths and tags, seeking over contents): counts per chunk type."""
    counts: dict[str, int] = {}
    for _, _, tag, _, _ in iter_chunk_headers(path):
        counts[CHUNK_TAGS[tag]] = counts.get(CHUNK_TAGS[tag], 0) + 1
    if not counts:
        raise ConversionError(path, "no chunks after the 'XDF:' magic")
    return counts


VALUE_BYTES = {"int8": 1, "int16": 2, "int32": 4, "int64": 8, "float32": 4, "double64": 8}


def _samples_problem(data: bytes, fmt: str, n_ch: int) -> str | None:
    """Why a Samples chunk's content (after the stream id) does not hold whole samples, or None."""
    mv = memoryview(data)

    def varlen(pos: int) -> tuple[int, int]:
        width = mv[pos] if pos < len(mv) else 0
        if width not in (1, 4, 8) or pos + 1 + width > len(mv):
            raise ValueError(f"bad length field at content byte {pos}")
        return int.from_bytes(mv[pos + 1 : pos + 1 + width], "little"), pos + 1 + width

    try:
        count, pos = varlen(0)
        if fmt != "string":  # fast path: every sample stamped (LabRecorder's usual layout), checked vectorised
            stride = 9 + VALUE_BYTES.get(fmt, 4) * n_ch
            if pos + count * stride == len(mv):
                flags = np.frombuffer(data, dtype=np.uint8)[pos : pos + count * stride : stride]
                if np.all(flags == 8):
                    return None
        for k in range(count):
            if pos >= len(mv) or mv[pos] not in (0, 8):
                return f"sample {k}: bad time stamp flag"
            pos += 1 + mv[pos]
            if fmt == "string":
                for _ in range(n_ch):
                    n, pos = varlen(pos)
                    pos += n
            else:
                pos += VALUE_BYTES.get(fmt, 4) * n_ch
            if pos > len(mv):
                return f"sample {k} of {count} runs past the chunk's end"
    except ValueError as e:
        return str(e)
    return None if pos == len(mv) else f"{len(mv) - pos} bytes left after {count} samples"


def locate_damaged_samples(path: Path) -> None:
    """Raise ConversionError naming the first Samples chunk whose samples do not fit its length (returns if none).

    pyxdf reads past such damage silently (misaligned values) or skips it with a log message, so every file is
    checked; numeric chunks whose samples all carry a time stamp are checked vectorised, others sample by sample.
    """
    import xml.etree.ElementTree as ET

    formats: dict[int, tuple[str, int]] = {}
    with open(path, "rb") as f:
        for index, at, tag, start, length in iter_chunk_headers(path):
            if tag not in (2, 3) or length < 4:
                continue
            f.seek(start)
            content = f.read(length)
            sid = int.from_bytes(content[:4], "little")
            if tag == 2:
                try:
                    root = ET.fromstring(content[4:].decode("utf-8", "replace"))
                    formats[sid] = (
                        root.findtext("channel_format", "float32"),
                        int(root.findtext("channel_count", "1")),
                    )
                except (ET.ParseError, ValueError):
                    raise ConversionError(path, f"chunk {index} (byte {at}): stream header is not valid XML") from None
                continue
            if sid not in formats:
                raise ConversionError(path, f"chunk {index} (byte {at}): samples of stream {sid} before its header")
            problem = _samples_problem(content[4:], *formats[sid])
            if problem:
                raise ConversionError(
                    path, f"chunk {index} (byte {at}): damaged Samples chunk of stream {sid}: {problem}"
                )
