"""Where a single damaged byte lies, from a CRC-32 mismatch (zlib's CRC, the one MCAP's data section uses).

CRC-32 is linear: for two byte strings of the same length, ``crc32(a) ^ crc32(b)`` depends only on
``a ^ b``. One damaged byte at position ``p`` of ``n`` (any value ``e`` XORed into it) gives the syndrome
``Z**(n-1-p)(T[e])``, where ``T`` is the CRC table and ``Z`` the CRC state advanced over one zero byte.
``Z`` is invertible, so walking the syndrome back one byte at a time finds the position where it equals a
table entry: that is where the damaged byte is (a wrong match has odds of 255 / 2**32 per byte tried).
Damage spread over more than one byte is not located (``None``).

    syndrome = crc_computed ^ crc_stored
    p = locate_byte_error(syndrome, n, [(start, end), ...])   # the byte ranges the damage may lie in
"""

from __future__ import annotations

from collections.abc import Iterable

_POLY = 0xEDB88320  # zlib's CRC-32, reflected


def _table() -> list[int]:
    out = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ (_POLY if c & 1 else 0)
        out.append(c)
    return out


_T = _table()
_BYTE_SYNDROMES = {t: e for e, t in enumerate(_T) if e}  # syndrome of one damaged byte (last in the string)
_BY_TOP = {t >> 24: i for i, t in enumerate(_T)}  # the top bytes of the table entries are all different


def _back(c: int) -> int:
    """The CRC state one zero byte earlier (the inverse of ``c -> (c >> 8) ^ T[c & 0xFF]``)."""
    i = _BY_TOP[c >> 24]
    return (((c ^ _T[i]) << 8) & 0xFFFFFFFF) | i


def _apply(mat: list[int], v: int) -> int:
    out, j = 0, 0
    while v:
        if v & 1:
            out ^= mat[j]
        v >>= 1
        j += 1
    return out


def _back_power(k: int) -> list[int]:
    """The GF(2) matrix (images of the 32 unit vectors) of going back ``k`` zero bytes."""
    result = [1 << j for j in range(32)]
    base = [_back(1 << j) for j in range(32)]
    while k:
        if k & 1:
            result = [_apply(base, r) for r in result]
        base = [_apply(base, b) for b in base]
        k >>= 1
    return result


def locate_byte_error(
    syndrome: int, length: int, regions: Iterable[tuple[int, int]], limit: int = 64 << 20
) -> int | None:
    """Offset of the one damaged byte of a ``length``-byte string whose CRC differs by ``syndrome``.

    Only offsets inside ``regions`` ([start, end) pairs) are tried, at most ``limit`` bytes of them; None when
    no single byte there explains the syndrome (damage elsewhere, or more than one byte).
    """
    if not syndrome:
        return None
    spans = sorted(((max(0, a), min(length, b)) for a, b in regions if b > a), reverse=True)
    if sum(b - a for a, b in spans) > limit:
        return None
    pos = length  # the state below is the syndrome walked back to just after byte ``pos - 1``
    state = syndrome
    for a, b in spans:
        if b <= 0 or a >= pos:
            continue
        b = min(b, pos)
        state = _apply(_back_power(pos - b), state)
        pos = b
        for p in range(b - 1, a - 1, -1):
            if state in _BYTE_SYNDROMES:
                return p
            state = _back(state)
            pos = p
    return None


def crc_field_damage(syndrome: int) -> bool:
    """True when the syndrome is one damaged byte of the stored CRC value itself (the data are intact)."""
    return any(syndrome == (syndrome & (0xFF << (8 * j))) for j in range(4)) and syndrome != 0


__all__ = ["crc_field_damage", "locate_byte_error"]
