"""Protobuf wire format for imulog's block messages, written and scanned without per-sample Python objects.

A packed ``repeated sfixed64`` / ``repeated double`` field is the tag, the byte length and the values as
little-endian 8-byte numbers; a packed ``repeated bool`` is one byte (0 or 1) per value. That is exactly
the layout of a numpy ``<i8`` / ``<f8`` / ``u1`` array, so blocks are written by joining array bytes and
read back with ``numpy.frombuffer`` on views of the payload. The bytes equal what protobuf's own
serializer produces for the same message (fields in number order), which ``tests/test_schemas.py`` checks.
"""

from __future__ import annotations

from typing import Any

import numpy as np

WIRE_VARINT, WIRE_I64, WIRE_LEN, WIRE_I32 = 0, 1, 2, 5


class Fallback(Exception):
    """The fast scan met something it does not handle (e.g. unpacked repeated values): use protobuf."""


def varint(value: int) -> bytes:
    """Unsigned LEB128 varint (protobuf's encoding of a uint32/uint64/bool/enum and of tags and lengths)."""
    out = bytearray()
    value &= (1 << 64) - 1
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def tag(number: int, wire: int) -> bytes:
    return varint(number << 3 | wire)


def len_field(number: int, data: bytes | memoryview) -> bytes:
    """A length-delimited field (bytes, string, packed repeated, sub-message); b"" when empty (proto3)."""
    if not len(data):
        return b""
    return tag(number, WIRE_LEN) + varint(len(data)) + bytes(data)


def packed(number: int, array: np.ndarray | None, dtype: np.dtype) -> bytes:
    """A packed repeated numeric field from a numpy array (row-major), b"" when None or empty."""
    if array is None:
        return b""
    return len_field(number, np.ascontiguousarray(array, dtype=dtype).tobytes())


def uint_field(number: int, value: int) -> bytes:
    return tag(number, WIRE_VARINT) + varint(value) if value else b""


def string_field(number: int, value: str) -> bytes:
    return len_field(number, value.encode("utf-8"))


def read_varint(mv: memoryview, pos: int) -> tuple[int, int]:
    result = shift = 0
    while True:
        b = mv[pos]
        pos += 1
        result |= (b & 0x7F) << shift
        if b < 0x80:
            return result, pos
        shift += 7
        if shift > 63:
            raise Fallback


def scan(payload: bytes | memoryview) -> list[tuple[int, int, Any]]:
    """``(field number, wire type, value)`` for every field: varints as int, length-delimited as views.

    Fixed-width scalar fields (wire types 1 and 5) come back as None (the block schemas have none at top
    level except inside packed arrays). Raises :class:`Fallback` on anything malformed.
    """
    mv = memoryview(payload)
    n = len(mv)
    pos = 0
    out = []
    try:
        while pos < n:
            key, pos = read_varint(mv, pos)
            number, wire = key >> 3, key & 7
            if wire == WIRE_VARINT:
                value, pos = read_varint(mv, pos)
            elif wire == WIRE_LEN:
                length, pos = read_varint(mv, pos)
                end = pos + length
                if end > n:
                    raise Fallback
                value, pos = mv[pos:end], end
            elif wire == WIRE_I64:
                value, pos = None, pos + 8
            elif wire == WIRE_I32:
                value, pos = None, pos + 4
            else:
                raise Fallback
            out.append((number, wire, value))
    except IndexError:
        raise Fallback from None
    if pos != n:
        raise Fallback
    return out
