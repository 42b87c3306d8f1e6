"""Content hashes of channels (SHA-256 over length-prefixed messages): what the writer records and the reader
checks. Below both, so that neither imports the other for it."""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Iterable

import numpy as np


def payload_hash(payloads: Iterable[bytes | memoryview]) -> str:
    """Content hash of a channel: SHA-256 over its messages (8-byte length + bytes each, in log order)."""
    h = hashlib.sha256()
    for p in payloads:
        h.update(struct.pack("<Q", len(p)))
        h.update(p)
    return h.hexdigest()


HASH_BLOCK_BYTES = 4 << 20  # rows_hash joins about this many bytes of rows at a time


def rows_hash(rows: np.ndarray, mask: np.ndarray | None = None, block: int | None = None) -> str:
    """:func:`payload_hash` of messages held as (N, W) uint8 rows (``mask``: the bytes each uses), with numpy.

    ``block`` rows at a time (default: about :data:`HASH_BLOCK_BYTES` of them, whatever W; a fixed 65,536 rows
    took three copies of a week's 0.1 Hz orientation overview twin, 120 MB, at once: issue 24)."""
    h = hashlib.sha256()
    n, width = rows.shape
    if block is None:
        block = max(1, HASH_BLOCK_BYTES // (8 + width))
    joined = np.empty((min(n, block), 8 + width), dtype=np.uint8)  # each message: 8-byte length, then its bytes
    keep = None if mask is None else np.ones((min(n, block), 8 + width), dtype=bool)
    for i in range(0, n, block):
        part = rows[i : i + block]
        k = len(part)
        lengths = (
            np.full(k, width, dtype="<u8")
            if mask is None
            else np.count_nonzero(mask[i : i + block], axis=1).astype("<u8")
        )
        joined[:k, :8] = lengths.view(np.uint8).reshape(k, 8)
        joined[:k, 8:] = part
        if keep is None:
            h.update(joined[:k])  # hashlib reads the contiguous buffer: no copy to bytes
        else:
            keep[:k, 8:] = mask[i : i + block]
            h.update(joined[:k][keep[:k]])
    return h.hexdigest()
