"""Cost of the orientation anchored at rests with the heading carried through rests (the default since 2026-12-07)
against the filter's heading at every rest (the default before), on the same simulated R2G trial in one process.

    python benchmarks/bench_anchor_heading.py [--repetitions 10] [--runs 5]

Prints the median wall time and the CPU time (user+sys) per call of each, and their ratio. The machine is shared
and loaded: read the ratio, not the absolute figures.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from trajectory_accuracy import _static_for_anchor  # noqa: E402

from imulog.process.integration import AnchorParams, rest_anchored_orientation  # noqa: E402


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main(argv: list[str] | None = None) -> int:
    from imulog.process.orientation import estimate_orientation
    from imulog.simulate.core import simulate

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repetitions", type=int, default=10)
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args(argv)
    sim = simulate("r2g", subject=0, seed=0, repetitions=args.repetitions)
    imu = sim.recording.imus[0]
    t = (imu.t_ns - imu.t_ns[0]) / 1e9
    rate = (len(t) - 1) / t[-1]
    q = estimate_orientation(imu.gyr, imu.acc, rate).quat
    static, restart = _static_for_anchor(imu, rate, args.repetitions, t_s=t)
    print(f"{len(t):,} samples ({t[-1]:.0f} s), {args.repetitions} repetitions")
    res = {}
    for label, params in (("filter", AnchorParams(heading="filter")), ("gyroscope", AnchorParams(heading="gyroscope"))):
        walls, cpus = [], []
        for _ in range(args.runs):
            w0, c0 = time.perf_counter(), _cpu()
            rest_anchored_orientation(q, imu.gyr, t, static, params, restart)
            walls.append(time.perf_counter() - w0)
            cpus.append(_cpu() - c0)
        res[label] = (float(np.median(walls)), float(np.median(cpus)))
        print(f"heading={label}: {1e3 * res[label][0]:.0f} ms wall, {1e3 * res[label][1]:.0f} ms CPU per call")
    print(
        f"ratio gyroscope / filter: {res['gyroscope'][0] / res['filter'][0]:.2f} (wall), "
        f"{res['gyroscope'][1] / max(res['filter'][1], 1e-9):.2f} (CPU)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
