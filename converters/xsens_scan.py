"""The first pass over an Xsens MT Manager text export read in pieces: what only the whole file tells.

Which time base applies (``SampleTimeFine`` only when every row has it), the median step (the rate when the header
gives none), which columns hold any value (the temperature and the extra signals), how many samples have gaps, and
the first rows with a valid UTC time: all summed piece by piece, so that the first piece already carries the
recording's final channel layout, meta and start time. Nothing here raises: the second pass checks and names bad
rows exactly as the whole-file reader does.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from imulog.numeric import add_counts, median_of_counts

UTC_COLUMNS = ["UTC_Year", "UTC_Month", "UTC_Day", "UTC_Hour", "UTC_Minute", "UTC_Second"]


@dataclass
class _Unwrap:
    """A wrapping counter unwrapped across pieces while it stays valid (as ``xsens.unwrap_counter``)."""

    modulus: int
    ok: bool = True
    prev_raw: int | None = None
    prev: int | None = None

    def add(self, raw: np.ndarray) -> np.ndarray | None:
        """Unwrapped values of the piece, or None once the counter is invalid (the second pass names where)."""
        if not self.ok or not len(raw):
            return None if not self.ok else np.zeros(0, np.int64)
        if not (np.isfinite(raw).all() and ((raw >= 0) & (raw < self.modulus) & (raw == np.round(raw))).all()):
            self.ok = False
            return None
        c = raw.astype(np.int64)
        full = c if self.prev_raw is None else np.concatenate([[self.prev_raw], c])
        d = np.diff(full)
        d = np.where(d < 0, d + self.modulus, d)
        if ((d <= 0) | (d > self.modulus // 2)).any():
            self.ok = False
            return None
        start = int(c[0]) if self.prev is None else self.prev
        out = start + np.concatenate([[0], np.cumsum(d)]) if self.prev is None else start + np.cumsum(d)
        self.prev_raw, self.prev = int(c[-1]), int(out[-1])
        return out


@dataclass
class XsensSummary:
    ncols: int
    seen: dict[str, int]
    rows: int = 0
    stf_finite: bool = True
    any_finite: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    gaps: int = 0
    steps: dict[int, int] = field(default_factory=dict)  # SampleTimeFine step (ns) -> count
    utc_rows: list[tuple[np.ndarray, float, int | None, int | None]] = field(default_factory=list)
    first_ticks: int | None = None
    first_counts: int | None = None

    def median_step_ns(self) -> float | None:
        """``np.median(np.diff(t_ns))`` of the SampleTimeFine times from the step counts (None: fewer than 2)."""
        return median_of_counts(self.steps)


def summarize(pieces: Iterable[np.ndarray], seen: dict[str, int], ncols: int, imu_cols: list[int]) -> XsensSummary:
    """Sum up the pieces' values (each (rows, ncols), in file order)."""
    s = XsensSummary(ncols, seen, any_finite=np.zeros(ncols, bool))
    stf = _Unwrap(2**32) if "SampleTimeFine" in seen else None
    pc = _Unwrap(65536) if "PacketCounter" in seen else None
    for values in pieces:
        s.any_finite |= np.isfinite(values).any(axis=0)
        if imu_cols:
            s.gaps += int((~np.isfinite(values[:, imu_cols])).any(axis=1).sum())
        ticks = counts = None
        if stf is not None:
            raw = values[:, seen["SampleTimeFine"]]
            s.stf_finite &= bool(np.isfinite(raw).all())
            before = stf.prev
            ticks = stf.add(raw) if s.stf_finite else None
            if ticks is not None and len(ticks):
                full = ticks if before is None else np.concatenate([[before], ticks])
                add_counts(s.steps, np.diff(full) * 100_000)
                s.first_ticks = int(ticks[0]) if s.first_ticks is None else s.first_ticks
        if pc is not None:
            counts = pc.add(values[:, seen["PacketCounter"]])
            if counts is not None and len(counts) and s.first_counts is None:
                s.first_counts = int(counts[0])
        if len(s.utc_rows) < 10 and all(c in seen for c in UTC_COLUMNS):
            _utc_candidates(s, values, ticks, counts)
        s.rows += len(values)
    return s


def _utc_candidates(s: XsensSummary, values: np.ndarray, ticks: np.ndarray | None, counts: np.ndarray | None) -> None:
    """Keep the first rows with a complete, valid UTC time (as ``xsens.utc_start`` picks them)."""
    seen = s.seen
    cols = values[:, [seen[c] for c in UTC_COLUMNS]]
    ok = np.isfinite(cols).all(axis=1)
    if "UTC_Valid" in seen:
        flags = values[:, seen["UTC_Valid"]]
        ok &= np.isfinite(flags) & ((np.nan_to_num(flags).astype(np.int64) & 0x04) != 0)
    for i in np.flatnonzero(ok)[: 10 - len(s.utc_rows)]:
        nano = values[i, seen["UTC_Nano"]] if "UTC_Nano" in seen and np.isfinite(values[i, seen["UTC_Nano"]]) else 0
        tick = int(ticks[i]) if ticks is not None else None
        count = int(counts[i]) if counts is not None else None
        s.utc_rows.append((cols[i].copy(), float(nano), tick, count))
