"""Sample times of Axivity ``.cwa`` blocks, by either of the two rules readers use (all times int64 ns on the
device's local clock).

Each data block carries the RTC second it was written in, ``timestampOffset`` (the sample index where that second
applies) and, when the top bit of ``deviceFractional`` is set, 15 bits of fraction of the second (the device then
lowered ``timestampOffset`` by ``fraction * rate``).

- ``"skdh"`` (the default): scikit-digital-health's ``read_axivity.f95`` ``get_time``. A block's own start is
  RTC - timestampOffset / rate (fraction and shim ignored) and its end that plus sampleCount / rate; a block that
  follows its predecessor without a pause starts where the predecessor ends. GGIR's CSV export of GGIRread's AX6
  test recording follows the same rule to 1 ms.
- ``"openmovement"``: OpenMovement's block start (``cwa_load`` ``estimatedFirstSampleTime``, GGIRread's block
  start): RTC + fraction - (timestampOffset + shim) / rate, samples spread from one block start to the next.

Either way a pause (the next block more than two block durations after this one) or a skipped run of damaged
blocks (``breaks``) ends a run: the next block keeps its own start and the samples that would fit between are the
caller's NaN gap (:func:`gaps`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from imulog.converters._binary import NS_PER_S, days_from_civil
from imulog.converters.errors import ConversionError

TIME_RULES = ("skdh", "openmovement")
DEFAULT_TIME_RULE = "skdh"
MAX_GAP_NS = 31 * 86400 * NS_PER_S  # a longer pause is a clock or file problem: refused


def rate_from_code(code: int | np.ndarray) -> float | np.ndarray:
    """Sampling rate in Hz of a CWA rate code: 3200 / 2^(15 - (code & 15))."""
    return 3200.0 / np.left_shift(1, 15 - (np.asarray(code, dtype=np.int64) & 0x0F))


def rtc_to_epoch_s(rtc: np.ndarray) -> np.ndarray:
    """Packed CWA RTC values -> int64 seconds since 1970 of the device's local wall time."""
    v = np.asarray(rtc, dtype=np.int64)
    year = ((v >> 26) & 0x3F) + 2000
    month = (v >> 22) & 0x0F
    day = (v >> 17) & 0x1F
    hour = (v >> 12) & 0x1F
    minute = (v >> 6) & 0x3F
    second = v & 0x3F
    return days_from_civil(year, month, day) * 86400 + hour * 3600 + minute * 60 + second


def block_start_ns(blocks: np.ndarray) -> np.ndarray:
    """OpenMovement's start of each block (its sample 0): RTC + fraction - (timestampOffset + shim) / rate, ns."""
    rate = rate_from_code(blocks["rate_code"])
    frac = blocks["fractional"].astype(np.int64)
    has_frac = (frac & 0x8000) != 0
    frac16 = np.where(has_frac, (frac & 0x7FFF) << 1, 0)  # 1/65536 s
    offset = blocks["offset"].astype(np.int64) + np.where(has_frac, (frac16 * rate.astype(np.int64)) // 65536, 0)
    secs = rtc_to_epoch_s(blocks["rtc"])
    return secs * NS_PER_S + (frac16 * NS_PER_S) // 65536 - np.round(offset * (NS_PER_S / rate)).astype(np.int64)


def skdh_block_start_ns(blocks: np.ndarray) -> np.ndarray:
    """scikit-digital-health's own start of each block: RTC - timestampOffset / rate (no fraction, no shim), ns."""
    rate = rate_from_code(blocks["rate_code"])
    secs = rtc_to_epoch_s(blocks["rtc"])
    return secs * NS_PER_S - np.round(blocks["offset"].astype(np.int64) * (NS_PER_S / rate)).astype(np.int64)


def anchor_ns(blocks: np.ndarray, rule: str) -> np.ndarray:
    """Each block's own start under ``rule`` (before any chaining)."""
    return skdh_block_start_ns(blocks) if rule == "skdh" else block_start_ns(blocks)


def nominal_ns(counts: np.ndarray, rate_hz: np.ndarray) -> np.ndarray:
    """Duration (ns) of ``counts`` samples at the nominal rate."""
    return np.round(np.asarray(counts, dtype=np.int64) * NS_PER_S / rate_hz).astype(np.int64)


@dataclass(frozen=True)
class PreviousBlock:
    """The last intact block of the batch before (for chaining across batches): own start, nominal duration,
    damaged blocks after it."""

    anchor: int
    nominal: int
    break_after: bool


def _pauses(anchors: np.ndarray, nxt: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """A block is followed by a pause when the next block's own start is two block durations or more later."""
    return nxt - anchors >= 2 * nominal


def block_spans(
    rule: str,
    anchors: np.ndarray,
    next_anchor: int | None,
    counts: np.ndarray,
    rate_hz: np.ndarray,
    breaks: np.ndarray | None,
    previous: PreviousBlock | None,
) -> tuple[np.ndarray, np.ndarray]:
    """(first-sample time, duration) of each block in ns under ``rule``; its samples are evenly spread over it."""
    counts = np.maximum(np.asarray(counts, dtype=np.int64), 1)
    nominal = nominal_ns(counts, rate_hz)
    if rule != "skdh":
        return anchors, _om_spans(anchors, next_anchor, counts, rate_hz, breaks)
    brk = np.zeros(len(anchors), dtype=bool) if breaks is None else breaks
    if previous is None:
        prev_anchor, prev_nominal, prev_break = anchors[:1], nominal[:1], np.array([True])
    else:
        prev_anchor = np.array([previous.anchor])
        prev_nominal = np.array([previous.nominal])
        prev_break = np.array([previous.break_after])
    pa = np.concatenate([prev_anchor, anchors[:-1]])
    pn = np.concatenate([prev_nominal, nominal[:-1]])
    pb = np.concatenate([prev_break, brk[:-1]])
    chained = ~pb & ~_pauses(pa, anchors, pn)
    starts = np.where(chained, pa + pn, anchors)
    span = anchors + nominal - starts
    return starts, np.where(span > 0, span, nominal)


def _om_spans(
    starts: np.ndarray, next_start: int | None, counts: np.ndarray, rate_hz: np.ndarray, breaks: np.ndarray | None
) -> np.ndarray:
    """OpenMovement rule: each block's duration (ns) to the next block's start when it follows within twice the
    nominal duration, else nominal; a block before skipped damaged blocks (``breaks``) takes the measured rate of
    the block before it (the device's clock runs off nominal by ~1 %: 14 ms over an AX3 block), nominal when that
    is unknown too."""
    nominal = nominal_ns(counts, rate_hz)
    nxt = np.append(starts[1:], next_start if next_start is not None else starts[-1] + nominal[-1])
    span = nxt - starts
    ok = (span > 0) & (span < 2 * nominal)
    if breaks is not None:
        ok &= ~breaks
    out = np.where(ok, span, nominal)
    if breaks is not None and len(out) > 1:
        measured = np.append(nominal[:1], (span[:-1] * counts[1:]) // counts[:-1])  # previous block's rate
        out = np.where(breaks & np.append(False, ok[:-1]), measured, out)
    return out


def sample_times_ns(starts: np.ndarray, spans: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Per-sample times (N, max count) int64 ns, each block's samples evenly over its span (entries past a
    block's count are meaningless)."""
    counts = np.maximum(np.asarray(counts, dtype=np.int64), 1)
    k = np.arange(int(counts.max()), dtype=np.int64)
    return starts[:, None] + (spans[:, None] * k[None, :]) // counts[:, None]


def gaps(
    path: Path,
    anchors: np.ndarray,
    next_anchor: int | None,
    ends: np.ndarray,
    counts: np.ndarray,
    rate_hz: np.ndarray,
    index: np.ndarray,
    breaks: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the recording paused: (sample positions, first NaN time, NaN count) per block, as ``with_fills`` takes.

    A block followed by the next one two block durations or more later (own starts, ``anchors``) ends a run, as
    does a skipped damaged run after it (``breaks``); the samples that would fit between its end (``ends``) and
    the next block's own start are missing (NaN on the nominal grid).
    """
    counts = np.asarray(counts, dtype=np.int64)
    nominal = nominal_ns(counts, rate_hz)
    has_next = np.ones(len(anchors), dtype=bool)
    nxt = np.append(anchors[1:], next_anchor if next_anchor is not None else 0)
    has_next[-1] = next_anchor is not None
    pause = has_next & _pauses(anchors, nxt, nominal)
    if breaks is not None:  # skipped damaged blocks: a gap whatever its length, after the block's own samples
        pause |= has_next & breaks & (nxt > ends)
    long = np.nonzero(pause & (nxt - ends > MAX_GAP_NS))[0]
    if len(long):
        i = int(long[0])
        raise ConversionError(
            path,
            f"data block {int(index[i]) + 1}: starts {int(nxt[i] - ends[i]) / 86400e9:.0f} days after the previous "
            "block: a device clock or file problem",
        )
    fill_n = np.where(pause, np.ceil((nxt - ends) * rate_hz / NS_PER_S - 1e-9), 0).astype(np.int64)
    return np.cumsum(counts), ends, fill_n
