"""Running statistics of a channel written piece by piece: what a whole-file writer computes at once (count, span,
rate, gaps, NaN samples, content hash), kept in the closing ``imulog.channel_stats`` record."""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Iterable
from typing import Any

import numpy as np

from imulog.archive import codec
from imulog.model import Stream
from imulog.numeric import add_counts, median_of_counts

#: distinct sample steps counted exactly (as many as 64 k: 1 MiB); beyond, the statistics keep the median so far
MAX_STEPS = 1 << 16
STATS_KEYS = ("sample_count", "start_ns", "end_ns", "rate_hz", "time_gaps", "nan_samples", "sha256")


def final_meta(meta: dict[str, Any]) -> dict[str, str]:
    """The channel metadata of ``channel_info.FINAL_META_KEYS`` for a stream whose ``meta`` is ``meta``, as
    :func:`imulog.archive.codec.encode` writes them."""
    return {"meta": json.dumps(meta, sort_keys=True, default=str), "source": str(meta.get("source", ""))}


class ChannelStats:
    """Running statistics of one channel, the same fields :mod:`imulog.archive.codec` computes at once."""

    def __init__(self) -> None:
        self.count = 0
        self.start: int | None = None
        self.end: int | None = None
        self.steps: dict[int, int] | None = {}  # step (ns) -> count: the median and gaps exactly as codec's
        self.median_dt: float | None = None  # only when the steps were too varied to count (MAX_STEPS)
        self.gaps = 0
        self.nan = 0
        self.has_values = False
        self.intervals = False  # an Intervals channel: count and span only, as codec writes it
        self._hash = hashlib.sha256()

    def add_intervals(self, start_ns: np.ndarray, end_ns: np.ndarray) -> None:
        """Intervals: their count, the earliest start and the latest end."""
        self.intervals = True
        if not len(start_ns):
            return
        lo, hi = int(np.min(start_ns)), int(np.max(end_ns))
        self.start = lo if self.start is None else min(self.start, lo)
        self.end = hi if self.end is None else max(self.end, hi)
        self.count += len(start_ns)

    def add_samples(self, t_ns: np.ndarray, values: Iterable[np.ndarray | None]) -> None:
        t = np.asarray(t_ns, dtype=np.int64)
        if not len(t):
            return
        t_all = np.concatenate([[self.end], t]) if self.end is not None else t
        steps = np.diff(t_all)
        if self.steps is not None:
            add_counts(self.steps, steps)
            if len(self.steps) > MAX_STEPS:  # jittery stamps: the first steps' median, gaps counted from here on
                self.median_dt = median_of_counts(self.steps)
                self.gaps = sum(c for k, c in self.steps.items() if self.median_dt and k > 1.5 * self.median_dt)
                self.steps = None
        elif self.median_dt:
            self.gaps += int(np.count_nonzero(steps > 1.5 * self.median_dt))
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
        if self.count > 1 and not self.intervals:
            median = median_of_counts(self.steps) if self.steps is not None else self.median_dt
            gaps = sum(c for k, c in self.steps.items() if k > 1.5 * median) if self.steps is not None else self.gaps
            out["rate_hz"] = f"{1e9 / median:.6g}" if median and median > 0 else "0"
            out["time_gaps"] = str(gaps) if median and median > 0 else "0"
        if self.has_values:
            out["nan_samples"] = str(self.nan)
        return out


def _sample_arrays(stream: Stream) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """(times, value arrays) of a piece, for the statistics; intervals count their starts."""
    t = getattr(stream, "t_ns", None)
    if t is None:
        return np.asarray(stream.start_ns), []
    names = ("acc", "gyr", "mag", "temperature", "pos", "values", "position", "orientation")
    return np.asarray(t), [getattr(stream, n) for n in names if getattr(stream, n, None) is not None]
