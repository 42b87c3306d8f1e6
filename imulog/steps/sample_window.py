"""Consecutive samples of a channel read block by block, addressed by their index in the whole recording.

The core-by-core paths of long recordings (orientation, phases, metrics) each read windows that overlap their
neighbours; this keeps the blocks a window may still need and nothing older (pure bookkeeping, no I/O of its own).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

Arrays = tuple[np.ndarray | None, ...]


class SampleWindow:
    """Samples read so far from ``blocks`` (tuples of per-sample arrays, e.g. ``(t_ns, gyr, acc)``; an array may
    be None in every block), the first kept one at global index ``start``.

    ``get(lo, hi)`` reads further blocks as needed; ``drop_before(i)`` frees the blocks that end before sample
    ``i``; ``take(lo, hi)`` is ``get`` then ``drop_before(lo)`` (windows that only move forward).
    """

    def __init__(self, blocks: Iterator[Arrays], total: int) -> None:
        self.blocks = blocks
        self.total = total
        self.start = 0  # global index of the first kept sample
        self.end = 0  # global index after the last sample read
        self.parts: list[Arrays] = []

    def get(self, lo: int, hi: int) -> Arrays:
        """The arrays of samples ``[lo, hi)``, clipped to the recording (a view when one block holds them)."""
        lo, hi = max(0, lo), min(self.total, hi)
        if lo < self.start:
            raise RuntimeError(f"samples before {self.start} were dropped (asked from {lo})")
        while self.end < hi:
            arrays = next(self.blocks)
            self.parts.append(arrays)
            self.end += len(arrays[0])
        if self.end >= self.total:
            self._drain()
        out: list[np.ndarray | None] = []
        for k in range(len(self.parts[0])):
            if self.parts[0][k] is None:
                out.append(None)
                continue
            pieces, pos = [], self.start
            for part in self.parts:
                n = len(part[0])
                a, b = max(lo, pos), min(hi, pos + n)
                if b > a:
                    pieces.append(part[k][a - pos : b - pos])
                pos += n
            out.append(np.concatenate(pieces) if len(pieces) != 1 else pieces[0])
        return tuple(out)

    def _drain(self) -> None:
        """Read the blocks after the last counted sample: every chunk of the channel is read (and so CRC- and
        size-checked) even when the counted samples end earlier, and samples beyond the count are an error."""
        for arrays in self.blocks:
            if len(arrays[0]):
                raise RuntimeError(f"the channel holds more samples than the {self.total:,} its statistics count")

    def drop_before(self, index: int) -> None:
        """Free every block whose samples all lie before global index ``index``."""
        while self.parts and self.start + len(self.parts[0][0]) <= index:
            self.start += len(self.parts.pop(0)[0])

    def take(self, lo: int, hi: int) -> Arrays:
        window = self.get(lo, hi)
        self.drop_before(lo)
        return window
