"""Moving seconds per minute from ``imulog process phases`` on simulated days at home, with and without step 9.

    python benchmarks/home_phases_accuracy.py                      # 3 daytime hours, seeds 0-1
    python benchmarks/home_phases_accuracy.py --hours 2 --seeds 0 1 2

Step 9 of the phase boundaries (the speed profile of a phase's last part, ``HandParams.profile_rest_s``, issue 31)
was validated on the drinking task's grid. This measures what it does on daily-life movements: each seed is a
recording of ``--hours`` from ``--start`` simulated by :mod:`imulog.simulate.home` (whose truth is the moving
seconds per minute), written as a ``.cwa`` and converted as ``imulog simulate home`` and ``imulog convert`` do, then
``process phases`` (:func:`imulog.steps.phases.run_phases`, the trial's own protocol: ``movements``) runs on one
copy with step 9 forced on (since issue 31's ninth round the step runs it on the drinking task only,
:func:`imulog.process.segmentation.pipeline.hand_params`; this lifts that) and on another with step 9 off (the
step's default on these recordings). Moving seconds per minute = the overlap of the phases with each minute. Prints, per seed and run, the
mean absolute error per minute (s), the mean error (s, detected - true), the total moving time against the truth,
how many minutes are off by more than 1 s, and the CPU time (user + sys, s) of the step; then the two runs
against each other (the minutes where they differ). CPU time is of this process (``resource.getrusage``), after
a first, untimed run on a 3-minute recording (imports and compiled code).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np


def cpu_s() -> float:
    """User + system CPU time (s) of this process so far."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def moving_per_minute(path: Path, minutes: int) -> np.ndarray:
    """Seconds per minute covered by the trial's ``/derived/phases`` intervals (minute 0 starts at the first
    IMU sample)."""
    from imulog.archive import TrialReader

    with TrialReader(path) as trial:
        imu = next(t for t in trial.topics() if t.startswith("/imu/"))
        t0 = int(trial.channel(imu).start_ns)
        phases = trial.read("/derived/phases/" + imu.split("/")[-1])
    out = np.zeros(minutes)
    for s, e in zip(np.asarray(phases.start_ns), np.asarray(phases.end_ns), strict=True):
        a, b = (int(s) - t0) * 1e-9, (int(e) - t0) * 1e-9
        for m in range(max(int(a // 60), 0), min(int(b // 60) + 1, minutes)):
            out[m] += max(0.0, min(b, 60.0 * (m + 1)) - max(a, 60.0 * m))
    return out


def one_recording(seed: int, hours: float, start: str, folder: Path) -> tuple[Path, np.ndarray]:
    """A converted simulated recording (``.mcap``) and its truth (moving s per minute)."""
    from imulog.cli import cli
    from imulog.simulate.home import HomeParams, write_home_cwa

    params = HomeParams(days=hours / 24.0, seed=seed, start=start)
    cwa = folder / f"home_{seed}.cwa"
    truth = write_home_cwa(cwa, params)
    mcap = folder / f"home_{seed}.mcap"
    try:
        cli.main(["convert", str(cwa), "-o", str(mcap)], standalone_mode=False)
    except SystemExit as e:  # a failed convert
        raise RuntimeError(f"imulog convert {cwa} failed ({e.code})") from None
    return mcap, np.asarray(truth, dtype=float)


def run(path: Path, step9: bool) -> float:
    """``process phases`` on ``path`` with the trial's own parameters, step 9 forced on (``step9``: the step's
    restriction to the drinking task lifted) or off (``profile_rest_s = 0``); CPU s of the step."""
    import imulog.process.segmentation.pipeline as pipeline
    from imulog.archive import TrialReader
    from imulog.steps.phases import params_for_trial, run_phases

    with TrialReader(path) as trial:
        params = params_for_trial(trial.metadata.get("imulog.trial", {}))
    if not step9:
        params = replace(params, hand=replace(params.hand, profile_rest_s=0.0))
    chosen = pipeline.hand_params
    if step9:  # the phases step looks it up at every call
        pipeline.hand_params = lambda p: p.hand
    t = cpu_s()
    try:
        run_phases(path, params=params, force=True)
    finally:
        pipeline.hand_params = chosen
    return cpu_s() - t


def figures(est: np.ndarray, truth: np.ndarray) -> dict:
    """Per-minute errors of the estimated moving seconds (s)."""
    d = est - truth
    return {
        "mae_s": float(np.mean(np.abs(d))),
        "bias_s": float(np.mean(d)),
        "total_ratio": float(est.sum() / max(truth.sum(), 1e-9)),
        "off_1s": int(np.sum(np.abs(d) > 1.0)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=3.0, help="hours per recording")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--start", default="2024-03-04T09:00:00", help="device local start time (daytime: movements)")
    args = ap.parse_args()
    print("| seed | run | minutes | MAE s/min | mean error s/min | total / truth | minutes off > 1 s | step CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        warm, _ = one_recording(99, 0.05, args.start, Path(tmp))  # imports and compiled code, not timed
        run(warm, True)
        for seed in args.seeds:
            mcap, truth = one_recording(seed, args.hours, args.start, Path(tmp))
            copy = mcap.with_name(mcap.stem + "_off.mcap")
            shutil.copyfile(mcap, copy)
            est = {}
            for label, path, step9 in (("step 9 on", mcap, True), ("step 9 off (the default here)", copy, False)):
                cpu = run(path, step9)
                est[label] = moving_per_minute(path, len(truth))
                f = figures(est[label], truth)
                print(
                    f"| {seed} | {label} | {len(truth)} | {f['mae_s']:.3f} | {f['bias_s']:+.3f} | {f['total_ratio']:.3f} "
                    f"| {f['off_1s']} | {cpu:.1f} |"
                )
            diff = np.abs(est["step 9 on"] - est["step 9 off (the default here)"])
            n = int(np.sum(diff > 1e-6))
            print(f"|  | minutes that differ between the two runs | {n} (max {diff.max():.3f} s) | | | | | |")


if __name__ == "__main__":
    main()
