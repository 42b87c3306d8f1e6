"""Running statistics of a channel written piece by piece: what a whole-file writer computes at once (count, span,
rate, gaps, NaN samples, content hash), kept in the closing ``imulog.channel_stats`` record."""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Iterable

import numpy as np

from imulog.archive import codec
from imulog.model import Stream

STATS_KEYS = ("sample_count", "start_ns", "end_ns", "rate_hz", "time_gaps", "nan_samples", "sha256")


class ChannelStats:
    """Running statistics of one channel, the same fields :mod:`imulog.archive.codec` computes at once."""

    def __init__(self) -> None:
        self.count = 0
        self.start: int | None = None
        self.end: int | None = None
        self.median_dt: float | None = None
        self.gaps = 0
        self.nan = 0
        self.has_values = False
        self._hash = hashlib.sha256()

    def add_samples(self, t_ns: np.ndarray, values: Iterable[np.ndarray | None]) -> None:
        t = np.asarray(t_ns, dtype=np.int64)
        if not len(t):
            return
        if self.median_dt is None and len(t) > 1:
            self.median_dt = float(np.median(np.diff(t)))
        t_all = np.concatenate([[self.end], t]) if self.end is not None else t
        if self.median_dt and len(t_all) > 1:
            self.gaps += int(np.count_nonzero(np.diff(t_all) > 1.5 * self.median_dt))
        arrays = [v for v in values if v is not None]
        if arrays:
            self.has_values = True
            self.nan += codec.nan_samples(len(t), arrays)
        self.start = int(t[0]) if self.start is None else self.start
        self.end = int(t[-1])
        self.count += len(t)

    def add_payloads(self, payloads: Iterable[bytes]) -> None:
        """Continue the content hash (as :func:`imulog.archive.writer.payload_hash`)."""
        for p in payloads:
            self._hash.update(struct.pack("<Q", len(p)))
            self._hash.update(p)

    @property
    def sha256(self) -> str:
        return self._hash.hexdigest()

    def to_meta(self) -> dict[str, str]:
        out = {"sample_count": str(self.count), "sha256": self.sha256}
        if self.count:
            out["start_ns"], out["end_ns"] = str(self.start), str(self.end)
        if self.count > 1 and self.median_dt:
            out["rate_hz"] = f"{1e9 / self.median_dt:.6g}"
            out["time_gaps"] = str(self.gaps)
        if self.has_values:
            out["nan_samples"] = str(self.nan)
        return out


def _sample_arrays(stream: Stream) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """(times, value arrays) of a piece, for the statistics; intervals count their starts."""
    t = getattr(stream, "t_ns", None)
    if t is None:
        return np.asarray(stream.start_ns), []
    names = ("acc", "gyr", "mag", "temperature", "pos", "values", "position")
    return np.asarray(t), [getattr(stream, n) for n in names if getattr(stream, n, None) is not None]
