"""The phases step's one implementation: movements, phases and the static mask of a recording of any length,
window by window (docs/architecture.md, "Step windows"). A lab trial is one window and gives what
:func:`imulog.process.segmentation.pipeline.segment_phases` gives on the whole; a week is read in one-hour cores.

Passes over the windows (``margin_s`` of filter context on each side of every core):

1. **norm**: the gyroscope (gaps treated as :func:`imulog.steps.phases_store.prepared` says) low-passed, its norm
   kept (:mod:`imulog.steps.phases_store`), and the summaries of what the method takes from the whole recording:
   the maximum (DynAMoS threshold; Otsu's from a histogram with exact counts), the white noise of the gyroscope and
   accelerometer (the boundary filters' cut-offs: exact on one window, :class:`~imulog.process.segmentation.
   reduce.NoiseHistogram` beyond);
2. **movements and phases** (a reduce: a few integers per movement): the runs above the threshold joined across
   windows, DynAMoS's merge/split with the recording's median duration (linear time), the flank refinement with the
   exact median of the norm below the threshold, then the protocol: event correction into R2G repetitions with
   their confidence (``r2g``) or one phase per movement (``movements``);
3. **gyroscope boundaries** core by core, each phase with the rest before and after it (``context_s`` at most);
4. **hand boundaries, static mask, timing rows**: core by core again; the static mask of a core is yielded once
   every phase that may reach into it is final (one core behind), the intervals at the end.

Methods ``double-threshold`` and ``template`` detect movements on the whole signal at once (a global bias, one
template correlated over the recording): they run on recordings of one window and say so beyond it.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from imulog.model import Intervals, SignalStream
from imulog.process.segmentation.reduce import (
    NoiseHistogram,
    exact_median_below,
    in_range,
    otsu_from_chunks,
    second_differences,
    store_max,
    threshold_runs,
)
from imulog.steps.common import missing_gyroscope
from imulog.steps.phases_record import PeriodCounts, phase_record
from imulog.steps.phases_store import NormFile, NormMemory, Source, prepared
from imulog.steps.windows import Window, plan_windows

INTERVAL_PIECE = 4096  # intervals per written piece: a week's ~50,000 movements are never encoded at once
WHOLE_SIGNAL_METHODS = ("double-threshold", "template")


@dataclass(frozen=True)
class PhaseWindows:
    """Core length, filter margin on each side and the most rest used on each side of a phase, seconds."""

    core_s: float = 3600.0
    margin_s: float = 30.0
    context_s: float = 600.0

    def plan(self, total: int, rate_hz: float) -> list[Window]:
        """The windows over ``total`` samples at ``rate_hz`` (``core_s`` infinite: one window)."""
        if not np.isfinite(self.core_s):
            return [Window(0, 0, total, 0, total)]
        return plan_windows(total, rate_hz, core_s=self.core_s, margin_s=self.margin_s)

    def to_dict(self) -> dict[str, float]:
        return {"core_s": self.core_s, "margin_s": self.margin_s, "context_s": self.context_s}


def unsupported(params: Any, n_windows: int) -> str | None:
    """Why ``params`` cannot segment a recording of ``n_windows`` windows, or None (always None for one)."""
    if n_windows > 1 and params.method in WHOLE_SIGNAL_METHODS:
        return (
            f"method {params.method} detects movements on the whole signal at once and this recording spans "
            f"{n_windows} windows; use --method dynamos (any length)"
        )
    return None


def interval_pieces(
    topic: str, start_ns: np.ndarray, end_ns: np.ndarray, labels: list[str], task_index: np.ndarray | None
) -> Iterator[Intervals]:
    """``Intervals`` of ``topic`` in consecutive pieces of at most :data:`INTERVAL_PIECE` (one, empty, if none)."""
    for k in range(0, max(len(start_ns), 1), INTERVAL_PIECE):
        r = slice(k, k + INTERVAL_PIECE)
        yield Intervals(
            topic, start_ns[r], end_ns[r], labels[r], task_index=None if task_index is None else task_index[r]
        )


class _Reader:
    """Prepared windows of the recording: slices of the whole when it is one window, else read and prepared."""

    def __init__(self, buf, gaps: Any, whole: tuple | None) -> None:
        self.buf, self.gaps, self.whole = buf, gaps, whole

    def get(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
        """(t_ns, gyr, acc, unknown) of samples ``[lo, hi)`` (clipped to the recording)."""
        if self.whole is not None:
            t, g, a, unknown = self.whole
            lo, hi = max(0, lo), min(len(t), hi)
            return t[lo:hi], g[lo:hi], None if a is None else a[lo:hi], unknown[lo:hi]
        t, gyr, acc = self.buf.get(lo, hi)
        g, a, unknown, _ = prepared(gyr, acc, self.gaps)
        return t, g, a, unknown

    def drop_before(self, index: int) -> None:
        if self.whole is None:
            self.buf.drop_before(max(0, index))


def phase_pieces(
    source: Source,
    total: int,
    rate_hz: float,
    imu: str,
    params: Any,
    gaps: Any,
    record: dict[str, Any],
    *,
    windows: PhaseWindows | None = None,
    alignment: dict | None = None,
    start_time: str | None = None,
    temp_dir: str | Path | None = None,
) -> Iterator[Any]:
    """Yield ``/derived/static/{imu}`` core by core, then the movements and phases; fill ``record``
    (``imulog.timing``) at the end. ``params``: a :class:`~imulog.process.segmentation.pipeline.PhaseParams`."""
    from imulog.heap import reuse_heap
    from imulog.process.segmentation.boundaries import adaptive_cutoff_hz, refine_phase_boundaries
    from imulog.process.segmentation.dynamos import lowpass_norm, postprocess, refine_boundaries, threshold_value
    from imulog.process.segmentation.gaps import unphased_movements
    from imulog.process.segmentation.hand import (
        accelerometer_cutoff_hz,
        cutoff_params,
        fill_gaps,
        refine_with_accelerometer,
    )
    from imulog.process.segmentation.pipeline import (
        METHODS,
        PROTOCOLS,
        hand_params,
        movements_as_phases,
        template_movements,
    )
    from imulog.process.segmentation.repetitions import segment_repetitions
    from imulog.process.segmentation.zero_velocity import gyro_norm_static, mask_from_intervals

    c = windows or PhaseWindows()
    p, dp = params, params.dynamos
    if p.method not in METHODS:
        raise ValueError(f"unknown segmentation method {p.method!r}; choose one of {', '.join(METHODS)}")
    if p.protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {p.protocol!r}; choose one of {', '.join(PROTOCOLS)}")
    if p.static not in ("movements", "gyro-norm"):
        raise ValueError(f"unknown static detector {p.static!r}; choose 'movements' or 'gyro-norm'")
    rate = float(rate_hz)
    plan = c.plan(total, rate)
    reason = unsupported(p, len(plan))
    if reason is not None:
        raise ValueError(reason)
    single = len(plan) == 1
    if not single:
        reuse_heap()  # the same temporaries window after window: reuse their pages (imulog.heap)
    over = plan[0].core_lo - plan[0].lo if single else max(w.core_lo - w.lo for w in plan)
    over = max(over, int(round(c.margin_s * rate)))
    ctx = total if single else max(1, int(round(c.context_s * rate)))
    refine = p.boundaries.enabled and (p.method != "dynamos" or dp.refine_boundaries)
    use_hand = refine and p.hand.enabled
    hp = hand_params(p)  # step 9 on the drinking task only
    norm = NormMemory() if single else NormFile(temp_dir)
    try:
        # pass 1: the filtered norm, the white-noise summaries, the gap counts
        gyr_noise, acc_noise = NoiseHistogram(0.5), NoiseHistogram(5.0)
        has_acc, missing, known_any, first_t, last_t = False, 0, False, 0, 0
        whole: tuple | None = None
        report = None
        with source() as buf:
            for w in plan:
                t, gyr, acc = buf.get(w.lo, w.hi)
                if gyr is None:
                    raise missing_gyroscope(f"/imu/{imu}", "phases are found on the angular velocity")
                k0, k1 = w.core_lo - w.lo, w.core_hi - w.lo
                first_t = int(t[0]) if w.index == 0 else first_t
                last_t = int(t[k1 - 1])
                g, a, unknown, report = prepared(gyr, acc, gaps)
                bad = ~np.isfinite(gyr[k0:k1]).all(axis=1)
                if acc is not None:
                    bad |= ~np.isfinite(acc[k0:k1]).all(axis=1)
                missing += int(bad.sum())
                known_any |= bool((~unknown[k0:k1]).any())
                norm.append(lowpass_norm(g, rate, dp.cutoff_hz, dp.filter_order)[k0:k1])
                has_acc |= a is not None
                if single:
                    whole = (np.asarray(t, np.int64), g, a, unknown)
                else:
                    gyr_noise.add(second_differences(g, k0, k1, w.core_lo == 0, w.core_hi == total))
                    if a is not None:
                        acc_noise.add(second_differences(a, k0, k1, w.core_lo == 0, w.core_hi == total))
                buf.drop_before(w.core_hi - over)
        if not known_any:
            raise ValueError(f"/imu/{imu}: no valid run of samples ({missing} of {total} missing)")
        # pass 2 (a reduce over the movements): the method's movements, then the protocol's phases
        post: dict[str, int] = {}
        thr = None
        if p.method == "dynamos":
            if isinstance(dp.threshold, str):
                if dp.threshold.lower() != "otsu":
                    threshold_value(np.zeros(1), dp.threshold)  # raises: names the valid choices
                thr = otsu_from_chunks(norm.chunks)
            else:
                thr = threshold_value(np.array([store_max(norm)]), dp.threshold)
            ms, me = threshold_runs(itertools.chain(norm.chunks(), [(total, np.zeros(0))]), thr)
            if dp.min_movement_s > 0:
                keep = (me - ms) >= dp.min_movement_s * rate
                ms, me = ms[keep], me[keep]
            ms, me = postprocess(ms, me, norm, dp.alpha, dp.beta, dp.max_iterations, stats=post)
            if dp.refine_boundaries and len(ms):
                ms, me = _refine_flanks(ms, me, norm, thr, dp, rate, plan, ctx, total, refine_boundaries)
        elif p.method == "double-threshold":
            from imulog.process.segmentation.double_threshold import double_threshold

            ms, me = double_threshold(whole[1], rate, p.double_threshold)
        else:
            ms, me = template_movements(whole[1], rate, norm.array, p)
        ms, me = np.asarray(ms, np.int64), np.asarray(me, np.int64)
        norm_in = norm.array if single else norm
        ph = segment_repetitions(ms, me, norm_in, rate, p.repetitions) if p.protocol == "r2g" else None
        ph = ph if ph is not None else movements_as_phases(ms, me)
        norm.close()
        if single:
            gyr_cut = adaptive_cutoff_hz(whole[1], rate, p.boundaries)
            acc_cut = accelerometer_cutoff_hz(fill_gaps(whole[2]), rate, p.hand) if whole[2] is not None else None
        else:
            gyr_cut = gyr_noise.cutoff_hz(rate, p.boundaries)
            acc_cut = acc_noise.cutoff_hz(rate, cutoff_params(p.hand)) if has_acc else None
        ps, pe = np.asarray(ph.start, np.int64).copy(), np.asarray(ph.end, np.int64).copy()
        order = np.argsort(ps, kind="stable")
        if not np.array_equal(order, np.arange(len(ps))):
            raise RuntimeError("phases are not in time order")
        cores = [(w.core_lo, w.core_hi) for w in plan]

        def refine_core(rd: _Reader, cs, ce, prev_end, starts, ends, hand: bool):
            sl = in_range(starts, cs, ce)
            if sl.stop <= sl.start:
                return sl, None, None
            nxt = int(starts[sl.stop]) if sl.stop < len(starts) else total
            lo = max(prev_end, int(starts[sl.start]) - ctx)
            hi = min(nxt, int(ends[sl.stop - 1]) + ctx)
            w0, w1 = max(0, lo - over), min(total, hi + over)
            _, g, a, _ = rd.get(w0, w1)
            if hand:
                rs, re_ = refine_with_accelerometer(
                    a,
                    g,
                    rate,
                    starts[sl] - w0,
                    ends[sl] - w0,
                    hp,
                    cutoff_hz=acc_cut,
                    bounds=(lo - w0, hi - w0),
                    movements=(others[0] - w0, others[1] - w0),
                )
            else:
                rs, re_ = refine_phase_boundaries(
                    g, rate, starts[sl] - w0, ends[sl] - w0, p.boundaries, cutoff_hz=gyr_cut, bounds=(lo - w0, hi - w0)
                )
            return sl, rs + w0, re_ + w0

        # pass 3: gyroscope-refined phase boundaries, core by core
        if refine and len(ps):
            gs, ge = ps.copy(), pe.copy()
            with source() as buf:
                rd = _Reader(buf, gaps, whole)
                prev_end = 0
                for cs, ce in cores:
                    sl, a, b = refine_core(rd, cs, ce, prev_end, ps, pe, False)
                    if a is not None:
                        gs[sl], ge[sl] = a, b
                        prev_end = int(ge[sl.stop - 1])
                    rd.drop_before(ce - ctx - over)
            ps, pe = gs, ge
        # pass 4: hand-refined boundaries, the static mask (one core behind), the intervals' times, timing rows
        others = unphased_movements(ms, me, ps, pe)  # motion that is no phase ends a phase's rest (the wave)
        fs, fe = ps.copy(), pe.copy()
        hand_ok = use_hand and has_acc
        last = total - 1
        m_last = np.minimum(np.maximum(me - 1, ms), last)
        t_ms, t_me = np.zeros(len(ms), np.int64), np.zeros(len(ms), np.int64)
        t_fs, t_fe = np.zeros(len(fs), np.int64), np.zeros(len(fs), np.int64)
        peaks = np.zeros(len(fs))
        pad = int(round(p.static_margin_s * rate))
        counts = PeriodCounts(first_t, start_time)
        sums = {"static": 0, "known": 0}

        def static_piece(rd: _Reader, cs: int, ce: int, final_upto: int) -> SignalStream:
            fl_rows = in_range(fs[:final_upto], cs, ce)
            reach = int(fe[fl_rows.stop - 1]) if fl_rows.stop > fl_rows.start else ce
            lo, hi = max(0, cs - over), min(total, max(ce, reach) + over)
            t, g, _, unknown = rd.get(lo, hi)
            core = slice(cs - lo, ce - lo)
            n = ce - cs
            if p.static == "gyro-norm":
                static = gyro_norm_static(g, rate, p.gyro_norm)[core]
            else:
                sl = slice(in_range(me, cs - pad, total + 1).start, in_range(ms, 0, ce + pad).stop)
                static = ~mask_from_intervals(n, ms[sl] - pad - cs, me[sl] + pad - cs)
                if refine and len(fs):
                    fl = slice(in_range(fe, cs - pad, total + 1).start, min(final_upto, in_range(fs, 0, ce + pad).stop))
                    static &= ~mask_from_intervals(n, fs[fl] - pad - cs, fe[fl] + pad - cs)
            for idx, out in ((ms, t_ms), (m_last, t_me)):
                r = in_range(idx, cs, ce)
                out[r] = t[idx[r] - lo]
            f_last = np.minimum(np.maximum(fe[fl_rows] - 1, fs[fl_rows]), last)
            t_fs[fl_rows] = t[fs[fl_rows] - lo]
            t_fe[fl_rows] = t[f_last - lo]
            raw = np.linalg.norm(g, axis=1)
            for i in range(fl_rows.start, fl_rows.stop):
                peaks[i] = raw[fs[i] - lo : int(f_last[i - fl_rows.start]) - lo + 1].max()
            tc, unknown = t[core], unknown[core]
            known = ~unknown
            sums["static"] += int((static & known).sum())
            sums["known"] += int(known.sum())
            counts.add(tc, known, static & known)
            values = np.where(unknown, np.nan, static.astype(np.float64))[:, None]
            return SignalStream(f"/derived/static/{imu}", tc, ["static"], ["1"], values, frame_id=imu)

        with source() as buf:
            rd = _Reader(buf, gaps, whole)
            prev_end = 0
            pending: tuple[int, int] | None = None
            for cs, ce in cores:
                if hand_ok and len(fs):
                    sl, a, b = refine_core(rd, cs, ce, prev_end, ps, pe, True)
                    if a is not None:
                        fs[sl], fe[sl] = a, b
                        prev_end = int(fe[sl.stop - 1])
                done = in_range(ps, 0, ce).stop  # phases final so far
                if pending is not None:
                    yield static_piece(rd, *pending, done)
                    rd.drop_before(min(pending[1] - over, ce - ctx - over))
                pending = (cs, ce)
            if pending is not None:
                yield static_piece(rd, *pending, len(fs))
        t_fs_device = t_fs.copy()  # per-period summaries are on the device clock, like the static mask
        first_iv = first_t
        if alignment is not None:
            from imulog.process.alignment import device_to_reference

            t_ms, t_me, t_fs, t_fe = (
                np.asarray(device_to_reference(x, alignment), dtype=np.int64) for x in (t_ms, t_me, t_fs, t_fe)
            )
            first_iv = int(np.asarray(device_to_reference(np.array([first_t]), alignment), dtype=np.int64)[0])
        yield from interval_pieces(f"/derived/movements/{imu}", t_ms, t_me, ["movement"] * len(ms), None)
        yield from interval_pieces(f"/derived/phases/{imu}", t_fs, t_fe, list(ph.labels), np.asarray(ph.repetition))
    finally:
        norm.close()
    final = replace(ph, start=fs, end=fe)
    record.update(
        phase_record(
            final,
            imu=imu,
            params=p,
            rate_hz=rate,
            aligned=alignment is not None,
            n_movements=len(ms),
            static_fraction=sums["static"] / max(sums["known"], 1),
            t_start=t_fs,
            t_end=t_fe,
            t_first=first_iv,
            peaks=peaks,
            t_start_device=t_fs_device,
            counts=counts,
            span_s=(last_t - first_t) * 1e-9,
            threshold=thr,
            post=post,
            cutoffs=(gyr_cut, acc_cut),
            windows=None if single else c,
        )
    )
    if missing:
        record["gaps"] = report.as_dict() if single else {"missing_samples": missing}


def _refine_flanks(ms, me, norm, thr, dp, rate, plan, ctx, total, refine_boundaries):
    """DynAMoS's flank refinement, movement group by movement group (each core's movements with ``ctx`` of norm
    on each side), with the exact median of the norm below the threshold as the noise level."""
    noise = exact_median_below(norm, thr)
    out_s, out_e = ms.copy(), me.copy()
    prev_end = 0
    for w in plan:
        sl = in_range(ms, w.core_lo, w.core_hi)
        if sl.stop <= sl.start:
            continue
        nxt = int(ms[sl.stop]) if sl.stop < len(ms) else total
        lo = max(prev_end, int(ms[sl.start]) - ctx)
        hi = min(nxt, int(me[sl.stop - 1]) + ctx)
        a, b = refine_boundaries(
            ms[sl] - lo,
            me[sl] - lo,
            norm[lo:hi],
            thr,
            dp.refine_level,
            int(round(dp.continuation_s * rate)),
            dp.continuation_level,
            dp.continuation_peak_fraction,
            noise=noise,
        )
        out_s[sl], out_e[sl] = a + lo, b + lo
        prev_end = int(out_e[sl.stop - 1])
    return out_s, out_e
