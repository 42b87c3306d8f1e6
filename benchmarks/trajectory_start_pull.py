"""Which term of the optimisation pulls the optimized trajectory away from its start (issue 31 point 2, twelfth round).

For every trial (``trajectory_accuracy``'s simulated R2G trials, subject k with seed k) the inputs of one pipeline
(``--change NAME``: the after parameters of ``trajectory_paired.CHANGES``) are built once, and the optimisation is
re-run with one of its terms switched off at a time (``TERMS``): the reference while the hand is still (its static
trust 1 m), the whole reference (static 1 m, moving 10 m), the coupled symmetry, the smoothness at rests, the
reference and the symmetry together, and the start's rotating-bias compensation (no compensation). Per condition
and axis (cm): the mean MAE of plain ZUPT, of the optimisation's start (``zupt_bias``: ZUPT on the compensated
acceleration) and of the optimized trajectory with every term and with each term off, and in brackets how many
trials' optimized MAE is below their ZUPT's on that axis (the second half of issue 31's target).

    python benchmarks/trajectory_start_pull.py --change rest-tilt-acc --grid default stroke uncalibrated combined \\
        combined-stroke --subjects 6 --first-subject 40 --repetitions 10
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from trajectory_accuracy import RunCost, add_trial_arguments, evaluate_trial, grid_names  # noqa: E402
from trajectory_paired import CHANGES, pipeline_inputs  # noqa: E402

from imulog.process.trajectory_opt import TrajectoryParams  # noqa: E402


def _opt(p: TrajectoryParams, **kw) -> TrajectoryParams:
    return replace(p, optimized=replace(p.optimized, **kw))


TERMS = {  # name: the pipeline's parameters with that term off
    "no static reference": lambda p: _opt(p, sigma_ref_static_m=1.0),
    "no reference": lambda p: _opt(p, sigma_ref_static_m=1.0, sigma_ref_moving_m=10.0),
    "no symmetry": lambda p: _opt(p, sigma_symmetry_m=None),
    "no smoothness": lambda p: _opt(p, sigma_static_vel_mps=None),
    "no reference, no symmetry": lambda p: _opt(
        p, sigma_ref_static_m=1.0, sigma_ref_moving_m=10.0, sigma_symmetry_m=None
    ),
    "no compensation": lambda p: replace(p, rotating_bias=replace(p.rotating_bias, min_movements=10**9)),
}


def _mae(records: list[dict]) -> np.ndarray:
    """Mean MAE (cm) per axis over a trial's repetitions."""
    return np.mean([[r[a]["mae_cm"] for a in "xyz"] for r in records], axis=0)


def trial_pull(name: str, subject: int, repetitions: int, params: TrajectoryParams) -> dict[str, np.ndarray]:
    """{"zupt" | "start" | "optimized" | TERMS' names: MAE x / y / z (cm)} of one trial."""
    inputs = pipeline_inputs(name, subject, repetitions, params)
    records, _, _ = evaluate_trial(inputs, ("zupt", "zupt_bias", "optimized"), params)
    out = {"zupt": _mae(records["zupt"]), "start": _mae(records["zupt_bias"]), "optimized": _mae(records["optimized"])}
    for term, change in TERMS.items():
        out[term] = _mae(evaluate_trial(inputs, ("optimized",), change(params))[0]["optimized"])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--change", choices=list(CHANGES), default="rest-tilt-acc")
    add_trial_arguments(ap, grid="all", first_subject=40)
    args = ap.parse_args(argv)
    params = CHANGES[args.change][1]
    cost = RunCost()
    keys = ["zupt", "start", "optimized", *TERMS]
    print(f"| condition | {' | '.join(keys)} |")
    print("|---|" + "---|" * len(keys))
    for name in grid_names(args.grid):
        rows = [
            trial_pull(name, s, args.repetitions, params)
            for s in range(args.first_subject, args.first_subject + args.subjects)
        ]
        cells = []
        for k in keys:
            m = np.mean([r[k] for r in rows], axis=0)
            below = np.sum([r[k] < r["zupt"] for r in rows], axis=0)
            cells.append(" / ".join(f"{v:.2f}" for v in m) + ("" if k == "zupt" else f" ({'/'.join(map(str, below))})"))
        print(f"| {name} | {' | '.join(cells)} |", flush=True)
    print(f"\n{cost.line()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
