"""Prototype (issue 31 point 1, thirteenth round): a whole-phase fit with starts near the truth, from the data only.

    python benchmarks/whole_phase_fit.py --conditions stroke-slow --sets 0:0 30:8 --diagnose
    python benchmarks/whole_phase_fit.py --conditions stroke-slow --sets 0:0 30:8 --diagnose --no-rotation

For every phase ``hand (default)`` finds on the simulated trial: the gravity-free acceleration relative to the
still window before the phase (step 2's search, the orientation integrated sample by sample from it, the window's
mean specific force removed), from 1 s before the phase (or the window) to ``--after`` s after it (or 0.1 s before
the next phase), as 20-Hz block means; the phase's submovements (``phase_fit.py``): greedy starts from the velocity's
speed peaks and from one submovement over the present boundaries, each ``k`` = 1..4 refitted to the acceleration with
``c + d t`` and (unless ``--no-rotation``) the wrist's rotation angle since the window as nuisance regressors (a
sensor's scale and misalignment leak gravity in proportion to it), ``k`` and start by BIC; the same fit held to the
present boundaries; the fit's boundaries replace the present ones when the evidence ``n ln(sse_held / sse_free)``
exceeds a margin (``--margins``, dimensionless, one column each). Scored against the simulator's truth as
``segmentation_accuracy.py`` does (durations within 0.1 s). ``--diagnose``: per phase also the model fitted at the
simulator's true submovement times (``boundary_limit.phases_of``), its residual against the rest's white noise, and
the fit started at the truth.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from phase_fit import basis, block_means, decompose, fit_times, held_fit, profile_boundary  # noqa: E402

from imulog.process.segmentation.boundaries import lowpass_axes  # noqa: E402
from imulog.process.segmentation.hand import fill_gaps  # noqa: E402
from imulog.process.segmentation.pipeline import PhaseParams, segment_phases  # noqa: E402
from imulog.process.segmentation.repetitions import RepetitionParams  # noqa: E402
from imulog.process.segmentation.rest_window import still_window  # noqa: E402
from imulog.simulate import simulate  # noqa: E402


def exact_gravity_free(acc, gyr, dt, window, hi):
    """Gravity-free acceleration and velocity from the end of ``window`` to ``hi`` with the orientation integrated
    as a product of each sample's rotation (not the summed rotation vector)."""
    from imulog.process import quaternion as quat

    w0, w1 = window
    f_rest = np.mean(acc[w0:w1], axis=0)
    bias = np.median(gyr[w0:w1], axis=0)
    dq = quat.from_rotation_vector((gyr[w1:hi] - bias) * dt)
    q = np.empty_like(dq)
    cur = np.array([1.0, 0.0, 0.0, 0.0])
    for i in range(len(dq)):
        cur = quat.multiply(cur, dq[i])
        q[i] = cur
    a = quat.rotate(q, acc[w1:hi]) - f_rest
    noise = float(np.sqrt(np.mean((1.4826 * np.median(np.abs(acc[w0:w1] - f_rest), axis=0)) ** 2)))
    return a, np.cumsum(a, axis=0) * dt, noise, np.cumsum((gyr[w1:hi] - bias) * dt, axis=0)


def phase_candidates(acc, gyr, rate, start, end, after_s=3.0, before_s=1.0, true_times=None):
    """Per phase (time order): (fitted onset s, fitted offset s from the present onset, evidence, k, the fit, the fit
    held to the present boundaries, residual rms / block noise) or None (no still window, too short a stretch)."""
    raw = fill_gaps(acc)
    acc_lp = lowpass_axes(raw, rate, 25.0 if rate > 60 else 0.4 * rate)
    gyr_lp = lowpass_axes(fill_gaps(gyr), rate, min(25.0, 0.45 * rate))
    dt = 1.0 / rate
    length = int(round(0.5 * rate))
    guard = int(round(0.1 * rate))
    reach = int(round(1.0 * rate))
    out = []
    for k in range(len(start)):
        a0, b0 = int(start[k]), int(end[k])
        prev_end = int(end[k - 1]) if k > 0 else 0
        next_start = int(start[k + 1]) if k + 1 < len(start) else len(acc)
        pre = still_window(acc_lp, prev_end + guard, a0 - guard, length, reach, True, 2.5)
        if pre is None:
            out.append(None)
            continue
        lo = max(pre[1], a0 - int(round(before_s * rate)))
        hi = min(b0 + int(round(after_s * rate)), next_start - guard)
        if hi - lo < rate:
            out.append(None)
            continue
        a, v, noise, theta = exact_gravity_free(raw, gyr_lp, dt, pre, hi)
        a, v, theta = a[lo - pre[1] :], v[lo - pre[1] :], theta[lo - pre[1] :]
        v = v - v[0]
        t = (np.arange(lo, hi) - a0) * dt
        blk = max(1, int(round(rate / 20.0)))
        t, a, v, theta = block_means(t, blk), block_means(a, blk), block_means(v, blk), block_means(theta, blk)
        extra = theta if ROTATION else None
        if PROJECT:  # along the phase's displacement only (the direction of a fit held to the present boundaries)
            first = held_fit(t, a, v, 0.0, (b0 - a0) * dt, k_max=1, extra=extra)
            d = first.amplitudes_m.sum(axis=0)
            d = d / max(float(np.linalg.norm(d)), 1e-12)
            a, v = a @ d[:, None], v @ d[:, None]
        if SEARCH == "profile":
            D = (b0 - a0) * dt
            held = held_fit(t, a, v, 0.0, D, extra=extra)
            grid = D + np.arange(-0.5, 3.0001, 0.1)
            grid = grid[(grid > 0.3) & (grid < t[-1] - 0.3)]
            sse, fits = profile_boundary(t, a, held, 0.0, grid, extra)
            j = int(np.argmin(sse))
            off = grid[j]
            if 0 < j < len(sse) - 1:  # the parabola's vertex through the three lowest points
                den = sse[j - 1] - 2 * sse[j] + sse[j + 1]
                if den > 0:
                    off += 0.1 * 0.5 * (sse[j - 1] - sse[j + 1]) / den
            ev = held.n * np.log(held.sse / sse[j])
            ratio = np.sqrt(sse[j] / held.n) / (noise / np.sqrt(blk))
            out.append((0.0, off, ev, fits[j].k, fits[j], held, ratio))
            continue
        dec = decompose(t, a, v, extra=extra, present=(0.0, (b0 - a0) * dt))
        if dec is None:
            out.append(None)
            continue
        held = fit_times(
            t, a, dec.onsets_s, dec.durations_s, 2, fixed_onset_s=0.0, fixed_offset_s=(b0 - a0) * dt, extra=extra
        )
        ev = dec.n * np.log(held.sse / dec.sse)
        ratio = np.sqrt(dec.sse / dec.n) / (noise / np.sqrt(blk))
        if true_times is not None and true_times.get(k) is not None:
            on_t, du_t = true_times[k]
            G = np.column_stack(
                [basis(t, on_t, du_t, 2), np.ones_like(t), t - t.mean()] + ([] if extra is None else list(extra.T))
            )
            r = a - G @ np.linalg.lstsq(G, a, rcond=None)[0]
            tr = fit_times(t, a, on_t, du_t, 2, extra=extra)
            DIAG.append(
                (
                    ratio,
                    np.sqrt(np.mean(r**2)) / (noise / np.sqrt(blk)),
                    np.sqrt(tr.sse / tr.n) / (noise / np.sqrt(blk)),
                    (tr.offset_s - tr.onset_s) - ((on_t + du_t).max() - on_t.min()),
                    (dec.offset_s - dec.onset_s) - ((on_t + du_t).max() - on_t.min()),
                    dec.sse,
                    tr.sse,
                )
            )
            print(
                f"    phase {k}: free fit {ratio:.2f}, true times {np.sqrt(np.mean(r**2)) / (noise / np.sqrt(blk)):.2f}, "
                f"refit from true times {np.sqrt(tr.sse / tr.n) / (noise / np.sqrt(blk)):.2f} (on {tr.onset_s - on_t.min():+.3f}, off {tr.offset_s - (on_t + du_t).max():+.3f}); "
                f"evidence free vs held {dec.n * np.log(fit_times(t, a, on_t, du_t, 2, fixed_onset_s=0.0, fixed_offset_s=(b0 - a0) * dt, extra=extra).sse / tr.sse):.1f}"
            )
        out.append((dec.onset_s, dec.offset_s, ev, dec.k, dec, held, ratio))
    return out


VERBOSE = False
TRUE_PLAN = None
DIAG: list = []
ROTATION = True
SEARCH = "greedy"
PROJECT = False


def run(sim, after_s: float):
    """``hand (default)`` on ``sim`` and the fit on each of its phases: per phase (repetition, label, hand onset and
    offset errors s, fit onset and offset errors s, evidence, k), the fit's CPU s, the number of true phases."""
    imu = sim.recording.imus[0]
    t_ref = np.asarray(sim.truth.imu_t_ref_ns, dtype=np.int64) * 1e-9
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) * 1e-9)
    params = replace(PhaseParams(), repetitions=RepetitionParams(n_repetitions=10))
    res = segment_phases(imu.gyr, rate, params, imu.acc)
    ph = res.phases
    order = np.argsort(ph.start)
    c0 = time.process_time()
    true_times = None
    if TRUE_PLAN is not None:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from boundary_limit import phases_of

        tp = {(r, lab): p for r, lab, p in phases_of(TRUE_PLAN)}
        labels_t = np.asarray(sim.truth.phases.labels)
        true_times = {}
        for j, i in enumerate(order):
            key = (int(ph.repetition[i]), str(ph.labels[i]))
            m = np.flatnonzero((sim.truth.phases.task_index == key[0]) & (labels_t == key[1]))
            if key in tp and len(m):
                ta = sim.truth.phases.start_ns[m[0]] * 1e-9
                true_times[j] = (ta - t_ref[ph.start[i]] + tp[key].onsets_s, tp[key].durations_s)
    cands = phase_candidates(imu.acc, imu.gyr, rate, ph.start[order], ph.end[order], after_s, true_times=true_times)
    cpu = time.process_time() - c0
    truth = sim.truth.phases
    labels = np.asarray(truth.labels)
    rows = []
    for j, i in enumerate(order):
        m = np.flatnonzero((truth.task_index == ph.repetition[i]) & (labels == ph.labels[i]))
        if len(m) == 0:
            continue
        ta, tb = truth.start_ns[m[0]] * 1e-9, truth.end_ns[m[0]] * 1e-9
        s0, e0 = t_ref[ph.start[i]], t_ref[max(ph.end[i] - 1, ph.start[i])]
        c = cands[j]
        fit_on = fit_off = np.nan
        ev = np.nan
        k = 0
        if c is not None:
            fit_on, fit_off = s0 + c[0], s0 + c[1]
            ev, k = c[2], c[3]
            if VERBOSE:
                print(
                    f"    phase {j}: residual rms / block noise {c[6]:.2f}, onsets {np.round(c[4].onsets_s, 2)}, "
                    f"durations {np.round(c[4].durations_s, 2)}, hand duration {(ph.end[i] - ph.start[i]) / rate:.2f}"
                )
        rows.append((int(ph.repetition[i]), str(ph.labels[i]), s0 - ta, e0 - tb, fit_on - ta, fit_off - tb, ev, k))
    return rows, cpu, len(truth)


def main() -> None:
    from segmentation_accuracy import _wider

    from imulog.simulate.grid import condition

    ap = argparse.ArgumentParser()
    ap.add_argument("--conditions", nargs="+", default=["stroke-slow"])
    ap.add_argument("--sets", nargs="+", default=["0:0", "30:8"])
    ap.add_argument("--margins", nargs="+", type=float, default=[0, 10, 30, 100, 300])
    ap.add_argument("--after", type=float, default=3.0)
    ap.add_argument("--verbose", action="store_true")
    ap.add_argument("--diagnose", action="store_true")
    ap.add_argument("--no-rotation", action="store_true")
    ap.add_argument("--search", choices=["greedy", "profile"], default="greedy")
    ap.add_argument("--project", action="store_true", help="fit the acceleration along the displacement only")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--subjects", type=int, default=2)
    args = ap.parse_args()
    global VERBOSE
    VERBOSE = args.verbose
    global ROTATION
    ROTATION = not args.no_rotation
    global SEARCH
    SEARCH = args.search
    global PROJECT
    PROJECT = args.project
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    wider = _wider()
    pairs = [
        (int(s) + i, int(b) + j)
        for s, b in (x.split(":") for x in args.sets)
        for i in range(args.seeds)
        for j in range(args.subjects)
    ]
    for cond in args.conditions:
        opts = dict(wider[cond]) if cond in wider else condition(cond)
        per = {m: [] for m in ["hand", "fit", *args.margins]}
        cpus = []
        for seed, subject in pairs:
            sim = simulate("r2g", seed=seed, subject=subject, repetitions=10, **opts)
            if args.diagnose:
                from imulog.simulate.core import motion_plan

                global TRUE_PLAN
                TRUE_PLAN = motion_plan("r2g", seed=seed, subject=subject, repetitions=10, **opts)
            rows, cpu, n_true = run(sim, args.after)
            cpus.append(cpu)
            r = np.array([x[2:] for x in rows], dtype=float)
            hand_ok = np.abs(r[:, 1] - r[:, 0]) < 0.1
            fit_ok = np.abs(r[:, 3] - r[:, 2]) < 0.1
            per["hand"].append(hand_ok.sum() / n_true)
            per["fit"].append(fit_ok.sum() / n_true)
            for mg in args.margins:
                use = np.nan_to_num(r[:, 4], nan=-np.inf) > mg
                ok = np.where(use, fit_ok, hand_ok)
                per[mg].append(ok.sum() / n_true)
            if args.verbose:
                for x in rows:
                    hok = abs(x[3] - x[2]) < 0.1
                    fok = abs(x[5] - x[4]) < 0.1
                    if not (hok and fok):
                        print(
                            f"  {seed}/{subject} r{x[0]} {x[1]}: hand {x[2]:+.3f} {x[3]:+.3f}  fit {x[4]:+.3f} "
                            f"{x[5]:+.3f} ev {x[6]:.1f} k {x[7]}"
                        )
            print(
                f"{cond} {seed}/{subject}: hand {100 * per['hand'][-1]:.1f}, fit {100 * per['fit'][-1]:.1f}, "
                + ", ".join(f"m{mg:g} {100 * per[mg][-1]:.1f}" for mg in args.margins)
                + f"; fit CPU {cpu:.1f} s",
                flush=True,
            )
        for m, v in per.items():
            v = np.array(v)
            print(f"{cond} {m}: {100 * v.mean():.1f} % (worst {100 * v.min():.1f}), {int(np.sum(v < 0.95))} under 95 %")
        print(f"fit CPU per trial {np.mean(cpus):.2f} s")
        if DIAG:
            d = np.array(DIAG)
            print(
                f"{cond} diagnosis over {len(d)} phases: residual rms / block noise (median, 90th percentile): free fit "
                f"{np.median(d[:, 0]):.2f} / {np.percentile(d[:, 0], 90):.2f}, the true times "
                f"{np.median(d[:, 1]):.2f} / {np.percentile(d[:, 1], 90):.2f}, refitted from the true times "
                f"{np.median(d[:, 2]):.2f} / {np.percentile(d[:, 2], 90):.2f}; the refit from the true times keeps "
                f"{int(np.sum(np.abs(d[:, 3]) < 0.1))} of {len(d)} durations within 0.1 s"
            )
            wrong = np.abs(d[:, 4]) >= 0.1
            print(
                f"{cond} the free fit's {int(wrong.sum())} durations outside 0.1 s: {int(np.sum(wrong & (d[:, 5] < d[:, 6])))} "
                f"with a smaller residual than the fit started at the truth (the likelihood prefers them), "
                f"{int(np.sum(wrong & (d[:, 5] >= d[:, 6])))} with a larger one (the search missed the truth's optimum)"
            )


if __name__ == "__main__":
    main()
