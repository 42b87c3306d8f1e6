"""Bounded windows over a channel: the one way every step iterates over a trial (docs/architecture.md,
"Step windows").

A window owns the samples ``[core_lo, core_hi)`` of a channel and reads ``[lo, hi)``, its core plus margins for
filters and smoothers. A recording no longer than one core is a single window without margins, so a lab trial is
computed exactly as a whole. Pure bookkeeping: no I/O, no numerics.

    for w in plan_windows(total=n, rate_hz=100.0, core_s=3600.0, margin_s=60.0):
        arrays = samples.take(w.lo, w.hi)          # imulog.steps.sample_window.SampleWindow
        out = compute(arrays)                      # the step's one implementation
        yield w.core(out)                          # the rows this window owns
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

T = TypeVar("T")


@dataclass(frozen=True)
class Window:
    """One window of a channel, in sample indices of the whole channel.

    ``[lo, hi)`` is read; ``[core_lo, core_hi)`` is owned (its outputs are written by this window alone).
    """

    index: int
    lo: int
    hi: int
    core_lo: int
    core_hi: int

    def __post_init__(self) -> None:
        if not (0 <= self.lo <= self.core_lo <= self.core_hi <= self.hi):
            raise ValueError(f"window {self.index}: need lo <= core_lo <= core_hi <= hi, got {self}")

    @property
    def core_slice(self) -> slice:
        """The owned samples as a slice of the read arrays (``arrays[w.core_slice]``)."""
        return slice(self.core_lo - self.lo, self.core_hi - self.lo)

    def core(self, array: np.ndarray) -> np.ndarray:
        """The owned rows of an array computed on the read samples (``len(array) == hi - lo``)."""
        if len(array) != self.hi - self.lo:
            raise ValueError(f"window {self.index}: array has {len(array)} rows, the window read {self.hi - self.lo}")
        return array[self.core_slice]


def plan_windows(total: int, rate_hz: float, *, core_s: float = 3600.0, margin_s: float = 60.0) -> list[Window]:
    """Consecutive windows covering ``total`` samples at ``rate_hz``: cores of ``core_s`` seconds, each read with
    ``margin_s`` seconds more on both sides (clipped to the recording). ``total`` within one core: one window,
    no margins. Raises ValueError for a non-positive rate or core."""
    if total < 0:
        raise ValueError(f"total must be >= 0 samples, got {total}")
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise ValueError(f"rate must be a positive number of Hz, got {rate_hz}")
    if not core_s > 0 or margin_s < 0:
        raise ValueError(f"need core_s > 0 and margin_s >= 0, got {core_s} and {margin_s}")
    core = max(1, int(round(core_s * rate_hz)))
    margin = int(round(margin_s * rate_hz))
    if total <= core:
        return [Window(0, 0, total, 0, total)]
    windows = []
    for k, start in enumerate(range(0, total, core)):
        end = min(total, start + core)
        windows.append(Window(k, max(0, start - margin), min(total, end + margin), start, end))
    return windows


@dataclass(frozen=True)
class WindowParams:
    """Core length and margin on each side, seconds, of the windows a step reads (:func:`plan_windows`)."""

    core_s: float = 3600.0
    margin_s: float = 60.0

    def plan(self, total: int, rate_hz: float) -> list[Window]:
        """The windows over ``total`` samples at ``rate_hz`` (one window when the recording fits one core)."""
        return plan_windows(total, rate_hz, core_s=self.core_s, margin_s=self.margin_s)

    def to_dict(self) -> dict[str, float]:
        return {"core_s": self.core_s, "margin_s": self.margin_s}


def channel_rate_hz(sample_count: int, start_ns: int | None, end_ns: int | None, rate_hz: float | None) -> float:
    """A channel's mean rate (Hz) from its summary (samples over span), for planning windows before reading it;
    the recorded ``rate_hz`` when the span is unknown, else 100 Hz (planning only: no result depends on it when
    the recording is one window)."""
    if start_ns is not None and end_ns is not None and end_ns > start_ns and sample_count > 1:
        return (sample_count - 1) / ((end_ns - start_ns) * 1e-9)
    return float(rate_hz) if rate_hz and rate_hz > 0 else 100.0


@dataclass(frozen=True)
class EventWindow:
    """A stretch between two rests for methods that reset at rests (trajectory): samples ``[lo, hi)``, the rest
    before ending at ``move_lo`` and the one after starting at ``move_hi``; ``split`` when the stretch was longer
    than the longest allowed and cut without a rest (dead reckoning cannot bound its drift)."""

    index: int
    lo: int
    move_lo: int
    move_hi: int
    hi: int
    split: bool = False


def event_windows(
    rests: Sequence[tuple[int, int]], total: int, rate_hz: float, *, max_s: float = 600.0
) -> list[EventWindow]:
    """One window per movement between consecutive rests (``rests``: sorted, non-overlapping ``(start, end)``
    sample intervals), each holding the rest before and after it; a movement longer than ``max_s`` seconds is cut
    into pieces of at most ``max_s`` marked ``split``. Stretches before the first and after the last rest have
    only one rest and are included (they are what a user will ask about)."""
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise ValueError(f"rate must be a positive number of Hz, got {rate_hz}")
    longest = max(1, int(round(max_s * rate_hz)))
    bounds = [(0, 0), *[(int(a), int(b)) for a, b in rests], (total, total)]
    out: list[EventWindow] = []
    for (r0a, r0b), (r1a, r1b) in zip(bounds[:-1], bounds[1:], strict=True):
        if r1a < r0b:
            raise ValueError(f"rests overlap or are not sorted near sample {r1a}")
        if r1a == r0b:
            continue  # two touching rests: no movement between them
        cuts = list(range(r0b, r1a, longest)) + [r1a]
        split = len(cuts) > 2
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            lo = r0a if a == r0b else a
            hi = r1b if b == r1a else b
            out.append(EventWindow(len(out), lo, a, b, hi, split))
    return out


def owned(windows: Sequence[Window], items: Sequence[T], starts: Sequence[int]) -> Iterator[tuple[Window, list[T]]]:
    """Each window with the items whose start sample lies in its core (intervals are emitted by the window that
    holds their start, so none is written twice)."""
    order = np.argsort(np.asarray(starts, dtype=np.int64), kind="stable")
    k = 0
    for w in windows:
        mine: list[T] = []
        while k < len(order) and starts[order[k]] < w.core_hi:
            if starts[order[k]] >= w.core_lo:
                mine.append(items[order[k]])
            k += 1
        yield w, mine


@dataclass(frozen=True)
class RestWindow(Window):
    """A window of consecutive movements between rests (:func:`rest_windows`): ``[lo, hi)`` read, from the start of
    the rest before its first movement to the end of the rest after its last; ``[core_lo, core_hi)`` owned, from
    the middle of the rest it shares with the previous window to the middle of the next; ``split``: it holds a
    stretch longer than ``max_s`` that was cut without a rest."""

    split: bool = False
    rest_only: bool = False  # the middle of a long rest (``context_s``): no movement in it


def rest_windows(
    rests: Sequence[tuple[int, int]],
    total: int,
    rate_hz: float,
    *,
    core_s: float = 3600.0,
    max_s: float = 600.0,
    keep_together: Sequence[tuple[int, int]] = (),
    context_s: float | None = None,
) -> list[RestWindow]:
    """The movements between rests (:func:`event_windows`) grouped into windows of at most ``core_s`` seconds,
    cut only at a rest (or where a stretch longer than ``max_s`` was split, flagged) and never inside a span of
    ``keep_together`` (sample intervals, e.g. a repetition's phases). A recording within one core is one window
    (nothing split). A stretch of movements longer than ``core_s`` without an allowed cut stays one window.

    ``context_s``: at most this much of a rest is read beside a movement; the middle of a longer rest between two
    windows (a night) becomes windows of its own of at most ``max_s`` (and ``core_s``), rest only, so a window's memory does not
    grow with the longest rest of the recording."""
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise ValueError(f"rate must be a positive number of Hz, got {rate_hz}")
    core = max(1, int(round(core_s * rate_hz)))
    if total <= core:
        return [RestWindow(0, 0, total, 0, total)]
    units = event_windows(rests, total, rate_hz, max_s=max_s)
    if not units:
        return [RestWindow(0, 0, total, 0, total)]
    spans = sorted((int(a), int(b)) for a, b in keep_together)
    span_lo = np.array([a for a, _ in spans], dtype=np.int64)
    span_hi = np.array([b for _, b in spans], dtype=np.int64)

    def allowed(cut_lo: int, cut_hi: int) -> bool:
        """No kept-together span holds the whole cut ``[cut_lo, cut_hi]`` (a rest, or one split point)."""
        k = int(np.searchsorted(span_lo, cut_lo, side="right"))  # spans starting at or before the cut
        return not (k and (span_hi[:k] > cut_hi).any())

    groups: list[list[EventWindow]] = [[units[0]]]
    for u in units[1:]:
        g = groups[-1]
        prev = g[-1]
        if u.hi - g[0].lo > core and allowed(prev.move_hi, u.move_lo):
            groups.append([u])
        else:
            g.append(u)
    out: list[RestWindow] = []
    for k, g in enumerate(groups):
        own_lo = 0 if k == 0 else (groups[k - 1][-1].move_hi + g[0].move_lo) // 2
        own_hi = total if k == len(groups) - 1 else (g[-1].move_hi + groups[k + 1][0].move_lo) // 2
        lo, hi = min(g[0].lo, own_lo), max(g[-1].hi, own_hi)
        out.append(RestWindow(k, lo, hi, own_lo, own_hi, any(u.split for u in g)))
    if context_s is None:
        return out
    return _cap_rests(
        out, groups, min(core, max(1, int(round(max_s * rate_hz)))), max(1, int(round(context_s * rate_hz)))
    )


def _cap_rests(out: list[RestWindow], groups: list[list[EventWindow]], core: int, ctx: int) -> list[RestWindow]:
    """``out`` with every rest longer than ``2 * ctx`` samples between two windows read only ``ctx`` into by
    each, the samples between owned by rest-only windows of at most ``core`` samples."""
    capped: list[RestWindow] = []
    for k, w in enumerate(out):
        g = groups[k]
        lo, own_lo = w.lo, w.core_lo
        before = groups[k - 1][-1].move_hi + ctx if k else 0  # the recording's start: a rest before it too
        if g[0].move_lo - before > ctx:
            lo = own_lo = g[0].move_lo - ctx
            a = before
            for b in range(a, own_lo, core):
                e = min(b + core, own_lo)
                capped.append(RestWindow(0, b, e, b, e, False, True))
        hi, own_hi = w.hi, w.core_hi
        after = groups[k + 1][0].move_lo - ctx if k + 1 < len(out) else w.core_hi  # core_hi: the total
        if after - g[-1].move_hi > ctx:
            hi = own_hi = g[-1].move_hi + ctx
        capped.append(RestWindow(0, min(lo, own_lo), max(hi, own_hi), own_lo, own_hi, w.split))
        if k + 1 == len(out):
            capped += [
                RestWindow(0, b, min(b + core, after), b, min(b + core, after), False, True)
                for b in range(hi, after, core)
            ]
    return [RestWindow(i, c.lo, c.hi, c.core_lo, c.core_hi, c.split, c.rest_only) for i, c in enumerate(capped)]
