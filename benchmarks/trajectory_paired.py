"""Paired comparison of one change to the optimized trajectory over simulated trials (issue 31 point 2).

For every trial (``trajectory_accuracy``'s simulated R2G trials, subject k with seed k, k from ``--first-subject``)
the same inputs are reconstructed before and after a change (``--change``, one of :data:`CHANGES`: the
parameters without it, and the defaults), and every repetition is paired by (subject, repetition index). Per
condition and axis (cm): the mean optimized MAE before and after, the mean paired difference after - before with its 95 % bootstrap interval, and
how many repetitions got worse / better by more than 0.5 cm (3D sum). ``--per-trial`` adds one row per trial with
ZUPT, and the target check of issue 31: optimized at most 1.0 cm on every axis and below ZUPT (of the same
pipeline: ZUPT before for before, after for after) on every axis; the closing lines count the trials meeting both,
and the after pipeline's optimized trajectory against the before pipeline's ZUPT too (what a user of the defaults
would compare it with).

    python benchmarks/trajectory_paired.py --change bias-uncertainty --grid all --subjects 6 --first-subject 30 \
        --repetitions 10 --per-trial

Changes (each: the defaults without it / the defaults, unless said): ``heading-drift`` (``OptimizationParams.heading_drift``),
``bias-uncertainty`` (the rotating-bias estimate refused at its bare physical limits, ``CheckParams.limit_z = 0``,
/ within 3 of its own standard errors), ``rest-run-mean`` (``RestParams.run_mean``: a still run that keeps
accelerating as a whole is no rest), ``heading-through-rests`` (the defaults / with ``AnchorParams.heading =
"gyroscope"``, an option: a rest keeps the heading the gyroscope carried through the movement before it), ``z-return``
(the defaults / ``OptimizationParams.return_to_start`` in z only), ``heading-and-z-return`` (the defaults / both
options), ``closure-sigma`` (without
``OptimizationParams.closure_factor`` / with 0.5, the default since 2026-12-07), ``robust-bias`` (the defaults, the rotating-bias estimate as one plain least squares, / refitted once
without the movements it cannot close, ``RotatingBiasParams.outlier_factor = 4``, an option), ``robust-bias-3`` (the same with factor 3), ``shrink-bias`` (the defaults / each global
axis's rotating-bias compensation scaled by its James-Stein share, ``RotatingBiasParams.shrink``, an option), ``robust-bias-iterated`` (factor 3, refitted
up to 20 times while the set of movements changes), ``rest-blend`` (the defaults / the start's rotating-bias
compensation in x and y blended by the rests, ``OptimizationParams.start_blend = (True, True, False)``, an option;
``rest-blend-xyz`` in z too), ``rest-chain`` (the defaults / each repetition's reference moved by where the hand
started and ended it, ``OptimizationParams.rest_chain``, an option), ``rest-model-NAME`` (the defaults / each
repetition's reference at its own rests estimated from the IMU, ``OptimizationParams.rest_model = NAME``, an option;
the names in :data:`REST_RULES`, ``trajectory_rest_model.RestRule``; ``rest-model-trusted-xy-test-ramp``: the rests from
displacements with each movement's offset ramped between its two rests), ``rest-ramp-xy`` (the defaults / that ramp
on the optimisation's start itself in x and y, ``OptimizationParams.rest_ramp``, an option; ``rest-ramp-xyz`` in z
too; ``rest-ramp-xy-rest-model``: with ``rest_model = "trusted-xy-test"``), ``issue31-session3`` (the code before this round's
default changes, ``bias-uncertainty`` and ``rest-run-mean``, / the defaults), ``issue31-options`` (the same
before / the defaults with the heading through rests and the z-only return), ``heading-restart`` (options 3 and 4
with the heading chained through the whole recording, ``AnchorParams.restart = False``, / restarted at every rest
where the trajectory step may cut a window), ``acc-rests`` (the defaults / the accelerometer's bias and sensitivity matrix estimated from the trial's own rests
before the orientation filter, ``TrajectoryParams.acc_rests``, an option; ``acc-rests-bias``: the bias alone,
``acc-rests-scale``: the bias and a per-axis scale; ``acc-rests-bias-compensation`` / ``acc-rests-no-compensation``:
with the rotating-bias compensation fitting the bias only / not at all; ``acc-rests-prior``: with it fitted under the
correction's posterior as its prior, ``RotatingBiasParams.calibration_prior``; ``acc-rests-prior-robust``: and the
movements it cannot close left out, ``outlier_factor = 3``; ``acc-rests-held-out``: with the prior, the compensation
per global axis only as far as it predicts the closures of movements left out of its fit,
``RotatingBiasParams.held_out``, and the start trusted as far as its own closure says, ``OptimizationParams.corrected_floor_m
= 0.002``), ``reference-scatter`` (the defaults / the trial-wide reference's static trust in x and y no more than the
hand's own scatter about it, ``OptimizationParams.reference_scatter = (True, True, False)``, an option;
``reference-scatter-xyz`` on z too), ``rest-tilt-acc`` (the defaults / each rest's tilt in the orientation's anchoring
from the direction the accelerometer measures over the rest, ``AnchorParams.rest_tilt = "accelerometer"``, an
option), ``rest-tilt-acc-rests`` (the defaults / that tilt on the accelerometer corrected from the trial's rests, with
``acc-rests-held-out``'s compensation and trust; ``rest-tilt-acc-rests-scatter``: and ``reference-scatter``; the
twelfth round), ``windowed-options`` (the filter's heading and the return to the start on every
axis, the defaults before 2026-12-07, / options 3 and 4 with the heading restarted where a window may be cut, the
defaults since).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from rest_gate_paired import bootstrap_ci  # noqa: E402
from trajectory_accuracy import RunCost, add_trial_arguments, evaluate_trial, grid_names, simulated_inputs  # noqa: E402

from imulog.process.trajectory_opt import DEFAULT_PARAMS, TrajectoryParams  # noqa: E402

D = DEFAULT_PARAMS
CHANGES: dict[str, tuple[TrajectoryParams, TrajectoryParams]] = {
    "heading-drift": (replace(D, optimized=replace(D.optimized, heading_drift=False)), D),
    "bias-uncertainty": (replace(D, checks=replace(D.checks, limit_z=0.0)), D),
    "rest-run-mean": (replace(D, rests=replace(D.rests, run_mean=False)), D),
    "heading-through-rests": (D, replace(D, anchor=replace(D.anchor, heading="gyroscope"))),
    "z-return": (D, replace(D, optimized=replace(D.optimized, return_to_start=(False, False, True)))),
    "heading-and-z-return": (
        D,
        replace(
            D,
            anchor=replace(D.anchor, heading="gyroscope"),
            optimized=replace(D.optimized, return_to_start=(False, False, True)),
        ),
    ),
    "closure-sigma": (replace(D, optimized=replace(D.optimized, closure_factor=None)), D),
    "robust-bias": (D, replace(D, rotating_bias=replace(D.rotating_bias, outlier_factor=4.0))),
    "robust-bias-3": (D, replace(D, rotating_bias=replace(D.rotating_bias, outlier_factor=3.0))),
    "shrink-bias": (D, replace(D, rotating_bias=replace(D.rotating_bias, shrink=True))),
    "rest-blend": (D, replace(D, optimized=replace(D.optimized, start_blend=(True, True, False)))),
    "rest-blend-xyz": (D, replace(D, optimized=replace(D.optimized, start_blend=(True, True, True)))),
    "rest-chain": (D, replace(D, optimized=replace(D.optimized, rest_chain=True))),
    "rest-ramp-xy": (D, replace(D, optimized=replace(D.optimized, rest_ramp=(True, True, False)))),
    "rest-ramp-xyz": (D, replace(D, optimized=replace(D.optimized, rest_ramp=(True, True, True)))),
    "rest-ramp-xy-rest-model": (
        D,
        replace(D, optimized=replace(D.optimized, rest_ramp=(True, True, False), rest_model="trusted-xy-test")),
    ),
    "robust-bias-iterated": (
        D,
        replace(D, rotating_bias=replace(D.rotating_bias, outlier_factor=3.0, outlier_refits=20)),
    ),
    "heading-restart": (
        replace(
            D,
            anchor=replace(D.anchor, heading="gyroscope", restart=False),
            optimized=replace(D.optimized, return_to_start=(False, False, True)),
        ),
        replace(
            D,
            anchor=replace(D.anchor, heading="gyroscope", restart=True),
            optimized=replace(D.optimized, return_to_start=(False, False, True)),
        ),
    ),
    "issue31-options": (
        replace(D, checks=replace(D.checks, limit_z=0.0), rests=replace(D.rests, run_mean=False)),
        replace(
            D,
            anchor=replace(D.anchor, heading="gyroscope"),
            optimized=replace(D.optimized, return_to_start=(False, False, True)),
        ),
    ),
    "windowed-options": (
        replace(D, anchor=replace(D.anchor, heading="filter"), optimized=replace(D.optimized, return_to_start=True)),
        replace(
            D,
            anchor=replace(D.anchor, heading="gyroscope", restart=True),
            optimized=replace(D.optimized, return_to_start=(False, False, True)),
        ),
    ),
    "issue31-session3": (
        replace(
            D,
            checks=replace(D.checks, limit_z=0.0),
            rests=replace(D.rests, run_mean=False),
        ),
        D,
    ),
}
# the accelerometer's bias and sensitivity matrix from the trial's own rests before the orientation filter
# (AccRestParams' defaults); -bias: the bias alone (identifiable below 0.05 m/s^2), -scale: with a per-axis scale
ACC_RESTS = replace(D.acc_rests, enabled=True)
CHANGES.update(
    {
        "acc-rests": (D, replace(D, acc_rests=ACC_RESTS)),
        "acc-rests-bias": (D, replace(D, acc_rests=replace(ACC_RESTS, model="bias", max_bias_sd_mps2=0.05))),
        "acc-rests-scale": (D, replace(D, acc_rests=replace(ACC_RESTS, model="scale"))),
        # the optimisation's start on the corrected accelerometer: the rotating-bias compensation fits the bias only
        # (3 unknowns), or not at all (min_movements above any trial's count)
        "acc-rests-bias-compensation": (
            D,
            replace(D, acc_rests=ACC_RESTS, rotating_bias=replace(D.rotating_bias, gravity_coupled=False)),
        ),
        "acc-rests-no-compensation": (
            D,
            replace(D, acc_rests=ACC_RESTS, rotating_bias=replace(D.rotating_bias, min_movements=10**9)),
        ),
        # the compensation fitted with the rest calibration's posterior as its prior (second half of the round)
        "acc-rests-prior": (
            D,
            replace(D, acc_rests=ACC_RESTS, rotating_bias=replace(D.rotating_bias, calibration_prior=True)),
        ),
        # with it, the movements the fit cannot close left out (outlier_factor 3; development sets only)
        "acc-rests-prior-robust": (
            D,
            replace(
                D,
                acc_rests=ACC_RESTS,
                rotating_bias=replace(D.rotating_bias, calibration_prior=True, outlier_factor=3.0),
            ),
        ),
        # tenth round: the compensation per global axis as far as it predicts held-out movements' closures, and the
        # start trusted as far as its own closure says (no 6-mm / 0.02-m/s floors) on the corrected accelerometer
        "acc-rests-held-out": (
            D,
            replace(
                D,
                acc_rests=ACC_RESTS,
                rotating_bias=replace(D.rotating_bias, calibration_prior=True, held_out=True),
                optimized=replace(D.optimized, corrected_floor_m=0.002),
            ),
        ),
    }
)
# eleventh round: the trial-wide reference's static trust per axis no more than the hand's own scatter about it
CHANGES["reference-scatter"] = (D, replace(D, optimized=replace(D.optimized, reference_scatter=(True, True, False))))
CHANGES["reference-scatter-xyz"] = (D, replace(D, optimized=replace(D.optimized, reference_scatter=(True, True, True))))
# issue 31 point 2, subject 44: each rest's tilt from the accelerometer's direction instead of the filter's mean
CHANGES["rest-tilt-acc"] = (D, replace(D, anchor=replace(D.anchor, rest_tilt="accelerometer")))
# twelfth round: that tilt on the accelerometer corrected from the trial's rests (acc-rests-held-out), so a rest's
# direction is gravity's; -scatter: and the reference trusted no more than the hand's scatter (reference-scatter)
REST_TILT_ACC_RESTS = replace(CHANGES["acc-rests-held-out"][1], anchor=replace(D.anchor, rest_tilt="accelerometer"))
CHANGES["rest-tilt-acc-rests"] = (D, REST_TILT_ACC_RESTS)
CHANGES["rest-tilt-acc-rests-scatter"] = (
    D,
    replace(
        REST_TILT_ACC_RESTS, optimized=replace(REST_TILT_ACC_RESTS.optimized, reference_scatter=(True, True, False))
    ),
)
# each rule of OptimizationParams.rest_model (trajectory_rest_model.RestRule) against the defaults: rest-model-NAME
REST_RULES = (
    "waypoints",
    "replace",
    "posterior",
    "posterior-data",
    "capped",
    "capped-tau",
    "capped-tau-xy",
    "trusted",
    "trusted-xy",
    "trusted-xy-nobias",
    "trusted-xy-test",
    "trusted-xy-test-gated",
    "trusted-posterior-xy",
    "trusted-xy-test-ramp",
)
CHANGES.update(
    {f"rest-model-{name}": (D, replace(D, optimized=replace(D.optimized, rest_model=name))) for name in REST_RULES}
)


def pipeline_inputs(
    name: str, subject: int, repetitions: int, params: TrajectoryParams, step_orientation: bool = False
) -> dict:
    """The trajectory inputs of the simulated trial of condition ``name`` (subject and seed ``subject``) as the
    pipeline of ``params`` builds them (its rests gate, anchoring and accelerometer correction); ``step_orientation``:
    the filter over dropped samples as the orientation step runs it (``simulated_inputs``)."""
    from imulog.simulate.grid import condition

    return simulated_inputs(
        subject,
        seed=subject,
        repetitions=repetitions,
        rests=params.rests,
        anchor_params=params.anchor,
        acc_rests=params.acc_rests,
        step_orientation=step_orientation,
        **condition(name),
    )


def trial_errors(
    name: str, subject: int, repetitions: int, change: str = "heading-drift", step_orientation: bool = False
) -> dict[str, dict[int, list[float]]]:
    """{"zupt" | "zupt_after" | "before" | "after": {repetition: [MAE x, y, z] cm}} of one trial (``zupt``:
    ZUPT with the before parameters, against which the targets are checked; ``zupt_after``: with the after
    ones)."""
    BEFORE, AFTER = CHANGES[change]  # noqa: N806
    inputs = {}
    for label, params in (("before", BEFORE), ("after", AFTER)):  # the anchoring is part of the inputs
        same = AFTER.anchor == BEFORE.anchor and AFTER.rests == BEFORE.rests and AFTER.acc_rests == BEFORE.acc_rests
        if label == "after" and same:
            inputs[label] = inputs["before"]
            continue
        inputs[label] = pipeline_inputs(name, subject, repetitions, params, step_orientation)
    out = {}
    for label, params in (("before", BEFORE), ("after", AFTER)):
        records, _, _ = evaluate_trial(inputs[label], ("zupt", "optimized"), params)
        for m, key in (("zupt", "zupt" if label == "before" else "zupt_after"), ("optimized", label)):
            out[key] = {r["repetition"]: [r[a]["mae_cm"] for a in "xyz"] for r in records[m]}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--change", choices=list(CHANGES), default="heading-drift")
    add_trial_arguments(ap, grid="all", first_subject=20)
    ap.add_argument("--per-trial", action="store_true")
    ap.add_argument(
        "--chain-rest-s",
        type=float,
        help="shortest rest (s) where the heading chain restarts (TrajectoryWindows.chain_rest_s, default 30)",
    )
    ap.add_argument(
        "--step-orientation",
        action="store_true",
        help="the orientation filter over dropped samples as the orientation step runs it (a uniform grid); "
        "default: every sample one nominal period after the last, as every published figure",
    )
    args = ap.parse_args(argv)
    if args.chain_rest_s is not None:  # read by trajectory_accuracy._static_for_anchor
        from imulog.steps.trajectory_windows import TrajectoryWindows

        TrajectoryWindows.chain_rest_s = args.chain_rest_s

    conditions = grid_names(args.grid)
    f = lambda v: " / ".join(f"{x:.2f}" for x in v)  # noqa: E731
    g = lambda v: " / ".join(f"{x:+.2f}" for x in v)  # noqa: E731
    cost = RunCost()
    table = [
        "| condition | pairs | before x/y/z (cm) | after x/y/z (cm) | mean after - before (cm) | 95 % CI (cm) | "
        "worse / better by > 0.5 cm | zupt before / after x/y/z (cm) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    trials = [
        "| trial | zupt before x/y/z (cm) | before x/y/z (cm) | zupt after x/y/z (cm) | after x/y/z (cm) | "
        "before: <= 1 cm / < zupt | after: <= 1 cm / < zupt |",
        "|---|---|---|---|---|---|---|",
    ]
    counts = {"before": [0, 0, 0], "after": [0, 0, 0]}  # y > 1 cm, any axis > 1 cm, any axis >= zupt
    both = {"before": 0, "after": 0, "after against the before pipeline's ZUPT": 0}  # <= 1 cm and below ZUPT
    for name in conditions:
        a_all, b_all, z_all, y_all = [], [], [], []
        for s in range(args.first_subject, args.first_subject + args.subjects):
            e = trial_errors(name, s, args.repetitions, args.change, args.step_orientation)
            keys = sorted(set(e["before"]) & set(e["after"]) & set(e["zupt"]) & set(e["zupt_after"]))
            a = np.array([e["before"][k] for k in keys])
            b = np.array([e["after"][k] for k in keys])
            z = np.array([e["zupt"][k] for k in keys])
            za = np.array([e["zupt_after"][k] for k in keys])
            a_all.append(a)
            b_all.append(b)
            z_all.append(z)
            y_all.append(za)
            ok = []
            for label, v, zm in (("before", a.mean(0), z.mean(0)), ("after", b.mean(0), za.mean(0))):
                counts[label][0] += int(v[1] > 1.0)
                counts[label][1] += int(np.any(v > 1.0))
                counts[label][2] += int(np.any(v >= zm))
                ok.append(f"{'yes' if np.all(v <= 1.0) else 'no'} / {'yes' if np.all(v < zm) else 'no'}")
                both[label] += int(np.all(v <= 1.0) and np.all(v < zm))
            both["after against the before pipeline's ZUPT"] += int(
                np.all(b.mean(0) <= 1.0) and np.all(b.mean(0) < z.mean(0))
            )
            trials.append(
                f"| {name} s{s} | {f(z.mean(0))} | {f(a.mean(0))} | {f(za.mean(0))} | {f(b.mean(0))} | {ok[0]} | "
                f"{ok[1]} |"
            )
            if args.per_trial:
                print(trials[-1], file=sys.stderr, flush=True)
        a, b = np.vstack(a_all), np.vstack(b_all)
        d = b - a
        lo, hi = bootstrap_ci(d)
        ci = " / ".join(f"[{x:+.2f}, {y:+.2f}]" for x, y in zip(lo, hi, strict=True))
        s3 = d.sum(axis=1)
        table.append(
            f"| {name} | {len(d)} | {f(a.mean(0))} | {f(b.mean(0))} | {g(d.mean(0))} | {ci} | "
            f"{(s3 > 0.5).sum()} / {(s3 < -0.5).sum()} | {f(np.vstack(z_all).mean(0))} / {f(np.vstack(y_all).mean(0))} |"
        )
        print(table[-1], file=sys.stderr, flush=True)
    print("\n".join(table))
    if args.per_trial:
        print()
        print("\n".join(trials))
    n = len(conditions) * args.subjects
    for label, (y1, any1, zupt) in counts.items():
        print(f"{label}: y > 1 cm on {y1} of {n} trials, some axis > 1 cm on {any1}, some axis >= ZUPT on {zupt}")
    print("both targets (every axis <= 1 cm and below ZUPT): " + ", ".join(f"{k} {v} of {n}" for k, v in both.items()))
    print(f"\n{cost.line()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
