"""Movements and phases of long recordings (a week of wrist data) in bounded memory.

Above :data:`LONG_SAMPLES` the phases step reads the IMU chunk by chunk and runs what
:func:`imulog.steps.phases.compute_phases` does on the whole recording (DynAMoS, one phase per movement for
daily-life trials, the phase-boundary refinements, the static mask), in passes:

1. **norm**: the gyroscope (gaps treated as the whole step does) is low-passed core by core, each core extended by
   ``overlap_s`` on both sides (the zero-phase 1.5 Hz filter's reach is a few seconds), and the filtered norm is
   kept in a temporary file next to the trial (8 bytes per sample, deleted at the end; read back by slices, not
   mapped into memory). The same pass gathers what the whole computation takes from the whole recording: the
   norm's maximum (the DynAMoS threshold) and histograms of the gyroscope's and accelerometer's second differences
   (their white noise sets the boundary filters' cut-offs; from 20000-bin histograms, i.e. to about 0.1 % of the
   exact median, which only moves a cut-off that is not already at its 25 Hz ceiling).
2. **movements**: on the norm file: the runs above the threshold (stitched across chunks), DynAMoS's iterative
   merge/split with the recording's median duration (the movements are a few pairs of integers each; the norm
   inside a movement is read back when it is split), the exact median of the norm below the threshold (static
   noise level) and the flank refinement, movement group by movement group.
3. **gyroscope boundaries**: core by core, the phases that start in the core with the rest before and after them
   (``context_s`` at most on each side) and ``overlap_s`` of filter margin: the refinement's bias and noise come
   from the rest between phases, like the whole computation's, unless that rest is longer than ``context_s``.
4. **hand boundaries, static mask, writing**: core by core again (accelerometer and gyroscope): the hand-following
   refinement, then the static mask of the previous core (a phase of this core can start up to ``max_shift_s``
   earlier, so the mask lags one core) is yielded as a piece; the movement and phase intervals are yielded at the
   end (a few intervals per minute of daily life).

``imulog.timing`` keeps counts and summaries, not a row per phase: phase durations (median, deciles, total) and
their histogram, per hour (and per day beyond a day) the phases, the time moving and the static percentage, the
threshold, the boundary filters' cut-offs and how many merges and splits DynAMoS made (``postprocess_changes``;
``max_iterations`` bounds them, in the whole computation too).

Supported: method ``dynamos`` with protocol ``movements`` (daily life) and ``static="movements"``; other choices
hold the recording and are refused above the threshold with a one-line error.
"""

from __future__ import annotations

import itertools
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from imulog.model import Intervals, SignalStream
from imulog.steps.sample_window import SampleWindow

#: recordings with more IMU samples than this (about 8 h at 100 Hz) get their phases core by core
LONG_SAMPLES = 3_000_000

DURATION_BINS_S = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 20.0, 60.0)


INTERVAL_PIECE = 4096  # intervals per written piece: a week's ~50,000 movements are never encoded at once


def interval_pieces(
    topic: str, start_ns: np.ndarray, end_ns: np.ndarray, task_index: np.ndarray, label: str = "movement"
) -> Iterator[Intervals]:
    """``Intervals`` of ``topic`` in consecutive pieces of at most :data:`INTERVAL_PIECE` (one, empty, if none)."""
    for k in range(0, max(len(start_ns), 1), INTERVAL_PIECE):
        r = slice(k, k + INTERVAL_PIECE)
        yield Intervals(topic, start_ns[r], end_ns[r], [label] * len(start_ns[r]), task_index=task_index[r])


@dataclass(frozen=True)
class PhaseCores:
    """Core length, filter margin on each side and the most rest used on each side of a phase, seconds."""

    core_s: float = 3600.0
    overlap_s: float = 30.0
    context_s: float = 600.0

    def to_dict(self) -> dict[str, float]:
        return {"core_s": self.core_s, "overlap_s": self.overlap_s, "context_s": self.context_s}


def refuse_long(step: str, topic: str, samples: int, hint: str) -> None:
    """Raise a one-line ValueError when ``topic`` has more than :data:`LONG_SAMPLES` samples: ``step`` holds the
    whole trial in memory; ``hint`` says what to do instead."""
    if samples > LONG_SAMPLES:
        raise ValueError(
            f"{step} holds the whole trial in memory and {topic} has {samples:,} samples (more than {LONG_SAMPLES:,}): "
            f"{hint}"
        )


def long_unsupported(params: Any) -> str | None:
    """Why ``params`` (a :class:`~imulog.process.segmentation.pipeline.PhaseParams`) cannot run core by core, or
    None."""
    if params.method != "dynamos":
        return f"method {params.method} needs the whole recording in memory; use --method dynamos"
    if params.protocol != "movements":
        return (
            f"protocol {params.protocol} groups a lab trial's repetitions over the whole recording; "
            "use --protocol movements (one phase per movement) or cut the trial"
        )
    if params.static != "movements":
        return f"static detector {params.static} is not streamed; use --static movements"
    if isinstance(params.dynamos.threshold, str):
        return "the Otsu threshold is not streamed; use a fraction, e.g. --threshold 0.11"
    return None


# ---------------------------------------------------------------------------------------------------- pure parts


class NoiseHistogram:
    """Per-axis histograms of second differences, for :func:`~imulog.process.segmentation.boundaries.
    white_noise_rad_s` of a whole recording added piece by piece (units of the signal).

    Each bin keeps its count and the sum of its values, so a bin holding one distinct value (a quantised sensor:
    bins are far narrower than its resolution) gives that value back: the medians are then exact (to rounding);
    otherwise they are within a bin width (``2 half_range / bins``)."""

    def __init__(self, half_range: float, bins: int = 200_000) -> None:
        self.half = float(half_range)
        self.bins = int(bins)
        self.width = 2 * self.half / self.bins
        self.counts = np.zeros((3, self.bins + 2), dtype=np.int64)  # [below, bins..., above]
        self.sums = np.zeros((3, self.bins + 2))

    def add(self, d2: np.ndarray) -> None:
        """Second differences ``x[i+1] - 2 x[i] + x[i-1]`` (M, 3)."""
        for j in range(3):
            k = np.clip(np.floor((d2[:, j] + self.half) / self.width).astype(np.int64) + 1, 0, self.bins + 1)
            self.counts[j] += np.bincount(k, minlength=self.bins + 2)
            self.sums[j] += np.bincount(k, weights=d2[:, j], minlength=self.bins + 2)

    @staticmethod
    def _median(values: np.ndarray, counts: np.ndarray) -> float:
        """``np.median`` of ``values`` repeated ``counts`` times."""
        keep = counts > 0
        order = np.argsort(values[keep], kind="stable")
        v, w = values[keep][order], counts[keep][order]
        n = int(w.sum())
        if n == 0:
            return 0.0
        cum = np.cumsum(w)
        lo = v[np.searchsorted(cum, (n - 1) // 2 + 1)]
        hi = v[np.searchsorted(cum, n // 2 + 1)]
        return float(0.5 * (lo + hi))

    def white_noise(self) -> float:
        """Per-sample white noise, rms over the axes of 1.4826 x MAD / sqrt 6 (as ``white_noise_rad_s``)."""
        mads = []
        for j in range(3):
            counts = self.counts[j]
            values = self.sums[j] / np.maximum(counts, 1)
            med = self._median(values, counts)
            mads.append(1.4826 * self._median(np.abs(values - med), counts) / np.sqrt(6.0))
        return float(np.sqrt(np.mean(np.square(mads))))

    def cutoff_hz(self, rate_hz: float, params: Any) -> float:
        """:func:`~imulog.process.segmentation.boundaries.adaptive_cutoff_hz` with this recording's noise."""
        if params.target_level_rad_s <= 0 or not params.cutoff_hz:
            return params.cutoff_hz
        noise = self.white_noise()
        if noise <= 0:
            return params.cutoff_hz
        f = (params.target_level_rad_s / (params.n_sigma * noise)) ** 2 * rate_hz / 2
        return float(np.clip(f, params.min_cutoff_hz, params.cutoff_hz))


def second_differences(x: np.ndarray, k0: int, k1: int, first: bool, last: bool) -> np.ndarray:
    """Second differences centred on samples ``k0..k1-1`` of ``x`` (N, 3), leaving out the recording's first and
    last sample (``first``/``last``: ``k0``/``k1 - 1`` is that sample)."""
    a = k0 + (1 if first else 0)
    b = k1 - (1 if last else 0)
    a, b = max(a, 1), min(b, len(x) - 1)
    if b <= a:
        return np.zeros((0, x.shape[1]))
    return x[a + 1 : b + 1] - 2 * x[a:b] + x[a - 1 : b - 1]


def threshold_runs(chunks: Iterator[tuple[int, np.ndarray]], threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Half-open runs where consecutive chunks ``(first index, values)`` exceed ``threshold``, joined across chunks."""
    from imulog.process.segmentation.dynamos import runs

    starts: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    open_start: int | None = None
    for off, x in chunks:
        s, e = runs(x > threshold)
        s, e = s + off, e + off
        if open_start is not None:
            if len(s) and s[0] == off:
                s[0] = open_start
            else:
                starts.append(np.array([open_start]))
                ends.append(np.array([off]))
            open_start = None
        if len(e) and e[-1] == off + len(x):
            open_start = int(s[-1])
            s, e = s[:-1], e[:-1]
        starts.append(s)
        ends.append(e)
    if open_start is not None:
        raise RuntimeError("threshold_runs: the last chunk must close its run (call with a final empty chunk)")
    if not starts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(starts).astype(np.int64), np.concatenate(ends).astype(np.int64)


def in_range(values: np.ndarray, lo: int, hi: int) -> slice:
    """Slice of the sorted ``values`` that lie in ``[lo, hi)``."""
    return slice(int(np.searchsorted(values, lo)), int(np.searchsorted(values, hi)))


def duration_summary(durations_s: np.ndarray) -> dict[str, Any]:
    """Median, deciles, longest and total (s) of phase durations, and their histogram (bin edges in s)."""
    d = np.asarray(durations_s, dtype=float)
    edges = [*DURATION_BINS_S, float("inf")]
    counts = np.histogram(d, bins=np.asarray(edges))[0] if len(d) else np.zeros(len(edges) - 1, np.int64)
    out: dict[str, Any] = {"n": int(len(d)), "total_s": round(float(d.sum()), 3)}
    if len(d):
        p10, p50, p90 = np.percentile(d, [10, 50, 90])
        out.update(median_s=round(float(p50), 4), p10_s=round(float(p10), 4), p90_s=round(float(p90), 4))
        out["max_s"] = round(float(d.max()), 4)
    out["histogram"] = {"bin_edges_s": [*DURATION_BINS_S, None], "counts": [int(c) for c in counts]}
    return out


# ----------------------------------------------------------------------------------------------------- I/O parts


class NormFile:
    """float64 values appended to a temporary file and read back by slices (``os.pread``: nothing is mapped, so the
    file's pages never count as the process's memory)."""

    def __init__(self, directory: str | Path | None = None) -> None:
        self._f = tempfile.TemporaryFile(dir=directory, prefix=".imulog-norm-")  # noqa: SIM115 (closed by close())
        self.n = 0

    def append(self, values: np.ndarray) -> None:
        self._f.write(np.ascontiguousarray(values, dtype="<f8").tobytes())
        self.n += len(values)

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, key: slice) -> np.ndarray:
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise TypeError("NormFile reads contiguous slices only")
        a, b, _ = key.indices(self.n)
        if b <= a:
            return np.zeros(0)
        self._f.flush()
        data = os.pread(self._f.fileno(), 8 * (b - a), 8 * a)
        return np.frombuffer(data, dtype="<f8")

    def chunks(self, size: int = 1 << 20) -> Iterator[tuple[int, np.ndarray]]:
        for a in range(0, self.n, size):
            yield a, self[a : a + size]

    def close(self) -> None:
        self._f.close()


def exact_median_below(norm: NormFile, threshold: float, bins: int = 4096, max_values: int = 200_000) -> float:
    """``np.median(norm[norm < threshold])`` over the file, exactly, in memory bounded by ``max_values``.

    Each pass histograms the values in the current range ``[lo, hi)`` and narrows it to the bins holding the two
    middle ranks, until at most ``max_values`` values remain (or they are all equal: the zeros of a long gap);
    those are sorted."""
    n, lo = 0, np.inf
    for _, x in norm.chunks():
        x = x[x < threshold]
        n += len(x)
        if len(x):
            lo = min(lo, float(x.min()))
    if n == 0:
        return 0.0
    ranks = ((n - 1) // 2, n // 2)
    hi = float(threshold)
    for _ in range(16):
        width = (hi - lo) / bins
        counts = np.zeros(bins, dtype=np.int64)
        below, vmin, vmax = 0, np.inf, -np.inf
        for _, x in norm.chunks():
            x = x[x < threshold]
            below += int(np.count_nonzero(x < lo))
            y = x[(x >= lo) & (x < hi)]
            if len(y):
                vmin, vmax = min(vmin, float(y.min())), max(vmax, float(y.max()))
                k = np.clip(((y - lo) / width).astype(np.int64), 0, bins - 1) if width > 0 else np.zeros(len(y), int)
                counts += np.bincount(k, minlength=bins)
        if vmin == vmax:  # every value left is the same (both middle ranks are in the range)
            return vmin
        if counts.sum() <= max_values or width <= 0:
            break
        cum = below + np.cumsum(counts)
        b1, b2 = (int(np.searchsorted(cum, r + 1)) for r in ranks)
        new_lo, new_hi = lo + b1 * width, min(hi, lo + (b2 + 1) * width)
        if (new_lo, new_hi) == (lo, hi):
            break
        lo, hi = new_lo, new_hi
    picked = []
    for _, x in norm.chunks():
        x = x[x < threshold]
        picked.append(x[(x >= lo) & (x < hi)])
    values = np.sort(np.concatenate(picked))
    return float(0.5 * (values[ranks[0] - below] + values[ranks[1] - below]))


def imu_windows(trial: Any, topic: str, total: int) -> SampleWindow:
    """(t_ns, gyr, acc) of ``topic``'s samples, block by block (:class:`imulog.steps.sample_window.SampleWindow`)."""
    blocks = ((np.asarray(b.t_ns, np.int64), b.gyr, b.acc) for b in trial.iter_blocks(topic))
    return SampleWindow(blocks, total)


def prepared(gyr: np.ndarray, acc: np.ndarray | None, gaps: Any) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """(gyr, acc, unknown) of a window as :func:`imulog.steps.phases.compute_phases` prepares the whole recording:
    short gaps bridged, gyroscope zero and accelerometer interpolated inside long gaps."""
    from imulog.process.gaps import prepare

    (gyr, acc), report = prepare([gyr, acc], gaps)
    unknown = np.ones(len(gyr), dtype=bool)
    for a, b in report.runs:
        unknown[a:b] = False
    if unknown.any():
        gyr = np.where(unknown[:, None], 0.0, gyr)
        if acc is not None and not unknown.all():
            ok = ~unknown
            idx = np.arange(len(acc))
            acc = np.column_stack([np.interp(idx, idx[ok], acc[ok, j]) for j in range(3)])
    return gyr, acc, unknown


def long_phase_pieces(
    path: str | Path,
    topic: str,
    imu: str,
    params: Any,
    gaps: Any,
    total: int,
    rate_hz: float,
    record: dict[str, Any],
    *,
    alignment: dict | None = None,
    start_time: str | None = None,
    cores: PhaseCores | None = None,
) -> Iterator[Any]:
    """Yield ``/derived/static/{imu}`` core by core, then the movements and phases; fill ``record`` at the end."""
    from imulog.archive import TrialReader
    from imulog.heap import bound_heap
    from imulog.process.metrics.periods import DAY_S, HOUR_S, wall_clock_origin_ns
    from imulog.process.segmentation.boundaries import refine_phase_boundaries
    from imulog.process.segmentation.dynamos import lowpass_norm, postprocess, refine_boundaries, threshold_value
    from imulog.process.segmentation.hand import cutoff_params, refine_with_accelerometer
    from imulog.process.segmentation.zero_velocity import mask_from_intervals

    bound_heap()  # the same temporaries core after core: keep them out of the heap (imulog.heap)
    c = cores or PhaseCores()
    p, dp = params, params.dynamos
    rate = float(rate_hz)
    core = max(1, int(round(c.core_s * rate)))
    over = max(1, int(round(c.overlap_s * rate)))
    ctx = max(1, int(round(c.context_s * rate)))
    refine = p.boundaries.enabled and dp.refine_boundaries
    use_hand = refine and p.hand.enabled
    bounds_list = [(a, min(total, a + core)) for a in range(0, total, core)]
    norm = NormFile(Path(path).resolve().parent)
    try:
        # pass 1: the filtered norm to a file, its maximum, the white-noise histograms
        gyr_noise, acc_noise = NoiseHistogram(0.5), NoiseHistogram(5.0)
        has_acc = False
        missing, first_t, last_t = 0, 0, 0
        with TrialReader(path) as trial:
            buf = imu_windows(trial, topic, total)
            for cs, ce in bounds_list:
                lo, hi = max(0, cs - over), min(total, ce + over)
                t, gyr, acc = buf.get(lo, hi)
                if cs == 0:
                    first_t = int(t[0])
                last_t = int(t[ce - lo - 1])
                if gyr is None:
                    raise ValueError(f"/imu/{imu} has no gyroscope columns")
                k0, k1 = cs - lo, ce - lo
                bad = ~np.isfinite(gyr[k0:k1]).all(axis=1)
                if acc is not None:
                    bad |= ~np.isfinite(acc[k0:k1]).all(axis=1)
                missing += int(bad.sum())
                g, a, _ = prepared(gyr, acc, gaps)
                norm.append(lowpass_norm(g, rate, dp.cutoff_hz, dp.filter_order)[k0:k1])
                gyr_noise.add(second_differences(g, k0, k1, cs == 0, ce == total))
                if a is not None:
                    has_acc = True
                    acc_noise.add(second_differences(a, k0, k1, cs == 0, ce == total))
                buf.drop_before(ce - over)
        # pass 2 (on the norm file): DynAMoS with the recording's threshold, median duration and noise level
        vmax = max((float(np.max(x)) for _, x in norm.chunks() if len(x)), default=0.0)
        thr = threshold_value(np.array([vmax]), dp.threshold)
        ms, me = threshold_runs(itertools.chain(norm.chunks(), [(total, np.zeros(0))]), thr)  # chunk by chunk
        if dp.min_movement_s > 0:
            keep = (me - ms) >= dp.min_movement_s * rate
            ms, me = ms[keep], me[keep]
        post: dict[str, int] = {}
        ms, me = postprocess(ms, me, norm, dp.alpha, dp.beta, dp.max_iterations, stats=post)
        if dp.refine_boundaries and len(ms):
            noise = exact_median_below(norm, thr)
            out_s, out_e = ms.copy(), me.copy()
            prev_end = 0
            for cs, ce in bounds_list:
                sl = in_range(ms, cs, ce)
                if sl.stop <= sl.start:
                    continue
                nxt = int(ms[sl.stop]) if sl.stop < len(ms) else total
                lo = max(prev_end, int(ms[sl.start]) - ctx)
                hi = min(nxt, int(me[sl.stop - 1]) + ctx)
                a, b = refine_boundaries(
                    ms[sl] - lo, me[sl] - lo, norm[lo:hi], thr, dp.refine_level,
                    int(round(dp.continuation_s * rate)), dp.continuation_level, dp.continuation_peak_fraction,
                    noise=noise,
                )
                out_s[sl], out_e[sl] = a + lo, b + lo
                prev_end = int(out_e[sl.stop - 1])
            ms, me = out_s, out_e
        norm.close()
        gyr_cut = gyr_noise.cutoff_hz(rate, p.boundaries)
        acc_cut = acc_noise.cutoff_hz(rate, cutoff_params(p.hand)) if has_acc else None
        ps, pe = ms.copy(), me.copy()  # protocol "movements": one phase per movement

        def refine_core(trial_buf: SampleWindow, cs: int, ce: int, prev_end: int, starts, ends, nxt_of, hand: bool):
            sl = in_range(starts, cs, ce)
            if sl.stop <= sl.start:
                return sl, None, None
            nxt = nxt_of(sl.stop)
            lo = max(prev_end, int(starts[sl.start]) - ctx)
            hi = min(nxt, int(ends[sl.stop - 1]) + ctx)
            w0, w1 = max(0, lo - over), min(total, hi + over)
            _, gyr, acc = trial_buf.get(w0, w1)
            g, a, _ = prepared(gyr, acc, gaps)
            if hand:
                rs, re_ = refine_with_accelerometer(
                    a, g, rate, starts[sl] - w0, ends[sl] - w0, p.hand, cutoff_hz=acc_cut, bounds=(lo - w0, hi - w0)
                )
            else:
                rs, re_ = refine_phase_boundaries(
                    g, rate, starts[sl] - w0, ends[sl] - w0, p.boundaries, cutoff_hz=gyr_cut, bounds=(lo - w0, hi - w0)
                )
            return sl, rs + w0, re_ + w0

        # pass 3: gyroscope-refined phase boundaries, core by core
        if refine and len(ps):
            gs, ge = ps.copy(), pe.copy()
            with TrialReader(path) as trial:
                buf = imu_windows(trial, topic, total)
                prev_end = 0
                for cs, ce in bounds_list:
                    sl, a, b = refine_core(
                        buf, cs, ce, prev_end, ps, pe, lambda k: int(ps[k]) if k < len(ps) else total, False
                    )
                    if a is not None:
                        gs[sl], ge[sl] = a, b
                        prev_end = int(ge[sl.stop - 1])
                    buf.drop_before(ce - ctx - over)  # the next window starts at or after this
            ps, pe = gs, ge
        # pass 4: hand-refined boundaries, the static mask (one core behind) and the intervals' times
        fs, fe = ps.copy(), pe.copy()
        last = total - 1
        m_last = np.minimum(np.maximum(me - 1, ms), last)
        t_ms, t_me = np.zeros(len(ms), np.int64), np.zeros(len(ms), np.int64)
        t_fs, t_fe = np.zeros(len(fs), np.int64), np.zeros(len(fs), np.int64)
        pad = int(round(p.static_margin_s * rate))
        static_sum, known_sum = 0, 0
        origins = {
            key: wall_clock_origin_ns(first_t, start_time, period_s)
            for key, period_s in (("by_hour", HOUR_S), ("by_day", DAY_S))
        }
        per: dict[str, dict[str, np.ndarray]] = {k: {} for k in origins}

        def add_period(key: str, period_s: float, index: np.ndarray, weights: np.ndarray, name: str) -> None:
            acc_ = per[key]
            k = np.bincount(index, weights=weights)
            old = acc_.get(name, np.zeros(0))
            if len(k) > len(old):
                old = np.concatenate([old, np.zeros(len(k) - len(old))])
            old[: len(k)] += k
            acc_[name] = old

        def static_piece(trial_buf: SampleWindow, cs: int, ce: int, final_upto: int) -> SignalStream:
            nonlocal static_sum, known_sum
            lo, hi = max(0, cs - over), min(total, ce + over)
            t, gyr, acc = trial_buf.get(lo, hi)
            _, _, unknown = prepared(gyr, acc, gaps)
            t, unknown = t[cs - lo : ce - lo], unknown[cs - lo : ce - lo]
            n = ce - cs
            sl = in_range(me, cs - pad, total + 1)
            sl = slice(sl.start, in_range(ms, 0, ce + pad).stop)
            static = ~mask_from_intervals(n, ms[sl] - pad - cs, me[sl] + pad - cs)
            if refine and len(fs):
                fl = slice(in_range(fe, cs - pad, total + 1).start, min(final_upto, in_range(fs, 0, ce + pad).stop))
                static &= ~mask_from_intervals(n, fs[fl] - pad - cs, fe[fl] + pad - cs)
            for idx, out in ((ms, t_ms), (m_last, t_me)):
                r = in_range(idx, cs, ce)
                out[r] = t[idx[r] - cs]
            f_last = np.minimum(np.maximum(fe[:final_upto] - 1, fs[:final_upto]), last)
            for idx, out in ((fs[:final_upto], t_fs), (f_last, t_fe)):
                r = in_range(idx, cs, ce)
                out[r] = t[idx[r] - cs]
            known = ~unknown
            static_sum += int((static & known).sum())
            known_sum += int(known.sum())
            for key, period_s in (("by_hour", HOUR_S), ("by_day", DAY_S)):
                k = ((t - origins[key][0]) // int(round(period_s * 1e9))).astype(np.int64)
                add_period(key, period_s, k, known.astype(float), "known")
                add_period(key, period_s, k, (static & known).astype(float), "static")
            values = np.where(unknown, np.nan, static.astype(np.float64))[:, None]
            return SignalStream(f"/derived/static/{imu}", t, ["static"], ["1"], values, frame_id=imu)

        with TrialReader(path) as trial:
            buf = imu_windows(trial, topic, total)
            prev_end = 0
            pending: tuple[int, int] | None = None
            for cs, ce in bounds_list:
                if use_hand and len(fs):
                    sl, a, b = refine_core(
                        buf, cs, ce, prev_end, ps, pe, lambda k: int(ps[k]) if k < len(ps) else total, True
                    )
                    if a is not None:
                        fs[sl], fe[sl] = a, b
                        prev_end = int(fe[sl.stop - 1])
                done = in_range(ps, 0, ce).stop  # phases final so far
                if pending is not None:
                    yield static_piece(buf, *pending, done)
                    buf.drop_before(min(pending[1] - over, ce - ctx - over))
                pending = (cs, ce)
            if pending is not None:
                yield static_piece(buf, *pending, len(fs))
        t_fs_device = t_fs.copy()  # per-period summaries are on the device clock, like the static mask
        if alignment is not None:
            from imulog.process.alignment import device_to_reference

            t_ms, t_me, t_fs, t_fe = (
                np.asarray(device_to_reference(a, alignment), dtype=np.int64) for a in (t_ms, t_me, t_fs, t_fe)
            )
        yield from interval_pieces(f"/derived/movements/{imu}", t_ms, t_me, np.full(len(ms), -1, np.int64))
        yield from interval_pieces(f"/derived/phases/{imu}", t_fs, t_fe, np.arange(1, len(fs) + 1))
    finally:
        norm.close()
    durations = (t_fe - t_fs) * 1e-9
    record.update(
        {
            "imu": topic,
            "method": p.method,
            "protocol": p.protocol,
            "clock": "reference" if alignment is not None else "device",
            "rate_hz": round(rate, 4),
            "n_movements": int(len(ms)),
            "n_repetitions": int(len(fs)),
            "n_phases": int(len(fs)),
            "n_corrected_repetitions": 0,
            "n_forced_phases": 0,
            "mean_confidence": None,
            "low_confidence_repetitions": [],
            "repetition_quality": [],
            "static_fraction": round(static_sum / max(known_sum, 1), 4),
            "phase_durations": duration_summary(durations),
            "threshold_rad_s": round(float(thr), 6),
            "postprocess_changes": int(post.get("changes", 0)),
            "cutoff_hz": {
                "gyroscope": round(gyr_cut, 4),
                "accelerometer": None if acc_cut is None else round(acc_cut, 4),
            },
            "computed": f"core by core ({c.core_s:g} s cores, bounded memory); no per-phase rows",
        }
    )
    span_s = (last_t - first_t) * 1e-9
    for key, period_s in (("by_hour", HOUR_S), ("by_day", DAY_S)):
        if key == "by_day" and span_s <= period_s:  # per hour always; per day beyond a day
            continue
        origin_ns, origin_time = origins[key]
        rows = period_rows(
            t_fs_device, durations, per[key]["known"], per[key]["static"], origin_ns, origin_time, period_s, rate,
            first_t,
        )
        record[key] = rows
    if missing:
        record["gaps"] = {"missing_samples": missing}


def period_rows(
    phase_start_ns: np.ndarray,
    durations_s: np.ndarray,
    known: np.ndarray,
    static: np.ndarray,
    origin_ns: int,
    origin_time: Any,
    period_s: float,
    rate_hz: float,
    first_ns: int,
) -> list[dict[str, Any]]:
    """Per period: start (wall clock when known), phases starting in it, their time (s), static percentage of the
    recorded samples and the recorded time (s). ``known``/``static``: sample counts per period."""
    from datetime import timedelta

    period_ns = int(round(period_s * 1e9))
    n = len(known)
    k = ((np.asarray(phase_start_ns, np.int64) - origin_ns) // period_ns).astype(np.int64)
    k = np.clip(k, 0, max(n - 1, 0))
    counts = np.bincount(k, minlength=n)[:n]
    moving = np.bincount(k, weights=durations_s, minlength=n)[:n] if len(k) else np.zeros(n)
    rows = []
    for i in range(n):
        if known[i] == 0:
            continue
        label = "" if origin_time is None else (origin_time + timedelta(seconds=i * period_s)).isoformat()
        rows.append(
            {
                "start": label,
                "start_s": round((origin_ns + i * period_ns - first_ns) * 1e-9, 3),
                "phases": int(counts[i]),
                "moving_s": round(float(moving[i]), 3),
                "static_percent": round(100.0 * float(static[i]) / float(known[i]), 3),
                "recorded_s": round(float(known[i]) / rate_hz, 3),
            }
        )
    return rows
