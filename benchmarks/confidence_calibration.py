"""Per-repetition features and true errors over the accuracy grid: what the repetition flag is calibrated on.

Issue 31, point 3: a repetition whose phase boundaries are off by more than 0.1 s, or whose optimised
trajectory error is above 2 cm on an axis, should be flagged with recall >= 80 % and precision >= 50 %.
This script simulates the grid's drinking trials (``imulog.simulate.grid``), runs imulog's own segmentation,
orientation and trajectory code on each (no truth enters the estimates), and writes one row per repetition:
the features the phases and trajectory steps know (event correction's counts and confidence, the ZUPT
velocity drift, the initial estimate's distance to the reference at the rests, the optimisation's pull) and the truth labels. Then it scores
``imulog.process.repetition_flags.flag_repetitions`` on it.

    python benchmarks/confidence_calibration.py --seeds 0 --subjects 0 1 -o /tmp/calib.json     # collect
    python benchmarks/confidence_calibration.py --score /tmp/calib.json                        # score a file
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.alignment import device_to_reference
from imulog.process.evaluation import trajectory_errors
from imulog.process.rests import true_rests
from imulog.process.trajectory_opt import (
    DEFAULT_PARAMS,
    merge_overlapping,
    reconstruct_repetitions,
    repetition_windows,
)

PHASE_TOLERANCE_S = 0.1
TRAJECTORY_TOLERANCE_CM = 2.0


def trial_rows(name: str, subject: int, seed: int, repetitions: int, overrides: dict[str, Any]) -> list[dict]:
    """One row per estimated repetition of one simulated trial: features and truth labels."""
    from imulog.process.anchor_heading import restart_rests
    from imulog.process.integration import rest_anchored_orientation
    from imulog.process.orientation import estimate_orientation, gravity_free_acceleration
    from imulog.process.repetition_flags import repetition_features
    from imulog.process.segmentation.pipeline import PhaseParams, segment_phases
    from imulog.process.segmentation.repetitions import RepetitionParams
    from imulog.simulate.core import simulate
    from imulog.steps.trajectory_windows import TrajectoryWindows

    sim = simulate("r2g", subject=subject, seed=seed, repetitions=repetitions, **overrides)
    imu, truth = sim.recording.imus[0], sim.truth
    t_ref_ns = device_to_reference(imu.t_ns, truth.alignment)
    t_s = (np.asarray(t_ref_ns, dtype=np.float64) - float(t_ref_ns[0])) / 1e9
    rate = (len(t_s) - 1) / t_s[-1]
    res = segment_phases(imu.gyr, rate, PhaseParams(repetitions=RepetitionParams(n_repetitions=repetitions)), imu.acc)
    static_ph = np.asarray(res.static, dtype=bool)
    # orientation and world frame as the trajectory step has them after alignment (a constant rotation)
    est = estimate_orientation(imu.gyr, imu.acc, rate)
    ph = res.phases
    spans: dict[int, tuple[float, float]] = {}
    for s, e, k in zip(ph.start, ph.end, ph.repetition, strict=True):
        lo, hi = spans.get(int(k), (np.inf, -np.inf))
        spans[int(k)] = (min(lo, t_s[int(s)]), max(hi, t_s[min(int(e), len(t_s) - 1)]))
    # the heading chain restarts where the step may cut a window (AnchorParams.heading="gyroscope")
    restart = restart_rests(static_ph, t_s, TrajectoryWindows.chain_rest_s, [v for k, v in spans.items() if k >= 0])
    q_est = rest_anchored_orientation(est.quat, imu.gyr, t_s, static_ph, restart=restart)
    acc_g = gravity_free_acceleration(q_est, imu.acc, est.static)
    q_g2w = quat.average(quat.multiply(truth.imu_orientation, quat.conjugate(q_est)))
    acc_world = quat.rotate(q_g2w, acc_g)
    q_world = quat.multiply(q_g2w, q_est)

    bounds: dict[int, list[tuple[float, float]]] = {}
    for s, e, k in zip(ph.start, ph.end, ph.repetition, strict=True):
        bounds.setdefault(int(k), []).append((t_s[int(s)], t_s[min(int(e), len(t_s) - 1)]))
    phase_bounds = {k: np.asarray(sorted(v)) for k, v in bounds.items()}
    static = true_rests(static_ph, acc_world, rate, DEFAULT_PARAMS.rests, orientation=q_world)
    reps, _ = merge_overlapping(repetition_windows(t_s, phase_bounds, static))
    info: dict[str, Any] = {}
    recon = reconstruct_repetitions(
        t_s,
        acc_world,
        static,
        reps,
        ["zupt", "zupt_bias", "optimized"],
        anthropometrics=sim.recording.metadata.get("imulog.anthropometrics", {}),
        orientation=q_world,
        params=DEFAULT_PARAMS,
        info=info,
        drift_candidates=True,  # the rows carry the unused drift candidates too (--feature scores them)
    )
    features = repetition_features(
        t_s, acc_world, static, reps, recon, ph.quality, trajectory_info=info, candidates=True
    )

    # truth: phase boundaries per (repetition, label) on the reference clock
    t0 = float(t_ref_ns[0]) / 1e9
    true_b = {
        (int(k), str(lab)): (a / 1e9 - t0, b / 1e9 - t0)
        for a, b, k, lab in zip(
            truth.phases.start_ns, truth.phases.end_ns, truth.phases.task_index, truth.phases.labels, strict=True
        )
    }
    det_b = {
        (int(k), str(lab)): (t_s[int(s)], t_s[max(int(e) - 1, int(s))])
        for s, e, k, lab in zip(ph.start, ph.end, ph.repetition, ph.labels, strict=True)
    }
    rows = []
    for rep in reps:
        k = int(rep.index)
        labels = [lab for (kk, lab) in true_b if kk == k]
        worst = 0.0
        for lab in labels:
            if (k, lab) not in det_b:
                worst = np.inf
                continue
            (a, b), (c, d) = true_b[(k, lab)], det_b[(k, lab)]
            worst = max(worst, abs(c - a), abs(d - b))
        sl = slice(rep.start, rep.stop)
        opt = recon["optimized"][sl]
        err = trajectory_errors(opt, truth.imu_position[sl]) if np.isfinite(opt).all(axis=1).sum() > 2 else None
        mae = [err[a]["mae_cm"] for a in "xyz"] if err else [float("nan")] * 3
        f = features.get(k, {})
        rows.append(
            {
                "condition": name,
                "subject": subject,
                "seed": seed,
                "repetition": k,
                "phase_error_s": float(worst),
                "optimized_mae_cm": mae,
                "bad_phase": bool(worst > PHASE_TOLERANCE_S),
                "bad_trajectory": bool(np.nanmax(mae) > TRAJECTORY_TOLERANCE_CM) if err else True,
                **f,
            }
        )
    return rows


def collect(conditions: list[str], seeds: list[int], subjects: list[int], repetitions: int) -> list[dict]:
    from imulog.simulate.grid import condition

    rows: list[dict] = []
    for name in conditions:
        for seed in seeds:
            for subject in subjects:
                t0 = time.perf_counter()
                rows.extend(trial_rows(name, subject, seed, repetitions, condition(name)))
                print(f"{name} seed {seed} subject {subject}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return rows


def score(rows: list[dict], params: Any = None) -> dict[str, float]:
    """Recall and precision of ``flag_repetitions`` (``params``: ``FlagParams``, None: the defaults) against the
    truth labels (bad phase or bad trajectory)."""
    from imulog.process.repetition_flags import FlagParams, flag_repetition

    bad = np.array([r["bad_phase"] or r["bad_trajectory"] for r in rows])
    flagged = np.array([bool(flag_repetition(r, params or FlagParams())) for r in rows])
    tp = int(np.sum(bad & flagged))
    return {
        "repetitions": len(rows),
        "bad": int(bad.sum()),
        "flagged": int(flagged.sum()),
        "recall": tp / max(int(bad.sum()), 1),
        "precision": tp / max(int(flagged.sum()), 1),
    }


def score_feature(rows: list[dict], feature: str, threshold: float) -> dict[str, float]:
    """``score`` with the ``drift`` reason replaced by ``feature > threshold`` (a candidate feature of the rows,
    absent counting as not above; every other reason as in ``FlagParams``)."""
    from imulog.process.repetition_flags import FlagParams

    marked = [{**r, "reference_cm": 1e9 if (r.get(feature) or 0.0) > threshold else 0.0} for r in rows]
    return score(marked, FlagParams(max_reference_cm=0.5))


def main(argv: list[str] | None = None) -> int:
    from imulog.process.repetition_flags import FlagParams
    from imulog.simulate.grid import CONDITIONS

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--conditions", nargs="*", default=list(CONDITIONS))
    ap.add_argument("--seeds", nargs="*", type=int, default=[0])
    ap.add_argument("--subjects", nargs="*", type=int, default=[0, 1])
    ap.add_argument("--repetitions", type=int, default=8)
    ap.add_argument("-o", "--output", type=Path, help="write the rows (JSON) here")
    ap.add_argument("--score", type=Path, help="score the rows of this file instead of simulating")
    ap.add_argument(
        "--max-reference-cm",
        nargs="*",
        type=float,
        help="also score these drift thresholds (FlagParams.max_reference_cm)",
    )
    ap.add_argument(
        "--max-pull-cm",
        nargs="*",
        type=float,
        help="also score the pull rule used until 2026-12-07 at these thresholds",
    )
    ap.add_argument(
        "--feature",
        nargs="+",
        metavar="NAME=T1,T2",
        help="also score a candidate drift feature of the rows at these thresholds (e.g. start_zupt_cm=1,2,3)",
    )
    ap.add_argument(
        "--closure-factor",
        type=float,
        help="OptimizationParams.closure_factor (option 5 of issue 31; default 0.5 since 2026-12-07)",
    )
    ap.add_argument(
        "--bias-outlier-factor",
        type=float,
        help="RotatingBiasParams.outlier_factor (refit the rotating bias without the movements it cannot close; an option, off by default)",
    )
    ap.add_argument(
        "--rest-model",
        help="OptimizationParams.rest_model (each repetition's own rests in the reference, issue 31 point 2; "
        "'none' for off)",
    )
    args = ap.parse_args(argv)
    global DEFAULT_PARAMS
    D = DEFAULT_PARAMS  # noqa: N806
    if args.rest_model is not None:
        mode = None if args.rest_model == "none" else args.rest_model
        DEFAULT_PARAMS = replace(D, optimized=replace(D.optimized, rest_model=mode))
        D = DEFAULT_PARAMS  # noqa: N806
    if args.closure_factor is not None:
        DEFAULT_PARAMS = replace(D, optimized=replace(D.optimized, closure_factor=args.closure_factor))
    if args.bias_outlier_factor is not None:
        D = DEFAULT_PARAMS  # noqa: N806
        DEFAULT_PARAMS = replace(D, rotating_bias=replace(D.rotating_bias, outlier_factor=args.bias_outlier_factor))
    if args.score:
        rows = json.loads(args.score.read_text())
    else:
        rows = collect(args.conditions, args.seeds, args.subjects, args.repetitions)
        if args.output:
            args.output.write_text(json.dumps(rows, default=float))
    print(json.dumps(score(rows), indent=1))
    for ref in args.max_reference_cm or ():  # the drift threshold scanned (FlagParams.max_reference_cm)
        print(f"max_reference_cm {ref}: {json.dumps(score(rows, FlagParams(max_reference_cm=ref)))}")
    for pull in args.max_pull_cm or ():  # the rule until 2026-12-07: the pull alone
        print(f"max_pull_cm {pull}: {json.dumps(score(rows, FlagParams(max_reference_cm=None, max_pull_cm=pull)))}")
    for spec in args.feature or ():  # candidate drift features (issue 31 point 2)
        name, _, values = spec.partition("=")
        for thr in map(float, values.split(",")):
            print(f"{name} > {thr}: {json.dumps(score_feature(rows, name, thr))}")
    by_condition: dict[str, list[dict]] = {}
    for r in rows:
        by_condition.setdefault(r["condition"], []).append(r)
    print("| condition | repetitions | bad | flagged | recall | precision |")
    print("|---|---|---|---|---|---|")
    for name, rs in by_condition.items():
        s = score(rs)
        print(
            f"| {name} | {s['repetitions']} | {s['bad']} | {s['flagged']} | {s['recall']:.2f} | {s['precision']:.2f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
