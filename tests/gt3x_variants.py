"""Build .gt3x variants of the shared ActiGraph sample: the same seconds of accelerometer samples stored as the
older 12-bit record types (ACTIVITY 0x00 in Y,X,Z order, ACTIVITY3 0x1B in X,Y,Z order) instead of ACTIVITY2."""

from __future__ import annotations

import struct
import zipfile
from pathlib import Path

import numpy as np

ACTIVITY, ACTIVITY2, ACTIVITY3 = 0x00, 0x1A, 0x1B


def pack_12bit(values: np.ndarray) -> bytes:
    """Signed 12-bit values, three big-endian nibbles each, packed two nibbles a byte (a last odd nibble is 0)."""
    v = np.asarray(values, dtype=np.int64).ravel() & 0xFFF
    nib = np.column_stack([v >> 8, (v >> 4) & 0xF, v & 0xF]).ravel()
    if len(nib) % 2:
        nib = np.append(nib, 0)
    return ((nib[0::2] << 4) | nib[1::2]).astype(np.uint8).tobytes()


def _record(typ: int, sec: int, payload: bytes) -> bytes:
    head = struct.pack("<BBIH", 0x1E, typ, sec, len(payload))
    x = 0
    for b in head + payload:
        x ^= b
    return head + payload + bytes([~x & 0xFF])


def build_variant(src: Path, out: Path, kind: str) -> Path:
    """``src`` with every ACTIVITY2 record rewritten as ``kind`` (``activity`` or ``activity3``)."""
    typ = {"activity": ACTIVITY, "activity3": ACTIVITY3}[kind]
    with zipfile.ZipFile(src) as z:
        info, log = z.read("info.txt"), z.read("log.bin")
    parts, pos = [], 0
    while pos < len(log):
        if log[pos] != 0x1E:
            parts.append(log[pos : pos + 1])
            pos += 1
            continue
        t, sec, size = struct.unpack_from("<BIH", log, pos + 1)
        payload = log[pos + 8 : pos + 8 + size]
        if t == ACTIVITY2 and size > 1:
            xyz = np.frombuffer(payload, dtype="<i2").reshape(-1, 3).astype(np.int64)
            assert np.abs(xyz).max() < 2048, "12-bit records hold +-2047 counts"
            order = xyz[:, [1, 0, 2]] if typ == ACTIVITY else xyz
            parts.append(_record(typ, sec, pack_12bit(order)))
        else:
            parts.append(log[pos : pos + 9 + size])
        pos += 9 + size
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("info.txt", info)
        z.writestr("log.bin", b"".join(parts))
    return out
