"""Accuracy of every trajectory method on simulated R2G trials (the thesis's Table 3.1, with ground truth).

Pipeline per trial, all with imulog's own code except where noted:

1. ``imulog.simulate.simulate("r2g", subject=s, seed=seed)`` (default, realistic IMU and Vicon noise);
2. IMU time stamps mapped to the reference clock with the simulator's true ``imulog.alignment`` record;
3. orientation: ``--orientation estimated`` (default) runs ``imulog.process.orientation`` (VQF offline,
   6D) and rotates its global frame into the world with a constant rotation fitted to the reference
   orientation over the trial (what the alignment step does against the Vicon cluster);
   ``--orientation truth`` uses the true orientation (an upper bound);
4. static mask and phases: ``--segmentation estimated`` (default) runs ``imulog.process.segmentation``
   (DynAMoS + event correction); ``--segmentation truth`` uses the true phases;
5. every method per repetition (:func:`imulog.process.trajectory_opt.reconstruct_repetitions`), waypoints
   from the anthropometrics record plus ZUPT medians (never from the optical data);
6. errors against the true cluster-origin position at the IMU samples, per repetition.

    python benchmarks/trajectory_accuracy.py --subjects 3 --repetitions 25 --seed 0

Accuracy grid (issue 19): the conditions of :mod:`imulog.simulate.grid`, one row per condition (MAE per axis of
``zupt``, ``zupt_bias`` and ``optimized``, mean over repetitions of ``--subjects`` trials, subject k with seed k):

    python benchmarks/trajectory_accuracy.py --grid all --subjects 2 --repetitions 8

``--first-subject N --per-trial`` runs other trials (subjects and seeds N, N+1, ...) one row each;
``--fixed-velocity-sigma`` is the optimisation before issue 31 (no per-axis velocity weight).
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from typing import Any

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.alignment import device_to_reference
from imulog.process.evaluation import aggregate, format_table, trajectory_errors
from imulog.process.rests import RestParams, true_rests
from imulog.process.trajectory_opt import (
    DEFAULT_PARAMS,
    METHODS,
    TrajectoryParams,
    merge_overlapping,
    reconstruct_repetitions,
    repetition_windows,
)


class RunCost:
    """Wall and CPU (user+sys) time since it was made, for a benchmark's closing line (the machine is shared, so
    both are printed)."""

    def __init__(self) -> None:
        self.t0, self.r0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)

    def line(self) -> str:
        """``"<wall> s wall, <cpu> s CPU (user+sys)"`` since construction (s, rounded)."""
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        cpu = (r1.ru_utime - self.r0.ru_utime) + (r1.ru_stime - self.r0.ru_stime)
        return f"{time.perf_counter() - self.t0:.0f} s wall, {cpu:.0f} s CPU (user+sys)"


def add_trial_arguments(ap: argparse.ArgumentParser, *, grid: str = "default", first_subject: int = 40) -> None:
    """The simulated trials a trajectory benchmark runs on: ``--grid`` (condition names or ``all``), ``--subjects``,
    ``--first-subject`` (subject k simulated with seed k) and ``--repetitions``; :func:`grid_names` reads ``--grid``."""
    ap.add_argument("--grid", nargs="+", default=[grid], help="accuracy-grid conditions (names or 'all')")
    ap.add_argument("--subjects", type=int, default=6)
    ap.add_argument("--first-subject", type=int, default=first_subject)
    ap.add_argument("--repetitions", type=int, default=10)


def grid_names(grid: list[str]) -> list[str]:
    """The condition names ``--grid`` asks for (``all``: every condition of :mod:`imulog.simulate.grid`)."""
    from imulog.simulate.grid import CONDITIONS

    return list(CONDITIONS) if grid == ["all"] else list(grid)


def _phase_params(repetitions: int, static: str = "movements"):
    """The phases step's parameters for a trial of ``repetitions``; ``static``: its zero-velocity mask
    (``"movements"``, the default, or ``"gyro-norm"``: the angular rate alone)."""
    from imulog.process.segmentation.pipeline import PhaseParams
    from imulog.process.segmentation.repetitions import RepetitionParams

    return PhaseParams(repetitions=RepetitionParams(n_repetitions=repetitions), static=static)


def _static_for_anchor(
    imu, rate: float, repetitions: int, static: str = "movements", t_s: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The phases step's zero-velocity mask (what the trajectory step anchors the orientation to) and the rests
    where the trajectory step may cut a window (the heading chain restarts there: rests of at least
    ``TrajectoryWindows.chain_rest_s`` outside the repetitions; ``t_s`` the sample times, s)."""
    from imulog.process.anchor_heading import restart_rests
    from imulog.process.segmentation.pipeline import segment_phases
    from imulog.steps.trajectory_windows import TrajectoryWindows

    res = segment_phases(imu.gyr, rate, _phase_params(repetitions, static), imu.acc)
    mask = np.asarray(res.static, dtype=bool)
    t = np.arange(len(mask)) / rate if t_s is None else t_s
    spans: dict[int, tuple[float, float]] = {}
    for s, e, k in zip(res.phases.start, res.phases.end, res.phases.repetition, strict=True):
        lo, hi = spans.get(int(k), (np.inf, -np.inf))
        spans[int(k)] = (min(lo, t[int(s)]), max(hi, t[min(int(e), len(t) - 1)]))
    return mask, restart_rests(mask, t, TrajectoryWindows.chain_rest_s, [v for k, v in spans.items() if k >= 0])


def simulated_inputs(
    subject: int,
    *,
    seed: int = 0,
    repetitions: int = 25,
    orientation: str = "estimated",
    segmentation: str = "estimated",
    anchor: bool = True,
    rests: RestParams | None = DEFAULT_PARAMS.rests,
    static: str = "movements",
    anchor_params: Any = None,
    acc_rests: Any = None,
    step_orientation: bool = False,
    **overrides: Any,
) -> dict[str, Any]:
    """Simulate one R2G trial and build the trajectory inputs on the reference clock in the world frame.

    ``rests``: the trajectory step's accelerometer gate (None: the segmentation's static mask as it is). As in
    the step, it is applied to the filter's gravity-free acceleration, and the orientation is anchored at the
    gated rests only (``acc_gate`` holds that acceleration for :func:`evaluate_trial`). ``static``: the phases
    step's zero-velocity mask (``"gyro-norm"``: the angular rate alone, many still-gyroscope translations).
    ``anchor_params``: :class:`imulog.process.integration.AnchorParams` of the anchoring (None: the default).
    ``acc_rests``: :class:`imulog.process.acc_rest_calibration.AccRestParams` (None or not enabled: the raw
    accelerometer); enabled, the accelerometer's bias (and scale) is estimated from the phases step's rests and the
    corrected accelerometer feeds the orientation filter and the acceleration (the record under
    ``"acc_rest_calibration"``). ``step_orientation``: the filter sees the IMU's time stamps as the orientation step
    does (dropped samples: run on a uniform grid and interpolated back); off, the default and every published figure,
    it takes every sample as one nominal period after the last.
    """
    from imulog.simulate.core import simulate

    sim = simulate("r2g", subject=subject, seed=seed, repetitions=repetitions, **overrides)
    imu = sim.recording.imus[0]
    truth = sim.truth
    t_ref_ns = device_to_reference(imu.t_ns, truth.alignment)
    t_s = (np.asarray(t_ref_ns, dtype=np.float64) - float(t_ref_ns[0])) / 1e9
    rate = (len(t_s) - 1) / t_s[-1]
    q_true = truth.imu_orientation
    calibration_record: dict[str, Any] | None = None
    acc_cal = None
    if orientation == "truth":
        q_world = q_true
        acc_world = quat.rotate(q_true, imu.acc)
        acc_world[:, 2] -= truth.info["gravity_mps2"]
        acc_gate, q_gate = acc_world, q_true
    elif orientation == "estimated":
        from imulog.process.orientation import estimate_orientation, gravity_free_acceleration

        acc_imu = imu.acc
        if anchor or (acc_rests is not None and acc_rests.enabled):
            anchor_static, restart = _static_for_anchor(imu, rate, repetitions, static, t_s)
        if acc_rests is not None and acc_rests.enabled:  # the accelerometer from the trial's own rests
            from imulog.process.acc_rest_calibration import estimate as estimate_acc

            acc_cal = estimate_acc(acc_imu, imu.gyr, t_s, anchor_static, acc_rests)
            calibration_record = acc_cal.as_dict()
            acc_imu = acc_cal.apply(acc_imu)
        est = estimate_orientation(imu.gyr, acc_imu, rate, t_ns=imu.t_ns if step_orientation else None)
        q_est = q_gate = est.quat
        acc_gate = gravity_free_acceleration(q_est, acc_imu, est.static)
        if anchor:  # what the trajectory step does with the gyroscope (TrajectoryParams.anchor)
            from imulog.process.integration import AnchorParams, rest_anchored_orientation

            if rests is not None:  # the step anchors at true rests only
                anchor_static = true_rests(anchor_static, acc_gate, rate, rests, orientation=q_gate)
            q_est = rest_anchored_orientation(
                q_est, imu.gyr, t_s, anchor_static, anchor_params or AnchorParams(), restart, acc_imu
            )
        acc_g = gravity_free_acceleration(q_est, acc_imu, est.static)
        q_g2w = quat.average(quat.multiply(q_true, quat.conjugate(q_est)))
        acc_world = quat.rotate(q_g2w, acc_g)
        q_world = quat.multiply(q_g2w, q_est)
    else:
        raise ValueError(f"orientation must be 'estimated' or 'truth', got {orientation!r}")
    t0_ref_s = float(t_ref_ns[0]) / 1e9
    bounds: dict[int, list[tuple[float, float]]] = {}
    if segmentation == "truth":
        ph = truth.phases
        for s, e, k in zip(ph.start_ns, ph.end_ns, ph.task_index, strict=True):
            bounds.setdefault(int(k), []).append((s / 1e9 - t0_ref_s, e / 1e9 - t0_ref_s))
        static = truth.imu_static_mask.copy()
    elif segmentation == "estimated":
        from imulog.process.segmentation.pipeline import segment_phases

        res = segment_phases(imu.gyr, rate, _phase_params(repetitions, static), imu.acc)
        ph = res.phases
        for s, e, k in zip(ph.start, ph.end, ph.repetition, strict=True):
            bounds.setdefault(int(k), []).append((t_s[int(s)], t_s[min(int(e), len(t_s) - 1)]))
        static = np.asarray(res.static, dtype=bool)
    else:
        raise ValueError(f"segmentation must be 'estimated' or 'truth', got {segmentation!r}")
    phase_bounds = {k: np.asarray(sorted(v)) for k, v in bounds.items()}
    return {
        "t_s": t_s,
        "acc_world": acc_world,
        "acc_gate": acc_gate,
        "q_gate": q_gate,
        "q_world": q_world,
        "static": static,
        "phase_bounds": phase_bounds,
        "truth_pos": truth.imu_position,
        "anthropometrics": sim.recording.metadata.get("imulog.anthropometrics", {}),
        "subject": subject,
        "acc_rest_calibration": calibration_record,
        "acc_calibration": acc_cal,
    }


def evaluate_trial(inputs: dict[str, Any], methods=METHODS, params: TrajectoryParams = DEFAULT_PARAMS):
    """Per-repetition error records {method: [trajectory_errors(...), ...]} and per-method seconds."""
    t_s = inputs["t_s"]
    # velocity resets only at true rests (the accelerometer agrees), as the trajectory step does
    rate = (len(t_s) - 1) / (t_s[-1] - t_s[0])
    acc_gate = inputs.get("acc_gate", inputs["acc_world"])
    static = true_rests(inputs["static"], acc_gate, rate, params.rests, orientation=inputs.get("q_gate"))
    reps, _ = merge_overlapping(repetition_windows(t_s, inputs["phase_bounds"], static))
    seconds: dict[str, float] = {}
    recon: dict[str, np.ndarray] = {}
    for m in methods:
        t0 = time.perf_counter()
        recon.update(
            reconstruct_repetitions(
                t_s,
                inputs["acc_world"],
                static,
                reps,
                [m],
                anthropometrics=inputs["anthropometrics"],
                orientation=inputs["q_world"],
                params=params,
                acc_calibration=inputs.get("acc_calibration"),
            )
        )
        seconds[m] = (time.perf_counter() - t0) / max(len(reps), 1)
    records: dict[str, list[dict]] = {m: [] for m in methods}
    for rep in reps:
        sl = slice(rep.start, rep.stop)
        for m in methods:
            if np.all(np.isnan(recon[m][sl])):
                continue
            r = trajectory_errors(recon[m][sl], inputs["truth_pos"][sl])
            r.update(subject=inputs["subject"], repetition=rep.index)
            records[m].append(r)
    return records, seconds, len(reps)


GRID_METHODS = ("zupt", "zupt_bias", "optimized")


def grid_rows(
    conditions,
    subjects: range,
    repetitions: int,
    methods=GRID_METHODS,
    params: TrajectoryParams = DEFAULT_PARAMS,
    per_trial: bool = False,
) -> list[dict[str, Any]]:
    """Per condition and method: mean MAE per axis (cm) over every repetition of the trials (subject k, seed k);
    ``per_trial``: one row per trial (condition ``name s<k>``)."""
    from imulog.simulate.grid import condition

    rows = []
    for name in conditions:
        groups: dict[str, dict[str, list[dict]]] = {}
        for s in subjects:
            inputs = simulated_inputs(s, seed=s, repetitions=repetitions, rests=params.rests, **condition(name))
            records, _, _ = evaluate_trial(inputs, methods, params)
            recs = groups.setdefault(f"{name} s{s}" if per_trial else name, {m: [] for m in methods})
            for m in methods:
                recs[m].extend(records[m])
        for label, recs in groups.items():
            for m in methods:
                mae = np.array([[r[a]["mae_cm"] for a in "xyz"] for r in recs[m]])
                rows.append({"condition": label, "method": m, "n": len(mae), "mae_cm": mae.mean(axis=0).tolist()})
    return rows


def print_grid(rows: list[dict[str, Any]]) -> None:
    methods = list(dict.fromkeys(r["method"] for r in rows))
    print(
        "| condition | reps | " + " | ".join(f"{m} x/y/z (cm)" for m in methods) + " | optimized <= 1 cm and <= zupt |"
    )
    print("|" + "---|" * (len(methods) + 3))
    by = {(r["condition"], r["method"]): r for r in rows}
    for name in dict.fromkeys(r["condition"] for r in rows):
        cells = [" / ".join(f"{v:.2f}" for v in by[(name, m)]["mae_cm"]) for m in methods]
        ok = ""
        if "optimized" in methods and "zupt" in methods:
            o, z = np.array(by[(name, "optimized")]["mae_cm"]), np.array(by[(name, "zupt")]["mae_cm"])
            ok = "yes" if np.all(o <= 1.0) and np.all(o <= z) else ("<= zupt only" if np.all(o <= z) else "no")
        print(f"| {name} | {by[(name, methods[0])]['n']} | " + " | ".join(cells) + f" | {ok} |")
    means = {m: np.mean([r["mae_cm"] for r in rows if r["method"] == m], axis=0) for m in methods}
    print(
        "| **mean over conditions** | | "
        + " | ".join(" / ".join(f"{v:.2f}" for v in means[m]) for m in methods)
        + " | |"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--subjects", type=int, default=3)
    ap.add_argument("--repetitions", type=int, default=25)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--orientation", choices=["estimated", "truth"], default="estimated")
    ap.add_argument("--segmentation", choices=["estimated", "truth"], default="estimated")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--residual-velocity", type=float, default=0.0, help="simulator residual_velocity_mps")
    ap.add_argument("--json", type=str, default=None, help="also write the table and records here")
    ap.add_argument("--grid", nargs="+", default=None, help="accuracy-grid conditions (names or 'all')")
    ap.add_argument("--first-subject", type=int, default=0, help="grid: subjects (and seeds) from this one")
    ap.add_argument("--per-trial", action="store_true", help="grid: one row per trial instead of per condition")
    ap.add_argument(
        "--fixed-velocity-sigma",
        action="store_true",
        help="optimisation: the fixed sigma_data_mps on every trial (before issue 31's velocity_from_static)",
    )
    ap.add_argument(
        "--no-rest-gate",
        action="store_true",
        help="rests from the segmentation alone (before issue 32's accelerometer gate)",
    )
    args = ap.parse_args(argv)
    params = DEFAULT_PARAMS
    if args.no_rest_gate:
        from dataclasses import replace

        from imulog.process.rests import RestParams

        params = replace(DEFAULT_PARAMS, rests=RestParams(enabled=False))
    if args.fixed_velocity_sigma:
        from dataclasses import replace

        params = replace(params, optimized=replace(params.optimized, velocity_from_static=False))
    if args.grid:
        from imulog.simulate.grid import CONDITIONS

        t0 = time.perf_counter()
        rows = grid_rows(
            list(CONDITIONS) if args.grid == ["all"] else args.grid,
            range(args.first_subject, args.first_subject + args.subjects),
            args.repetitions,
            params=params,
            per_trial=args.per_trial,
        )
        print_grid(rows)
        print(f"\n{time.perf_counter() - t0:.0f} s wall")
        if args.json:
            with open(args.json, "w") as fh:
                json.dump({"args": vars(args), "grid": rows}, fh, indent=1)
        return 0
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    all_records: dict[str, list[dict]] = {m: [] for m in methods}
    timing: dict[str, list[float]] = {m: [] for m in methods}
    for s in range(args.subjects):
        inputs = simulated_inputs(
            s,
            seed=args.seed,
            repetitions=args.repetitions,
            orientation=args.orientation,
            segmentation=args.segmentation,
            residual_velocity_mps=args.residual_velocity,
            rests=params.rests,
        )
        records, seconds, n = evaluate_trial(inputs, methods, params)
        for m in methods:
            all_records[m].extend(records[m])
            timing[m].append(seconds[m])
        print(f"subject {s}: {n} repetitions", file=sys.stderr)
    table = aggregate(all_records)
    print(f"# imulog trajectory accuracy: {args.subjects} subjects x {args.repetitions} repetitions, seed {args.seed},")
    print(
        f"# orientation {args.orientation}, segmentation {args.segmentation}; MAE per axis, mean±std over repetitions"
    )
    print(format_table(table))
    print("# per-repetition time (ms): " + ", ".join(f"{m} {1000 * np.mean(timing[m]):.1f}" for m in methods))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"args": vars(args), "table": table, "records": all_records}, fh, indent=1, default=float)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
