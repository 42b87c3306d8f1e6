"""Repetitions whose IMU estimate is far off, and whether the orientation's tilt is why (issue 31 point 2; a
diagnostic, not a method).

For every simulated trial (``trajectory_accuracy``'s R2G trials, subject k with seed k) it runs ``zupt_bias`` (the
IMU's own estimate: ZUPT on the rotating-bias-compensated acceleration) and the optimized trajectory with the
defaults, and counts the repetitions whose ``zupt_bias`` MAE is above ``--far`` cm (5) on some axis; for each it
prints the repetition's MAE x / y / z (cm) of ``zupt_bias`` and ``optimized``: with the defaults, with
``AnchorParams.rest_tilt = "accelerometer"`` (each rest's tilt from the accelerometer's direction,
``--change rest-tilt-acc`` of ``trajectory_paired.py``) and with the true orientation's tilt (the estimated heading
kept; ``trajectory_displacements.variant(..., {"tilt"})``), and whether the optimisation kept its start
(``inconsistent_repetitions``: the fallback). The closing table counts them per condition.

    python benchmarks/trajectory_far_repetitions.py --grid all --subjects 6 --first-subject 40 --repetitions 10
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from trajectory_accuracy import RunCost, add_trial_arguments, evaluate_trial, grid_names, simulated_inputs  # noqa: E402
from trajectory_displacements import variant  # noqa: E402

import imulog.process.trajectory_opt as topt  # noqa: E402
from imulog.process.trajectory_opt import DEFAULT_PARAMS  # noqa: E402

METHODS = ("zupt_bias", "optimized")
REST_TILT = replace(DEFAULT_PARAMS, anchor=replace(DEFAULT_PARAMS.anchor, rest_tilt="accelerometer"))


def run(inputs: dict[str, Any], params=DEFAULT_PARAMS) -> tuple[dict[str, dict[int, np.ndarray]], set[int]]:
    """{method: {repetition: MAE x, y, z (cm)}} and the repetitions the optimisation kept at its start."""
    seen: dict[str, Any] = {}
    residuals, inconsistent = topt.reference_residuals, topt.inconsistent_repetitions

    def spy_residuals(t, z, static, reps, waypoints):
        seen["reps"] = reps
        return residuals(t, z, static, reps, waypoints)

    def spy_inconsistent(res, *a, **k):
        out = inconsistent(res, *a, **k)
        seen["fallback"] = {seen["reps"][i].index for i in out}
        return out

    with (
        mock.patch.object(topt, "reference_residuals", spy_residuals),
        mock.patch.object(topt, "inconsistent_repetitions", spy_inconsistent),
    ):
        records, _, _ = evaluate_trial(inputs, METHODS, params)
    maes = {m: {r["repetition"]: np.array([r[a]["mae_cm"] for a in "xyz"]) for r in records[m]} for m in METHODS}
    return maes, seen.get("fallback", set())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_trial_arguments(ap, grid="stroke", first_subject=40)
    ap.add_argument("--far", type=float, default=5.0, help="cm: a repetition's zupt_bias MAE above this on an axis")
    args = ap.parse_args(argv)
    from imulog.simulate.core import simulate
    from imulog.simulate.grid import condition

    cost = RunCost()
    f = lambda v: " / ".join(f"{x:.1f}" for x in v)  # noqa: E731
    nan = np.full(3, np.nan)
    summary = []
    print(
        "| trial | rep | zupt_bias | optimized | fallback | rest-tilt-acc zupt_bias / optimized | true tilt zupt_bias / optimized |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in grid_names(args.grid):
        n_reps = n_far = n_far_acc = n_far_tilt = n_fallback = 0
        for s in range(args.first_subject, args.first_subject + args.subjects):
            kw = condition(name)
            inputs = simulated_inputs(
                s,
                seed=s,
                repetitions=args.repetitions,
                rests=DEFAULT_PARAMS.rests,
                anchor_params=DEFAULT_PARAMS.anchor,
                **kw,
            )
            base, fallback = run(inputs)
            acc_in = simulated_inputs(
                s, seed=s, repetitions=args.repetitions, rests=REST_TILT.rests, anchor_params=REST_TILT.anchor, **kw
            )
            acc, _ = run(acc_in, REST_TILT)
            v = variant(inputs, simulate("r2g", subject=s, seed=s, repetitions=args.repetitions, **kw), {"tilt"})
            tilt, _ = run(dict(inputs, acc_world=v["acc"], q_world=v["q"]))
            n_reps += len(base["zupt_bias"])
            n_fallback += len(fallback)
            n_far_acc += sum(bool(np.any(e > args.far)) for e in acc["zupt_bias"].values())
            n_far_tilt += sum(bool(np.any(e > args.far)) for e in tilt["zupt_bias"].values())
            for k, e in sorted(base["zupt_bias"].items()):
                if not np.any(e > args.far):
                    continue
                n_far += 1
                print(
                    f"| {name} s{s} | {k} | {f(e)} | {f(base['optimized'].get(k, nan))} | {'yes' if k in fallback else ''} "
                    f"| {f(acc['zupt_bias'].get(k, nan))}, {f(acc['optimized'].get(k, nan))} "
                    f"| {f(tilt['zupt_bias'].get(k, nan))}, {f(tilt['optimized'].get(k, nan))} |",
                    flush=True,
                )
        summary.append((name, n_reps, n_far, n_fallback, n_far_acc, n_far_tilt))
        print(f"{name}: {n_far} of {n_reps} far", file=sys.stderr, flush=True)
    print(
        f"\n| condition | repetitions | far (> {args.far:g} cm) | fallback | far with rest-tilt-acc | far with the true tilt |"
    )
    print("|---|---|---|---|---|---|")
    for row in summary:
        print("| " + " | ".join(str(x) for x in row) + " |")
    print(f"\n{cost.line()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
