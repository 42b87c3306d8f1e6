"""A uniform device clock fitted to jittery host time stamps, accumulated piece by piece (pure numerics).

The sensor samples at a fixed rate; the host stamps packets on arrival (e.g. Shimmer ``Timestamp_Unix``, 1 ms
resolution), so stamps repeat and jitter. A least-squares line through (sample index, stamp) gives start and
period. The sums behind the line are exact integers, so the fit is the same however the recording is cut into
pieces (one piece: the whole file); memory is one piece.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

_LIMB = 21  # bits per limb of the exact dot product
_BLOCK = 1 << 20  # terms per partial sum: 2**20 terms of |x| < 2**42 stay within int64


def exact_dot(a: np.ndarray, b: np.ndarray) -> int:
    """``sum(a * b)`` as an exact Python int for int64 arrays, ``0 <= a < 2**42`` and any ``b``: both are cut into
    21-bit limbs so that no partial sum overflows int64."""
    mask = np.int64((1 << _LIMB) - 1)
    total = 0
    for s in range(0, len(a), _BLOCK):
        x, y = np.asarray(a[s : s + _BLOCK], np.int64), np.asarray(b[s : s + _BLOCK], np.int64)
        xs = (x & mask, x >> _LIMB)
        ys = (y & mask, (y >> _LIMB) & mask, y >> (2 * _LIMB))  # the top limb keeps the sign (arithmetic shift)
        for p, xp in enumerate(xs):
            for q, yq in enumerate(ys):
                total += int(np.dot(xp, yq)) << (_LIMB * (p + q))
    return total


@dataclass
class HostClockFit:
    """Sums of the least-squares line through (sample index, stamp - first stamp), int64 ns, added piece by piece
    in recording order (:meth:`add`); :meth:`line` and :meth:`times` once every piece was added."""

    n: int = 0
    sum_t: int = 0
    sum_it: int = 0
    t0: int | None = None  # the first stamp, ns
    last: int | None = None  # the previous piece's last stamp relative to t0
    repeats: bool = False  # a stamp not after the one before it (anywhere, piece borders included)

    def add(self, t_ns: np.ndarray) -> None:
        if not len(t_ns):
            return
        if self.t0 is None:
            self.t0 = int(t_ns[0])
        rel = np.asarray(t_ns, np.int64) - np.int64(self.t0)
        if (self.last is not None and rel[0] <= self.last) or bool(np.any(np.diff(rel) <= 0)):
            self.repeats = True
        self.sum_t += exact_dot(np.ones(len(rel), np.int64), rel)
        self.sum_it += exact_dot(np.arange(self.n, self.n + len(rel), dtype=np.int64), rel)
        self.n += len(rel)
        self.last = int(rel[-1])

    @property
    def applies(self) -> bool:
        """True when the stamps need the fit: more than two and some repeat or go back (as before: else as found)."""
        return self.n > 2 and self.repeats

    def line(self) -> tuple[float, float]:
        """(slope ns per sample, intercept ns relative to the first stamp), each the float nearest the exact fit."""
        n = self.n
        sum_i = n * (n - 1) // 2
        sum_ii = (n - 1) * n * (2 * n - 1) // 6
        den = n * sum_ii - sum_i * sum_i
        slope = Fraction(n * self.sum_it - sum_i * self.sum_t, den)
        intercept = Fraction(self.sum_t * sum_ii - sum_i * self.sum_it, den)
        return float(slope), float(intercept)

    def times(self, t_ns: np.ndarray, first_row: int, max_off_ns: float = 1e9) -> tuple[np.ndarray, int | None]:
        """The fitted times (int64 ns) of the piece whose stamps are ``t_ns`` and whose first sample is sample
        ``first_row`` of the recording, and the index in the piece of the first stamp more than ``max_off_ns``
        off the line (None when none is)."""
        slope, intercept = self.line()
        assert self.t0 is not None
        i = np.arange(first_row, first_row + len(t_ns), dtype=np.float64)
        fitted = intercept + slope * i
        rel = (np.asarray(t_ns, np.int64) - np.int64(self.t0)).astype(np.float64)
        off = np.flatnonzero(np.abs(rel - fitted) > max_off_ns)
        return self.t0 + np.round(fitted).astype(np.int64), (int(off[0]) if len(off) else None)
