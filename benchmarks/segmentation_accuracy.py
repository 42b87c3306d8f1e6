"""Segmentation accuracy on simulated R2G trials (25 repetitions x 4 phases) against the simulator's truth.

    python benchmarks/segmentation_accuracy.py                 # 4 seeds x 2 subjects, all methods
    python benchmarks/segmentation_accuracy.py --seeds 10 --subjects 3 --methods dynamos

Trials have corrective sub-movements (``extra_submovement_probability``) and residual static velocity
(``residual_velocity_mps``). A detected phase is correct when it has the true phase's repetition and
label and overlaps it with intersection-over-union > 0.5; onset/offset errors are over correct phases, on
the reference clock. Also prints the segmentation time per trial against the baseline (gyro-norm
detector) run in the same process.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from imulog.process.segmentation.dynamos import DynamosParams
from imulog.process.segmentation.pipeline import METHODS, PhaseParams, segment_phases
from imulog.process.segmentation.zero_velocity import gyro_norm_static
from imulog.simulate import simulate


def score(sim, params: PhaseParams) -> dict:
    """Phase count, fraction correctly identified and onset/offset errors (s) of one simulated trial."""
    imu = sim.recording.imus[0]
    t_ref = np.asarray(sim.truth.imu_t_ref_ns, dtype=np.int64)
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) * 1e-9)
    result = segment_phases(imu.gyr, rate, params)
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
    return {
        "n_phases": len(ph),
        "n_true": len(truth),
        "correct": correct / len(truth),
        "mae_s": float(errors.mean()) if len(errors) else float("nan"),
        "onset_mae_s": float(np.mean(np.abs(onset))) if onset else float("nan"),
        "offset_mae_s": float(np.mean(np.abs(offset))) if offset else float("nan"),
        "n_corrected": ph.n_corrected,
        "n_movements": len(result.movement_start),
    }


SIM_OPTIONS = {"extra_submovement_probability": 0.2, "residual_velocity_mps": 0.01}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--subjects", type=int, default=2)
    ap.add_argument("--methods", nargs="+", default=[*METHODS, "dynamos-otsu", "dynamos-raw"])
    args = ap.parse_args()
    variants = {
        "dynamos": PhaseParams(method="dynamos"),
        "dynamos-otsu": PhaseParams(method="dynamos", dynamos=DynamosParams(threshold="otsu")),
        "dynamos-raw": PhaseParams(method="dynamos", dynamos=DynamosParams(refine_boundaries=False)),
        "double-threshold": PhaseParams(method="double-threshold"),
        "template": PhaseParams(method="template"),
    }
    trials = [
        ((seed, subject), simulate("r2g", seed=seed, subject=subject, **SIM_OPTIONS))
        for seed in range(args.seeds)
        for subject in range(args.subjects)
    ]
    print(
        f"{len(trials)} simulated R2G trials (seeds 0..{args.seeds - 1} x subjects 0..{args.subjects - 1}), {SIM_OPTIONS}"
    )
    header = "| method | trials with 100 phases | correct phases % (min) | onset MAE s | offset MAE s | MAE s (max) | s/trial |"
    print(header)
    print("|" + "---|" * 7)
    baseline = time.perf_counter()
    for _, sim in trials:
        gyro_norm_static(sim.recording.imus[0].gyr, 114.9)
    baseline = (time.perf_counter() - baseline) / len(trials)
    for name in args.methods:
        t0 = time.perf_counter()
        rows = [score(sim, variants[name]) for _, sim in trials]
        per_trial = (time.perf_counter() - t0) / len(trials)
        exact = sum(r["n_phases"] == r["n_true"] for r in rows)
        correct = [100 * r["correct"] for r in rows]
        mae = [r["mae_s"] for r in rows]
        print(
            f"| {name} | {exact}/{len(rows)} | {np.mean(correct):.1f} ({np.min(correct):.0f}) | "
            f"{np.nanmean([r['onset_mae_s'] for r in rows]):.3f} | {np.nanmean([r['offset_mae_s'] for r in rows]):.3f} | "
            f"{np.nanmean(mae):.3f} ({np.nanmax(mae):.3f}) | {per_trial:.2f} |"
        )
    print(f"baseline gyro-norm static detector: {baseline * 1e3:.1f} ms/trial")


if __name__ == "__main__":
    main()
