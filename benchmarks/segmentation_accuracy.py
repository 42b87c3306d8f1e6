"""Segmentation accuracy on simulated R2G trials (25 repetitions x 4 phases) against the simulator's truth.

    python benchmarks/segmentation_accuracy.py                 # 4 seeds x 2 subjects, all methods
    python benchmarks/segmentation_accuracy.py --seeds 10 --subjects 3 --methods dynamos

Two scenarios: corrective sub-movements (``extra_submovement_probability``) with residual static velocity
(``residual_velocity_mps``), and the simulator's defaults. A detected phase is correct when it has the true
phase's repetition and label and overlaps it with intersection-over-union > 0.5; onset/offset errors are over
correct phases, on the reference clock. Phase durations are paired with the truth by (repetition, label)
over all true phases (issue 9: within 0.1 s). Also prints the segmentation time per trial against the
baseline (gyro-norm detector) run in the same process.

    python benchmarks/segmentation_accuracy.py --first-seed 40 --first-subject 20 --seeds 6 --subjects 3

Accuracy grid (issue 19): every condition of :mod:`imulog.simulate.grid` (rotation ending before the hand stops,
curved paths, placements, pauses, stroke-like submovements, uncalibrated sensors, clock drift, other rates),
one table row per condition and method, over ``--seeds`` x ``--subjects`` trials of ``--repetitions``:

    python benchmarks/segmentation_accuracy.py --grid all --seeds 3 --subjects 1 --repetitions 10

``--grid wider``: slower, more hesitant and slow curved stroke-like phases beyond the simulator's grid (issue 31).
``--grid devices``: ``default``, ``stroke`` and ``stroke-slow`` at the median real device's sensor noise.
``--outside`` lists every phase whose duration is outside 0.1 s with its onset and offset errors, and counts them
per condition by what is wrong (missing, offsets early or late, onsets early or late, both ends within 0.1 s).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from imulog.process.segmentation.boundaries import BoundaryParams
from imulog.process.segmentation.dynamos import DynamosParams
from imulog.process.segmentation.hand import HandParams
from imulog.process.segmentation.pipeline import METHODS, PhaseParams, segment_phases
from imulog.process.segmentation.zero_velocity import gyro_norm_static
from imulog.simulate import simulate


def score(sim, params: PhaseParams) -> dict:
    """Phase count, fraction correctly identified and onset/offset errors (s) of one simulated trial."""
    imu = sim.recording.imus[0]
    t_ref = np.asarray(sim.truth.imu_t_ref_ns, dtype=np.int64)
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) * 1e-9)
    result = segment_phases(imu.gyr, rate, params, imu.acc)
    ph, truth = result.phases, sim.truth.phases
    det_s = t_ref[ph.start] * 1e-9
    det_e = t_ref[np.maximum(ph.end - 1, ph.start)] * 1e-9
    labels = np.asarray(truth.labels)
    correct, onset, offset = 0, [], []
    for i in range(len(ph)):
        m = np.flatnonzero((truth.task_index == ph.repetition[i]) & (labels == ph.labels[i]))
        if len(m) == 0:
            continue
        a, b = truth.start_ns[m[0]] * 1e-9, truth.end_ns[m[0]] * 1e-9
        inter = max(0.0, min(b, det_e[i]) - max(a, det_s[i]))
        union = max(b, det_e[i]) - min(a, det_s[i])
        if union > 0 and inter / union > 0.5:
            correct += 1
            onset.append(det_s[i] - a)
            offset.append(det_e[i] - b)
    errors = np.abs(np.r_[onset, offset])
    # phase durations (s) paired with the truth by (repetition, label), as clinicians read them; a true phase
    # without a detected partner counts as outside the tolerance
    det = {(int(r), lab): e - s for r, lab, s, e in zip(ph.repetition, ph.labels, det_s, det_e, strict=True)}
    dur_err = np.array(
        [
            det[(int(r), lab)] - (b - a) * 1e-9 if (int(r), lab) in det else np.inf
            for r, lab, a, b in zip(truth.task_index, truth.labels, truth.start_ns, truth.end_ns, strict=True)
        ]
    )
    ends = {(int(r), lab): (s, e) for r, lab, s, e in zip(ph.repetition, ph.labels, det_s, det_e, strict=True)}
    outside = [  # (repetition, label, onset error s, offset error s) of the durations outside 0.1 s (nan: missing)
        (
            int(r),
            str(lab),
            *(np.subtract(ends[(int(r), lab)], (a * 1e-9, b * 1e-9)) if (int(r), lab) in ends else (np.nan,) * 2),
        )
        for r, lab, a, b, d in zip(truth.task_index, truth.labels, truth.start_ns, truth.end_ns, dur_err, strict=True)
        if not abs(d) < 0.1
    ]
    return {
        "outside": [(r, lab, float(on), float(off)) for r, lab, on, off in outside],
        # every true phase's (repetition, label, onset error s, offset error s) where one was detected
        "ends": [(r, lab, float(s - a * 1e-9), float(e - b * 1e-9)) for (r, lab), (s, e), a, b in _paired(ends, truth)],
        "n_phases": len(ph),
        "n_true": len(truth),
        "correct": correct / len(truth),
        "mae_s": float(errors.mean()) if len(errors) else float("nan"),
        "onset_mae_s": float(np.mean(np.abs(onset))) if onset else float("nan"),
        "offset_mae_s": float(np.mean(np.abs(offset))) if offset else float("nan"),
        "duration_within_0_1_s": float(np.mean(np.abs(dur_err) < 0.1)),
        "max_duration_error_s": float(np.max(np.abs(dur_err))),
        "mean_duration_error_s": float(np.mean(dur_err[np.isfinite(dur_err)])),
        "n_corrected": ph.n_corrected,
        "n_movements": len(result.movement_start),
    }


def _paired(ends: dict, truth) -> list:
    """((repetition, label), (detected start, end) s, true start ns, true end ns) of the true phases detected."""
    return [
        ((int(r), str(lab)), ends[(int(r), lab)], a, b)
        for r, lab, a, b in zip(truth.task_index, truth.labels, truth.start_ns, truth.end_ns, strict=True)
        if (int(r), lab) in ends
    ]


SIM_OPTIONS = {"extra_submovement_probability": 0.2, "residual_velocity_mps": 0.01}
SCENARIOS = {
    "sub-movements + residual velocity": SIM_OPTIONS,
    "default noise": {},
}


def table(trials, methods, variants) -> None:
    """Print one markdown table row per method over ``trials``."""
    print(
        "| method | trials with 100 phases | correct phases % (min) | onset MAE s | offset MAE s | MAE s (max) "
        "| durations within 0.1 s % (min) | max duration error s | s/trial |"
    )
    print("|" + "---|" * 9)
    for name in methods:
        t0 = time.perf_counter()
        rows = [score(sim, variants[name]) for _, sim in trials]
        per_trial = (time.perf_counter() - t0) / len(trials)
        exact = sum(r["n_phases"] == r["n_true"] for r in rows)
        correct = [100 * r["correct"] for r in rows]
        mae = [r["mae_s"] for r in rows]
        within = [100 * r["duration_within_0_1_s"] for r in rows]
        print(
            f"| {name} | {exact}/{len(rows)} | {np.mean(correct):.1f} ({np.min(correct):.0f}) | "
            f"{np.nanmean([r['onset_mae_s'] for r in rows]):.3f} | {np.nanmean([r['offset_mae_s'] for r in rows]):.3f} | "
            f"{np.nanmean(mae):.3f} ({np.nanmax(mae):.3f}) | {np.mean(within):.1f} ({np.min(within):.0f}) | "
            f"{np.max([r['max_duration_error_s'] for r in rows]):.3f} | {per_trial:.2f} |"
        )


GRID_METHODS = {
    "hand (default)": PhaseParams(),
    "hand without step 9": PhaseParams(hand=HandParams(profile_rest_s=0.0)),  # the default until issue 31's 7th round
    "hand + gyroscope floor (step 10)": PhaseParams(hand=HandParams(gyro_floor=True)),  # issue 31's 9th round, off
    "hand, step 9 tied to step 2's window": PhaseParams(hand=HandParams(profile_alone=False)),  # before issue 31's 10th
    "hand + both flanks (step 7)": PhaseParams(hand=HandParams(flank_combine=True)),  # issue 31's 11th round, off
    "hand + the rests' own drift (step 8)": PhaseParams(hand=HandParams(rest_drift=True)),  # issue 31's 11th round
    "hand + a slow last part inside the offset (step 8)": PhaseParams(hand=HandParams(slow_inside=True)),  # 12th round
    "hand + step 2's gap ended by movements (gaps.py)": PhaseParams(hand=HandParams(movement_gaps=True)),  # 12th, off
    "hand, onset walk at fixed speeds (step 5)": PhaseParams(hand=HandParams(walk_noise=False)),  # before 12th round
    "hand + the rest's level in the flank fit (step 7)": PhaseParams(hand=HandParams(flank_rest_level=True)),  # 13th
    "hand + both flanks with the rest's level (step 7)": PhaseParams(
        hand=HandParams(flank_combine=True, flank_rest_level=True)
    ),  # issue 31's 13th round, off
    "hand + the low-passed noise's correlation in the flank fit (step 7)": PhaseParams(
        hand=HandParams(flank_noise=True)
    ),  # issue 31's 14th round, off
    "hand + the rest's level and the noise's correlation in the flank fit (step 7)": PhaseParams(
        hand=HandParams(flank_noise=True, flank_rest_level=True)
    ),  # issue 31's 14th round, off
    "gyroscope only": PhaseParams(hand=HandParams(enabled=False)),
    "published (--no-refine)": PhaseParams(
        dynamos=DynamosParams(refine_boundaries=False), boundaries=BoundaryParams(enabled=False)
    ),
}


def _wider() -> dict[str, dict]:
    """Conditions beyond the simulator's grid (issue 31: "widen the grid to what makes today's method fail"):
    stroke-like phases slower (``slowness`` 2.5, the top of the 1.5-2.5 the simulator documents for stroke
    survivors), more hesitant (a pause in 60 % of the phases, 0.3-0.8 s, 2-5 submovements) or slow and
    curved (bowed 4-12 cm across the straight line)."""
    from imulog.simulate.grid import CURVED, STROKE

    return {
        "stroke-slow": {**STROKE, "slowness": 2.5},
        "stroke-hesitant": {**STROKE, "pause_probability": 0.6, "pause_s": (0.3, 0.8), "submovements": (2, 5)},
        "stroke-curved": {**STROKE, **CURVED, "curve_m": (0.04, 0.12), "slowness": 2.0},
    }


def _devices() -> dict[str, dict]:
    """``--grid devices``: the grid's ``device-noise`` and ``stroke-device-noise`` (:mod:`imulog.simulate.grid`,
    the median real device's sensor noise instead of the simulator's quieter default) and the wider
    ``stroke-slow`` at that noise."""
    from imulog.simulate.grid import DEVICE_CONDITIONS, DEVICE_NOISE

    return {**DEVICE_CONDITIONS, "stroke-slow-device-noise": {**_wider()["stroke-slow"], **DEVICE_NOISE}}


def grid_rows(conditions, seeds, subjects, repetitions: int, methods=GRID_METHODS, pairs=None) -> list[dict]:
    """One record per (condition, method) with the means over the trials (see :func:`score`); a condition is
    one of :mod:`imulog.simulate.grid` or of :func:`_wider`. Trials: every seed x subject, or the (seed, subject)
    ``pairs`` when given."""
    from dataclasses import replace

    from imulog.process.segmentation.repetitions import RepetitionParams
    from imulog.simulate.grid import condition

    wider = {**_wider(), **_devices()}
    pairs = list(pairs) if pairs is not None else [(seed, subject) for seed in seeds for subject in subjects]
    trials = [
        (name, seed, subject, dict(wider[name]) if name in wider else condition(name))
        for name in conditions
        for seed, subject in pairs
    ]
    rows: dict[tuple[str, str], list[dict]] = {}
    for name, seed, subject, options in trials:
        sim = simulate("r2g", seed=seed, subject=subject, repetitions=repetitions, **options)
        for label, params in methods.items():
            params = replace(params, repetitions=RepetitionParams(n_repetitions=repetitions))
            rows.setdefault((name, label), []).append({**score(sim, params), "seed": seed, "subject": subject})
    out = []
    for (name, label), rs in rows.items():
        out.append(
            {
                "condition": name,
                "method": label,
                "trials": len(rs),
                "correct": float(np.mean([r["correct"] for r in rs])),
                "within_0_1_s": float(np.mean([r["duration_within_0_1_s"] for r in rs])),
                "worst_trial_within_0_1_s": float(np.min([r["duration_within_0_1_s"] for r in rs])),
                "onset_mae_s": float(np.nanmean([r["onset_mae_s"] for r in rs])),
                "offset_mae_s": float(np.nanmean([r["offset_mae_s"] for r in rs])),
                "mean_duration_error_s": float(np.mean([r["mean_duration_error_s"] for r in rs])),
                "max_duration_error_s": float(np.max([r["max_duration_error_s"] for r in rs])),
                "per_trial": [
                    (r["seed"], r["subject"], r["duration_within_0_1_s"], r["correct"], r["max_duration_error_s"])
                    for r in rs
                ],
                "outside": [(r["seed"], r["subject"], *o) for r in rs for o in r["outside"]],
            }
        )
    return out


def print_trials_under(rows: list[dict], share: float = 0.95) -> None:
    """One line per trial with fewer than ``share`` of its durations within 0.1 s (issue 31: >= 95 % on every
    trial), with its condition, method, seed and subject."""
    print(f"\ntrials under {100 * share:.0f} % of durations within 0.1 s:")
    n = 0
    for r in rows:
        for seed, subject, within, correct, worst in r["per_trial"]:
            if within < share:
                n += 1
                print(
                    f"  {r['condition']} / {r['method']}: seed {seed} subject {subject}: {100 * within:.1f} % "
                    f"(correct phases {100 * correct:.1f} %, max duration error {worst:.2f} s)"
                )
    print(f"  {n} of {sum(len(r['per_trial']) for r in rows)} trials")


def print_outside(rows: list[dict]) -> None:
    """Per condition and method, the phases whose durations are outside 0.1 s by what is wrong (a phase can count
    under two ends), then each of them: seed, subject, repetition, label, onset and offset errors (s)."""
    for r in rows:
        out = r["outside"]
        if not out:
            continue
        on, off = np.array([o[4] for o in out]), np.array([o[5] for o in out])
        both = (np.abs(on) < 0.1) & (np.abs(off) < 0.1)
        print(
            f"\n{r['condition']} / {r['method']}: {len(out)} phases outside 0.1 s: missing {int(np.isnan(on).sum())}, "
            f"offset more than 0.3 s early {int((off < -0.3).sum())}, 0.1-0.3 s early {int(((off >= -0.3) & (off < -0.1)).sum())}, "
            f"0.1-0.3 s late {int(((off > 0.1) & (off <= 0.3)).sum())}, more than 0.3 s late {int((off > 0.3).sum())}; "
            f"onset more than 0.1 s early {int((on < -0.1).sum())}, late {int((on > 0.1).sum())}; both ends within 0.1 s "
            f"{int(both.sum())}"
            + (f" (onset {on[both].mean():+.3f} s, offset {off[both].mean():+.3f} s on average)" if both.any() else "")
        )
        for seed, subject, rep, label, a, b in out:
            print(f"  seed {seed} subject {subject} repetition {rep} {label}: onset {a:+.3f} s, offset {b:+.3f} s")


def print_comparison(before: list[dict], rows: list[dict], method: str | None = None) -> None:
    """Per condition and method, ``before`` (a ``--json`` file of an earlier run on the same trials) → ``rows``:
    the share of durations within 0.1 s (worst trial), the trials under 95 %, how many trials gained / lost, and
    the onset / offset MAE (s). With ``method``, every row is compared with that method's record in ``before``."""
    old = {(r["condition"], method or r["method"]): r for r in before if method is None or r["method"] == method}
    print(
        "\n| condition | method | within 0.1 s % (worst trial), before → after | trials under 95 % | trials better / worse "
        "| onset / offset MAE s |"
    )
    print("|" + "---|" * 6)
    for r in rows:
        b = old.get((r["condition"], method or r["method"]))
        if b is None:
            continue
        was = {(t[0], t[1]): t[2] for t in b["per_trial"]}
        now = {(t[0], t[1]): t[2] for t in r["per_trial"]}
        better = sum(now[k] > was[k] + 1e-9 for k in now if k in was)
        worse = sum(now[k] < was[k] - 1e-9 for k in now if k in was)
        print(
            f"| {r['condition']} | {r['method']} | {100 * b['within_0_1_s']:.1f} ({100 * b['worst_trial_within_0_1_s']:.1f}) → "
            f"{100 * r['within_0_1_s']:.1f} ({100 * r['worst_trial_within_0_1_s']:.1f}) | "
            f"{sum(v < 0.95 for v in was.values())} → {sum(v < 0.95 for v in now.values())} | {better} / {worse} | "
            f"{b['onset_mae_s']:.3f} / {b['offset_mae_s']:.3f} → {r['onset_mae_s']:.3f} / {r['offset_mae_s']:.3f} |"
        )
        for k in sorted(now):
            if k in was and now[k] < was[k] - 1e-9:
                print(f"  worse: seed {k[0]} subject {k[1]}: {100 * was[k]:.1f} → {100 * now[k]:.1f} %")


def print_grid(rows: list[dict]) -> None:
    print(
        "| condition | method | trials | correct phases % | durations within 0.1 s % (worst trial) | onset MAE s "
        "| offset MAE s | mean duration error s | max duration error s |"
    )
    print("|" + "---|" * 9)
    for r in rows:
        print(
            f"| {r['condition']} | {r['method']} | {r['trials']} | {100 * r['correct']:.1f} | "
            f"{100 * r['within_0_1_s']:.1f} ({100 * r['worst_trial_within_0_1_s']:.1f}) | {r['onset_mae_s']:.3f} | "
            f"{r['offset_mae_s']:.3f} | "
            f"{r['mean_duration_error_s']:+.3f} | {r['max_duration_error_s']:.2f} |"
        )
    for label in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == label]
        print(
            f"| **all conditions** | {label} | {sum(r['trials'] for r in mine)} | "
            f"{100 * np.mean([r['correct'] for r in mine]):.1f} | {100 * np.mean([r['within_0_1_s'] for r in mine]):.1f} "
            f"({100 * np.min([r['worst_trial_within_0_1_s'] for r in mine]):.1f}) | "
            f"{np.mean([r['onset_mae_s'] for r in mine]):.3f} | {np.mean([r['offset_mae_s'] for r in mine]):.3f} | "
            f"{np.mean([r['mean_duration_error_s'] for r in mine]):+.3f} | "
            f"{np.max([r['max_duration_error_s'] for r in mine]):.2f} |"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--subjects", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--first-subject", type=int, default=0)
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=list(SCENARIOS))
    ap.add_argument("--methods", nargs="+", default=[*METHODS, "dynamos-otsu", "dynamos-no-boundaries", "dynamos-raw"])
    ap.add_argument(
        "--grid",
        nargs="+",
        default=None,
        help="accuracy-grid conditions (names, 'all', 'wider' or 'devices': see _wider, _devices)",
    )
    ap.add_argument("--repetitions", type=int, default=10, help="repetitions per grid trial")
    ap.add_argument(
        "--grid-methods", nargs="+", default=list(GRID_METHODS), choices=list(GRID_METHODS), help="grid methods"
    )
    ap.add_argument("--per-trial", action="store_true", help="also list every grid trial under 95 %% within 0.1 s")
    ap.add_argument(
        "--sets",
        nargs="+",
        default=None,
        metavar="SEED:SUBJECT",
        help="several trial sets, each --seeds x --subjects from a first seed and subject (instead of --first-*)",
    )
    ap.add_argument(
        "--outside", action="store_true", help="also list the phases outside 0.1 s, by what is wrong (issue 31)"
    )
    ap.add_argument("--json", default=None, help="also write the grid records (with every trial's figures) here")
    ap.add_argument(
        "--compare", default=None, help="a --json file of an earlier run on the same trials: before → after"
    )
    ap.add_argument(
        "--compare-as", default=None, help="compare every method with this method's records in --compare's file"
    )
    args = ap.parse_args()
    if args.grid:
        from imulog.simulate.grid import CONDITIONS

        named = {"all": list(CONDITIONS), "wider": list(_wider()), "devices": list(_devices())}
        conditions = [c for g in args.grid for c in named.get(g, [g])]
        t0 = time.perf_counter()
        firsts = (
            [tuple(int(x) for x in s.split(":")) for s in args.sets]
            if args.sets
            else [(args.first_seed, args.first_subject)]
        )
        pairs = [(s0 + i, j0 + j) for s0, j0 in firsts for i in range(args.seeds) for j in range(args.subjects)]
        rows = grid_rows(
            conditions, None, None, args.repetitions, {k: GRID_METHODS[k] for k in args.grid_methods}, pairs=pairs
        )
        print_grid(rows)
        if args.per_trial:
            print_trials_under(rows)
        if args.outside:
            print_outside(rows)
        if args.json:
            import json

            with open(args.json, "w") as f:
                json.dump(rows, f, indent=1)
        if args.compare:
            import json

            with open(args.compare) as f:
                print_comparison(json.load(f), rows, args.compare_as)
        print(f"\n{time.perf_counter() - t0:.0f} s wall")
        return
    variants = {
        "dynamos": PhaseParams(method="dynamos"),
        "dynamos-otsu": PhaseParams(method="dynamos", dynamos=DynamosParams(threshold="otsu")),
        "dynamos-no-boundaries": PhaseParams(method="dynamos", boundaries=BoundaryParams(enabled=False)),
        "dynamos-raw": PhaseParams(
            method="dynamos",
            dynamos=DynamosParams(refine_boundaries=False),
            boundaries=BoundaryParams(enabled=False),
        ),
        "double-threshold": PhaseParams(method="double-threshold"),
        "template": PhaseParams(method="template"),
    }
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    subjects = range(args.first_subject, args.first_subject + args.subjects)
    for scenario in args.scenarios:
        options = SCENARIOS[scenario]
        trials = [
            ((seed, subject), simulate("r2g", seed=seed, subject=subject, **options))
            for seed in seeds
            for subject in subjects
        ]
        print(
            f"\n{scenario}: {len(trials)} simulated R2G trials (seeds {seeds.start}..{seeds.stop - 1} x subjects "
            f"{subjects.start}..{subjects.stop - 1}), {options or 'simulator defaults'}"
        )
        table(trials, args.methods, variants)
        if scenario == args.scenarios[0]:
            baseline = time.perf_counter()
            for _, sim in trials:
                gyro_norm_static(sim.recording.imus[0].gyr, 114.9)
            baseline = (time.perf_counter() - baseline) / len(trials)
            print(f"baseline gyro-norm static detector: {baseline * 1e3:.1f} ms/trial")


if __name__ == "__main__":
    main()
