"""Where the optimized trajectory's minimum-jerk reference is wrong, and what that costs (issue 31 point 2, eleventh
round; a diagnostic, not a method).

For every simulated trial (``trajectory_accuracy``'s R2G trials, subject k with seed k, the defaults) each
repetition's optimisation is captured as the trajectory step runs it (start, reference, phases, rests, the per-axis
trusts), and against the simulator's true path (relative to the repetition's start) it prints, per condition and
axis (cm):

* the reference's MAE over the repetition, over its holds and over its movements, and per phase (reach, the hold at
  the bottle, lift, at the mouth, return of the bottle, at the bottle put back, return of the hand, the hold after);
* how much of it is the reference's **ends** (the bottle / mouth / bottle-back / end positions: the reference
  against the same minimum-jerk path through the true rests, ``true ends``) and how much its **shape** (that path
  against the truth: a stroke-like movement's submovements, pauses and slow last parts);
* the RMS error of each rest (bottle, mouth, bottle put back, end; each the median over its hold) in the reference
  and in the optimisation's start (the IMU's own evidence);
* the optimized MAE re-solved on the same inputs with one thing changed: the reference through the true ends, the
  truth as the reference, the reference's static trust (``sigma_ref_static_m``, 1.5 cm) at 3 cm / 6 cm / none, and
  the start trusted twice as much / half as much (its static-position and velocity sigmas halved / doubled); with
  the number of trials at most 1 cm on every axis.

    python benchmarks/trajectory_reference.py --grid stroke combined-stroke --subjects 6 --first-subject 40
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

import imulog.process.trajectory_methods as methods  # noqa: E402
from imulog.process.minjerk import piecewise_minimum_jerk  # noqa: E402
from imulog.process.trajectory_opt import DEFAULT_PARAMS, optimize_repetition  # noqa: E402

SEGMENTS = ("reach", "at bottle", "lift", "at mouth", "return bottle", "at bottle back", "return hand", "after")
RESTS = ("bottle", "mouth", "bottle back", "end")


def capture(inputs: dict[str, Any]) -> list[dict[str, Any]]:
    """Every repetition's optimisation inputs as :func:`evaluate_trial` runs them with the defaults: start ``z``,
    reference ``ref`` (N, 3) m, phase bounds ``b`` (4, 2) s, rests ``st``, parameters ``p``, times ``t`` s."""
    seen: list[dict[str, Any]] = []
    solve = methods.optimize_repetition

    def spy(t, initial, reference, bounds, static, params):
        seen.append({"t": t, "z": initial, "ref": reference, "b": np.asarray(bounds), "st": static, "p": params})
        return solve(t, initial, reference, bounds, static, params)

    with mock.patch.object(methods, "optimize_repetition", spy):
        evaluate_trial(inputs, ("optimized",), DEFAULT_PARAMS)
    return seen


def hold_positions(pos: np.ndarray, t: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The four rests (bottle, mouth, bottle back, end) of one repetition: the median position over each hold
    after a phase (the last: to the window's end); (4, 3) m."""
    ends = [b[1, 0], b[2, 0], b[3, 0], t[-1]]
    out = []
    for (_, lo), hi in zip(b, ends, strict=True):
        m = (t >= lo) & (t <= hi)
        out.append(np.median(pos[m], axis=0) if m.any() else pos[min(np.searchsorted(t, lo), len(t) - 1)])
    return np.asarray(out)


def segment_masks(t: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
    """Masks of :data:`SEGMENTS`: each phase and the hold after it."""
    edges = [b[0, 0], b[0, 1], b[1, 0], b[1, 1], b[2, 0], b[2, 1], b[3, 0], b[3, 1], t[-1] + 1.0]
    return [(t >= lo) & (t < hi) for lo, hi in zip(edges[:-1], edges[1:], strict=True)]


def repetition_rows(rep: dict[str, Any], truth: np.ndarray) -> dict[str, Any]:
    """One repetition's figures (cm) against the true path ``truth`` (N, 3) m relative to its start."""
    t, b, z, ref, p = rep["t"], rep["b"], rep["z"], rep["ref"], rep["p"]
    tr = truth - truth[0]
    rests = hold_positions(tr, t, b)
    true_ends = piecewise_minimum_jerk(t, b, np.vstack([np.zeros(3), rests]))
    moving = np.zeros(len(t), dtype=bool)
    for lo, hi in b:
        moving |= (t >= lo) & (t <= hi)

    def mae(a: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        d = (a - tr) if mask is None else (a - tr)[mask]
        return 100 * np.mean(np.abs(d), axis=0) if len(d) else np.full(3, np.nan)

    def solve(reference: np.ndarray, **changes: Any) -> np.ndarray:
        return mae(optimize_repetition(t, z, reference, b, rep["st"], replace(p, **changes)).position)

    sds, sdv = np.asarray(p.sigma_data_static_m, dtype=float), np.asarray(p.sigma_data_mps, dtype=float)
    return {
        "start": mae(z),
        "reference": mae(ref),
        "reference at holds": mae(ref, ~moving),
        "reference in movements": mae(ref, moving),
        "ends (reference - true ends)": 100 * np.mean(np.abs(ref - true_ends), axis=0),
        "shape (true ends - truth)": mae(true_ends),
        "shape in movements": mae(true_ends, moving),
        "segments": [mae(ref, m) for m in segment_masks(t, b)],
        "rest error reference": 100 * (hold_positions(ref, t, b) - rests),
        "rest error start": 100 * (hold_positions(z, t, b) - rests),
        "optimized": solve(ref),
        "optimized, true ends": solve(true_ends),
        "optimized, truth as reference": solve(tr),
        "optimized, reference trust 3 cm": solve(ref, sigma_ref_static_m=0.03),
        "optimized, reference trust 6 cm": solve(ref, sigma_ref_static_m=0.06),
        "optimized, no reference": solve(ref, sigma_ref_static_m=10.0, sigma_ref_moving_m=10.0),
        "optimized, start trusted 2x": solve(ref, sigma_data_static_m=tuple(sds / 2), sigma_data_mps=tuple(sdv / 2)),
        "optimized, start trusted 0.5x": solve(ref, sigma_data_static_m=tuple(sds * 2), sigma_data_mps=tuple(sdv * 2)),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_trial_arguments(ap, grid="stroke", first_subject=40)
    args = ap.parse_args(argv)
    from imulog.simulate.grid import condition

    cost = RunCost()
    f = lambda v: " / ".join(f"{x:.2f}" for x in v)  # noqa: E731
    d = DEFAULT_PARAMS
    for name in grid_names(args.grid):
        rows, trial_of = [], []
        for s in range(args.first_subject, args.first_subject + args.subjects):
            inputs = simulated_inputs(
                s, seed=s, repetitions=args.repetitions, rests=d.rests, anchor_params=d.anchor, **condition(name)
            )
            t_all, truth = inputs["t_s"], inputs["truth_pos"]
            for rep in capture(inputs):
                i0 = int(np.searchsorted(t_all, rep["t"][0]))
                rows.append(repetition_rows(rep, truth[i0 : i0 + len(rep["t"])]))
                trial_of.append(s)
            print(f"{name} subject {s}: {sum(1 for x in trial_of if x == s)} repetitions", file=sys.stderr, flush=True)
        trial_of_a = np.asarray(trial_of)
        print(f"\n## {name}: {len(rows)} repetitions of {args.subjects} trials (first subject {args.first_subject})\n")
        print("| figure | MAE x / y / z (cm) | trials with every axis <= 1 cm |")
        print("|---|---|---|")
        for key, value in rows[0].items():
            if isinstance(value, list) or key.startswith("rest error"):
                continue
            v = np.array([r[key] for r in rows])
            per_trial = np.array([v[trial_of_a == s].mean(0) for s in np.unique(trial_of_a)])
            ok = f"{int(np.sum(np.all(per_trial <= 1.0, axis=1)))} of {len(per_trial)}" if "optim" in key else ""
            print(f"| {key} | {f(np.nanmean(v, axis=0))} | {ok} |")
        print("\n| the reference's MAE per segment | x / y / z (cm) |\n|---|---|")
        seg = np.array([r["segments"] for r in rows])  # (R, 8, 3)
        for j, label in enumerate(SEGMENTS):
            print(f"| {label} | {f(np.nanmean(seg[:, j], axis=0))} |")
        print("\n| rest | reference RMS error x / y / z (cm) | start RMS error x / y / z (cm) |\n|---|---|---|")
        er = np.array([r["rest error reference"] for r in rows])
        es = np.array([r["rest error start"] for r in rows])
        for j, label in enumerate(RESTS):
            print(f"| {label} | {f(np.sqrt(np.mean(er[:, j] ** 2, 0)))} | {f(np.sqrt(np.mean(es[:, j] ** 2, 0)))} |")
    print(f"\n{cost.line()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
