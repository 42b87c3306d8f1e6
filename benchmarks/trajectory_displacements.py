"""Where one movement's rest-to-rest displacement goes wrong (issue 31 point 2, eighth round): oracle substitutions.

The rest model (:func:`imulog.process.trajectory_rest_model.repetition_rests`) reads each repetition's rests from
the optimisation's start: ZUPT (zero velocity at the rests, linear velocity de-drift over each movement) on the
rotating-bias-compensated, heading-corrected acceleration, averaged over each rest
(:func:`imulog.process.trajectory_rests.rest_positions`). Its input is the displacement from one rest to the next
(home -> bottle -> mouth -> bottle -> home). For every simulated trial (``trajectory_accuracy``'s R2G trials,
subject k with seed k) this prints the RMS error (cm, x / y / z) of those displacements against the truth over the
same rest samples, with the pipeline's own inputs (``base``) and with sources of error replaced by the simulator's
truth, one at a time and all but one:

* ``tilt``: the true orientation's tilt (the estimate's heading kept): gravity leaking through a tilt error;
* ``heading``: the true orientation's heading (the estimate's tilt kept): a displacement turned about the vertical
  (``tilt`` and ``heading`` together: the true sensor-to-world orientation, with the true gravity);
* ``sensor``: the accelerometer corrected by the device's true constant bias and scale/misalignment matrix (its
  bias random walk and warm-up drift stay);
* ``rests``: the true zero-velocity mask (the body exactly still) and the true phase boundaries (segmentation's);
* ``velocity``: the true velocity wherever ZUPT assumes zero (at the rests, and linearly between the two rests'
  true velocities in the de-drift), instead of zero.

The rotating-bias compensation and the heading drift are re-estimated on each variant's inputs, as the step would.
Three more columns, with the pipeline's inputs otherwise: ``acc-calibrated`` / ``gyr-calibrated`` (everything re-run
on a sensor corrected by its true constant bias and scale / misalignment matrix, the orientation filter included),
``rest-ramp`` (the start with ``OptimizationParams.rest_ramp`` in x and y: each movement's offset a line between
its two rests' mean accelerations) and ``spread-none`` (the anchoring's ``AnchorParams.spread = "none"``: the
gyroscope's tilt through each movement, the next rest's tilt taken up only at that rest).
Then, per group of conditions, each source's share of the mean-square displacement error in x and y (the axes the
rest model uses): what replacing it alone removes, and what it adds when it is the only one left. A diagnostic, not
a method. ``--tilt`` prints only the estimated orientation's tilt error at each rest of the step's static mask and
its change from one rest to the next (deg, median and 90th percentile per condition).

    python benchmarks/trajectory_displacements.py --grid all --subjects 6 --first-subject 40 --repetitions 10
"""

from __future__ import annotations

import argparse
import itertools
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from trajectory_accuracy import RunCost, add_trial_arguments, grid_names, simulated_inputs  # noqa: E402
from trajectory_paired import CHANGES  # noqa: E402

from imulog.process import quaternion as quat  # noqa: E402
from imulog.process import trajectory_opt, trajectory_rest_model  # noqa: E402
from imulog.process.anchor_heading import heading_offset  # noqa: E402
from imulog.process.integration import cumtrapz, zupt_velocity  # noqa: E402
from imulog.process.rest_runs import static_runs  # noqa: E402
from imulog.process.rests import true_rests  # noqa: E402
from imulog.process.trajectory_opt import DEFAULT_PARAMS, merge_overlapping, repetition_windows  # noqa: E402
from imulog.process.trajectory_rests import rest_positions  # noqa: E402

SOURCES = ("tilt", "heading", "sensor", "rests", "velocity")
GROUPS = {
    "calibrated": (
        "default",
        "rotation-early",
        "curved",
        "placements",
        "pauses",
        "clock-occlusion",
        "rate-50hz",
        "rate-200hz",
    ),
    "uncalibrated": ("uncalibrated", "combined"),
    "stroke-like": ("stroke", "combined-stroke"),
    "residual-velocity": ("residual-velocity",),
}


class _Captured(Exception):
    """Raised by the spy once the start is known (the optimisation itself is not needed)."""


def trial(
    name: str, subject: int, repetitions: int, calibrate: str = "", anchor=None, acc_rests=None
) -> tuple[dict, object]:
    """One simulated trial of grid condition ``name`` as the trajectory step sees it, and its simulation;
    ``calibrate`` ``"acc"`` or ``"gyr"``: that sensor corrected by the device's true constant bias and scale /
    misalignment matrix before anything runs (the orientation filter, the anchoring and the segmentation too);
    ``anchor``: the anchoring's :class:`imulog.process.integration.AnchorParams` (None: the default's);
    ``acc_rests``: :class:`imulog.process.acc_rest_calibration.AccRestParams` (None: the default's, off)."""
    from imulog.simulate import core
    from imulog.simulate.grid import condition

    seen: dict = {}
    original = core.simulate

    def keep(*args, **kwargs):
        sim = seen["sim"] = original(*args, **kwargs)
        if calibrate:
            imu, dev = sim.recording.imus[0], sim.truth.info["device_errors"]
            raw = getattr(imu, calibrate)
            bias, matrix = (
                np.asarray(dev[f"{calibrate}_bias_{'mps2' if calibrate == 'acc' else 'rads'}"]),
                np.asarray(dev[f"{calibrate}_matrix"]),
            )
            setattr(imu, calibrate, (raw - bias) @ np.linalg.inv(matrix).T)
        return sim

    core.simulate = keep
    try:
        d = DEFAULT_PARAMS
        inputs = simulated_inputs(
            subject,
            seed=subject,
            repetitions=repetitions,
            rests=d.rests,
            anchor_params=anchor or d.anchor,
            acc_rests=acc_rests or d.acc_rests,
            **condition(name),
        )
    finally:
        core.simulate = original
    return inputs, seen["sim"]


def _with_true_velocity(v_true: np.ndarray, t_all: np.ndarray):
    """``zupt`` with the true velocity (N, 3) m/s where it assumes zero: at the static samples, and the de-drift's
    line running between the true velocities of the movement's two rests."""

    def run(acc, t, static, params):
        i0 = int(np.searchsorted(t_all, t[0]))
        vt = v_true[i0 : i0 + len(t)]
        v = zupt_velocity(acc, t, static, params)
        add = np.where(np.asarray(static, dtype=bool)[:, None], vt, 0.0)
        n = len(t)
        for s, e in static_runs(~np.asarray(static, dtype=bool)):
            a, b = max(s - 1, 0), min(e, n - 1)
            if e < n and b > a:  # de-drifted: from the true velocity at one rest to the true one at the next
                frac = (t[s:e] - t[a]) / (t[b] - t[a])
                add[s:e] = vt[a] + frac[:, None] * (vt[b] - vt[a])
            else:
                add[s:e] = vt[a]
        v = v + add
        return v, cumtrapz(v, t)

    return run


def variant(inputs: dict, sim, subs: set[str]) -> dict:
    """The trajectory inputs with the sources in ``subs`` replaced by the truth."""
    truth = sim.truth
    imu = sim.recording.imus[0]
    t = inputs["t_s"]
    acc_s = np.asarray(imu.acc, dtype=np.float64)
    rate = (len(t) - 1) / (t[-1] - t[0])
    static = true_rests(inputs["static"], inputs["acc_gate"], rate, DEFAULT_PARAMS.rests, orientation=inputs["q_gate"])
    if "sensor" in subs:
        dev = truth.info["device_errors"]
        fixed = (acc_s - np.asarray(dev["acc_bias_mps2"])) @ np.linalg.inv(np.asarray(dev["acc_matrix"])).T
    else:
        fixed = acc_s
    if "tilt" in subs:
        q = truth.imu_orientation
        acc = quat.rotate(q, fixed)
        acc[:, 2] -= truth.info["gravity_mps2"]
    else:
        q = inputs["q_world"]
        acc = np.array(inputs["acc_world"], copy=True)
        if "sensor" in subs:  # the same gravity-free acceleration of the corrected specific force
            acc += quat.rotate(q, fixed - acc_s)
            dg = np.mean(np.linalg.norm(fixed[static], axis=1)) - np.mean(np.linalg.norm(acc_s[static], axis=1))
            acc[:, 2] -= dg
    if ("tilt" in subs) != ("heading" in subs):  # one of the two: turn about the vertical onto the other's heading
        turn = heading_offset(truth.imu_orientation, inputs["q_world"]) * (1.0 if "heading" in subs else -1.0)
        rz = np.column_stack([np.cos(turn / 2), np.zeros((len(turn), 2)), np.sin(turn / 2)])
        q = quat.normalize(quat.multiply(rz, q))
        acc = quat.rotate(rz, acc)
    bounds = inputs["phase_bounds"]
    if "rests" in subs:
        static = np.asarray(truth.imu_static_mask, dtype=bool)
        t0 = float(truth.imu_t_ref_ns[0]) / 1e9
        ph = truth.phases
        b: dict[int, list] = {}
        for s, e, k in zip(ph.start_ns, ph.end_ns, ph.task_index, strict=True):
            b.setdefault(int(k), []).append((s / 1e9 - t0, e / 1e9 - t0))
        bounds = {k: np.asarray(sorted(v)) for k, v in b.items()}
    vel = np.asarray(truth.imu_velocity, dtype=np.float64) if "velocity" in subs else None
    return {"t": t, "acc": acc, "q": q, "static": static, "bounds": bounds, "vel": vel}


def start_of(inputs: dict, v: dict, ramp: bool = False) -> tuple[np.ndarray, np.ndarray, list] | None:
    """The optimisation's start (N, 3) m as :func:`imulog.process.trajectory_opt.reconstruct_repetitions` builds it
    for the rest model (compensated, heading-corrected ZUPT; ``ramp``: with ``OptimizationParams.rest_ramp`` in x and
    y), with the static mask and windows it used; None when the variant leaves no complete repetition."""
    reps, _ = merge_overlapping(repetition_windows(v["t"], v["bounds"], v["static"]))
    seen: dict = {}

    def spy(t, z, static, repetitions, *args, **kwargs):
        seen.update(z=z, static=static, reps=repetitions)
        raise _Captured

    ramp_axes = (True, True, False) if ramp else (False, False, False)
    params = replace(
        DEFAULT_PARAMS,
        optimized=replace(DEFAULT_PARAMS.optimized, rest_model="trusted-xy-test", rest_ramp=ramp_axes),
    )
    model, zupt = trajectory_rest_model.repetition_rests, trajectory_opt.zupt
    trajectory_rest_model.repetition_rests = spy
    if v["vel"] is not None:
        trajectory_opt.zupt = _with_true_velocity(v["vel"], v["t"])
    try:
        trajectory_opt.reconstruct_repetitions(
            v["t"],
            v["acc"],
            v["static"],
            reps,
            ["optimized"],
            anthropometrics=inputs["anthropometrics"],
            orientation=v["q"],
            params=params,
        )
    except _Captured:
        pass
    except ValueError:  # no complete repetition in this variant's windows (e.g. no true rest when the hand drifts)
        return None
    finally:
        trajectory_rest_model.repetition_rests, trajectory_opt.zupt = model, zupt
    return seen["z"], seen["static"], seen["reps"]


def displacement_errors(inputs: dict, v: dict, ramp: bool = False) -> np.ndarray:
    """Every complete repetition's four rest-to-rest displacement errors (M, 3) m against the truth over the same
    rest samples (``ramp``: of the start with ``OptimizationParams.rest_ramp`` in x and y)."""
    start = start_of(inputs, v, ramp)
    if start is None:
        return np.zeros((0, 3))
    z, static, reps = start
    out = []
    for rep in reps:
        if len(rep.phase_bounds_s) != 4:
            continue
        est = rest_positions(v["t"], z, static, rep)
        truth = rest_positions(v["t"], inputs["truth_pos"] - inputs["truth_pos"][rep.start], static, rep)
        d = np.diff(np.vstack([np.zeros(3), est]), axis=0) - np.diff(np.vstack([np.zeros(3), truth]), axis=0)
        out.extend(d)
    return np.asarray(out).reshape(-1, 3)


def rest_tilt_errors(inputs: dict, sim) -> tuple[np.ndarray, np.ndarray]:
    """The estimated orientation's tilt error (deg) at each rest of the step's static mask (the angle between the
    estimated and the true vertical in the sensor frame, averaged over the rest) and its change (deg) from each rest
    to the next (the angle between the two rests' error vectors' difference, small-angle)."""
    v = variant(inputs, sim, set())
    up = np.tile([0.0, 0.0, 1.0], (len(v["t"]), 1))
    est = quat.rotate_inverse(inputs["q_world"], up)
    true = quat.rotate_inverse(sim.truth.imu_orientation, up)
    errs = []
    for a, b in static_runs(v["static"]):
        e = np.mean(np.cross(true[a:b], est[a:b]), axis=0)  # small-angle tilt error vector (rad), sensor frame
        errs.append(quat.rotate(sim.truth.imu_orientation[(a + b) // 2], e))  # in the world frame
    errs = np.degrees(np.asarray(errs).reshape(-1, 3))
    return np.linalg.norm(errs, axis=1), np.linalg.norm(np.diff(errs, axis=0), axis=1)


VARIANTS = {
    "base": frozenset(),
    **{s: frozenset({s}) for s in SOURCES},
    **{f"all-{s}": frozenset(SOURCES) - {s} for s in SOURCES},
    "all": frozenset(SOURCES),
}
# the whole pipeline re-run on a calibrated sensor (the filter's tilt then absorbs no accelerometer bias)
RERUN = ("acc-calibrated", "gyr-calibrated")
# and the start as OptimizationParams.rest_ramp = (True, True, False) builds it, with the pipeline's inputs
# and with the anchoring's spread "none" (the gyroscope's tilt through each movement, no spread to the next rest)
EXTRA = (*RERUN, "rest-ramp", "spread-none")


def acc_rests_table(names: list[str], args: argparse.Namespace, params) -> None:
    """Per condition: the displacements' RMS error x / y / z (cm) with the pipeline's inputs, with the accelerometer
    corrected by :mod:`imulog.process.acc_rest_calibration` and by the device's true bias and scale; the trials
    where the estimate was applied; the RMS of the true constant bias and of the applied estimate's error, and
    the estimate's mean posterior standard deviation (m/s^2, 3D); ``params``: the
    :class:`imulog.process.acc_rest_calibration.AccRestParams`."""
    print(
        "| condition | base x/y/z (cm) | acc-rests x/y/z (cm) | acc-calibrated x/y/z (cm) | tilt at the rests, "
        "median base / acc-rests / acc-calibrated (deg) | applied | true bias (m/s^2) | estimate's error (m/s^2) | "
        "posterior sd (m/s^2) |"
    )
    print("|---|---|---|---|---|---:|---:|---:|---:|")
    for name in names:
        errs: dict[str, list] = {"base": [], "acc-rests": [], "acc-calibrated": []}
        tilt: dict[str, list] = {k: [] for k in errs}
        true_b, err_b, sd_b, applied = [], [], [], 0
        for s in range(args.first_subject, args.first_subject + args.subjects):
            inputs, sim = trial(name, s, args.repetitions)
            fixed, sim_f = trial(name, s, args.repetitions, acc_rests=params)
            cal, sim_c = trial(name, s, args.repetitions, calibrate="acc")
            for k, (inp, sm) in {
                "base": (inputs, sim),
                "acc-rests": (fixed, sim_f),
                "acc-calibrated": (cal, sim_c),
            }.items():
                errs[k].append(displacement_errors(inp, variant(inp, sm, set())))
                tilt[k].append(rest_tilt_errors(inp, sm)[0])
            rec = fixed["acc_rest_calibration"]
            b = np.asarray(sim.truth.info["device_errors"]["acc_bias_mps2"])
            true_b.append(np.linalg.norm(b))
            if rec["applied"]:
                applied += 1
                err_b.append(np.linalg.norm(np.asarray(rec["bias_mps2"]) - b))
                sd_b.append(np.linalg.norm(rec["bias_sd_mps2"]))

        def rms(v: list) -> float:
            return float(np.sqrt(np.mean(np.square(v)))) if v else float("nan")

        cells = [
            " / ".join(f"{100 * x:.2f}" for x in np.sqrt(np.nanmean(np.concatenate(errs[k]) ** 2, axis=0)))
            for k in errs
        ]
        cells.append(" / ".join(f"{np.median(np.concatenate(tilt[k])):.2f}" for k in tilt))
        print(
            f"| {name} | " + " | ".join(cells) + f" | {applied} of {args.subjects} | {rms(true_b):.3f} | "
            f"{rms(err_b):.3f} | {rms(sd_b):.3f} |",
            flush=True,
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_trial_arguments(ap)
    ap.add_argument(
        "--tilt",
        action="store_true",
        help="only the estimated orientation's tilt error at the rests and its change from rest to rest (deg)",
    )
    ap.add_argument(
        "--acc-rests",
        metavar="CHANGE",
        choices=[k for k in CHANGES if k.startswith("acc-rests")],
        help="only the displacements with the accelerometer's bias from the trial's own rests (the AccRestParams of "
        "trajectory_paired.py's change CHANGE, e.g. acc-rests) against the pipeline's and the true calibration's, "
        "and the estimated bias against the true one",
    )
    args = ap.parse_args(argv)
    names = grid_names(args.grid)
    cost = RunCost()
    if args.acc_rests:
        acc_rests_table(names, args, CHANGES[args.acc_rests][1].acc_rests)
        print(f"\n{cost.line()}")
        return 0
    if args.tilt:
        print("| condition | rests | tilt error at a rest, median / 90th pct (deg) | change to the next rest (deg) |")
        print("|---|---:|---|---|")
        for name in names:
            err, change = [], []
            for s in range(args.first_subject, args.first_subject + args.subjects):
                e, c = rest_tilt_errors(*trial(name, s, args.repetitions))
                err.append(e)
                change.append(c)
            e, c = np.concatenate(err), np.concatenate(change)
            print(
                f"| {name} | {len(e)} | {np.median(e):.2f} / {np.percentile(e, 90):.2f} | "
                f"{np.median(c):.2f} / {np.percentile(c, 90):.2f} |",
                flush=True,
            )
        print(f"\n{cost.line()}")
        return 0
    errs: dict[str, dict[str, list]] = {n: {k: [] for k in (*VARIANTS, *EXTRA)} for n in names}
    print("| condition | " + " | ".join((*VARIANTS, *EXTRA)) + " |")
    print("|---|" + "---|" * (len(VARIANTS) + len(EXTRA)))
    for name in names:
        for s in range(args.first_subject, args.first_subject + args.subjects):
            inputs, sim = trial(name, s, args.repetitions)
            for k, subs in VARIANTS.items():
                errs[name][k].append(displacement_errors(inputs, variant(inputs, sim, set(subs))))
            errs[name]["rest-ramp"].append(displacement_errors(inputs, variant(inputs, sim, set()), ramp=True))
            for k in RERUN:
                fixed, sim_k = trial(name, s, args.repetitions, calibrate=k.removesuffix("-calibrated"))
                errs[name][k].append(displacement_errors(fixed, variant(fixed, sim_k, set())))
            carried, sim_c = trial(name, s, args.repetitions, anchor=replace(DEFAULT_PARAMS.anchor, spread="none"))
            errs[name]["spread-none"].append(displacement_errors(carried, variant(carried, sim_c, set())))
        cells = [
            " / ".join(f"{100 * x:.2f}" for x in np.sqrt(np.nanmean(np.concatenate(errs[name][k]) ** 2, axis=0)))
            + ("" if all(len(e) for e in errs[name][k]) else f" ({sum(not len(e) for e in errs[name][k])} trials none)")
            for k in (*VARIANTS, *EXTRA)
        ]
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    print("\nshare of the x/y mean-square displacement error per source: removed when it alone is true / added when")
    print("it alone is left (all others true); RMS x/y (cm) with the pipeline's inputs and with every source true\n")
    print("| group | movements | RMS base (cm) | " + " | ".join((*SOURCES, *EXTRA)) + " | RMS all true (cm) |")
    print("|---|---:|---:|" + "---|" * (len(SOURCES) + len(EXTRA)) + "---:|")
    for group, members in GROUPS.items():
        members = [m for m in members if m in names]
        if not members:
            continue

        def mse(k: str, members=members) -> float:
            e = np.concatenate(list(itertools.chain.from_iterable(errs[m][k] for m in members)))
            return float(np.nanmean(e[:, :2] ** 2))

        base, every = mse("base"), mse("all")
        n = sum(len(e) for m in members for e in errs[m]["base"])
        shares = [f"{(base - mse(s)) / base:+.0%} / {(mse(f'all-{s}') - every) / base:+.0%}" for s in SOURCES]
        shares += [f"{(base - mse(k)) / base:+.0%}" for k in EXTRA]
        print(
            f"| {group} | {n} | {100 * np.sqrt(base):.2f} | " + " | ".join(shares) + f" | {100 * np.sqrt(every):.2f} |"
        )
    print(f"\n{cost.line()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
