"""ActiGraph log.bin records in bounded batches: separators, headers, checksums (pure, from a byte stream)."""

from __future__ import annotations

import re
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
from imulog.converters.actigraph_format import BATCH_BYTES, SEPARATOR
from imulog.converters.errors import ConversionError


# ---------------------------------------------------------------------------------------------- record reading
@dataclass
class RecordBatch:
    """Complete records found in ``buf``: types, timestamps (s), payload offsets and sizes; ``first`` = index."""

    buf: bytes
    first: int
    byte0: int
    types: np.ndarray
    seconds: np.ndarray
    starts: np.ndarray
    sizes: np.ndarray

    def payload(self, i: int) -> bytes:
        s = int(self.starts[i])
        return self.buf[s : s + int(self.sizes[i])]


_NONZERO = re.compile(rb"[^\x00]")


def iter_record_batches(stream: IO[bytes], path: Path, batch_bytes: int = BATCH_BYTES) -> Iterator[RecordBatch]:
    """Split ``log.bin`` into batches of complete, checksum-verified records with bounded reads."""
    leftover = b""
    index = 0
    byte0 = 0
    eof = False
    while not eof:
        data = stream.read(batch_bytes)
        eof = not data
        buf = leftover + data
        pos = 0
        heads: list[int] = []
        types: list[int] = []
        secs: list[int] = []
        sizes: list[int] = []
        n = len(buf)
        while pos < n:
            b = buf[pos]
            if b != SEPARATOR:
                if b == 0:  # zero padding: skip the whole run at once (a member of zeros is scanned at C speed)
                    m = _NONZERO.search(buf, pos)
                    pos = m.start() if m else n
                    continue
                raise ConversionError(
                    path, f"log.bin record {index + len(heads)} (byte {byte0 + pos}): no record separator (0x{b:02X})"
                )
            if pos + 8 > n:
                break
            typ, sec, size = struct.unpack_from("<BIH", buf, pos + 1)
            if pos + 9 + size > n:
                break
            heads.append(pos)
            types.append(typ)
            secs.append(sec)
            sizes.append(size)
            pos += 9 + size
        if eof and pos < n:
            raise ConversionError(
                path,
                f"log.bin record {index + len(heads)} (byte {byte0 + pos}): truncated ({n - pos} bytes at the end)",
            )
        if heads:
            h = np.asarray(heads, dtype=np.int64)
            arr = np.frombuffer(buf, dtype=np.uint8, count=pos)
            xor = np.bitwise_xor.reduceat(arr, h)  # header ^ payload ^ checksum (^ zero padding) == 0xFF
            bad = np.nonzero(xor != 0xFF)[0]
            if len(bad):
                i = int(bad[0])
                raise ConversionError(
                    path,
                    f"log.bin record {index + i} (byte {byte0 + heads[i]}, type 0x{types[i]:02X}): checksum mismatch "
                    "(the record is damaged)",
                )
            yield RecordBatch(
                buf=buf,
                first=index,
                byte0=byte0,
                types=np.asarray(types, dtype=np.int64),
                seconds=np.asarray(secs, dtype=np.int64),
                starts=h + 8,
                sizes=np.asarray(sizes, dtype=np.int64),
            )
        index += len(heads)
        leftover = buf[pos:]
        byte0 += pos
