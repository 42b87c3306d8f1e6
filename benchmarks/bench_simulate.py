"""Simulator speed: a full 25-repetition R2G trial (issue 4: "simulates in a few seconds").

    python benchmarks/bench_simulate.py

Prints the time to simulate one trial in memory, to write its raw files + truth, and the speed-up of
the vectorised analytic evaluation over a per-sample Python loop (the baseline, measured on a slice
in the same process and scaled to the trial's sample count).
"""

from __future__ import annotations

import tempfile
import time

import numpy as np

from imulog.simulate import simulate, write_trial_files
from imulog.simulate.core import _rng
from imulog.simulate.protocols import r2g


def main() -> None:
    t = time.perf_counter()
    sim = simulate("r2g", seed=0)
    t_sim = time.perf_counter() - t
    n_imu = len(sim.recording.imus[0])
    n_vicon = len(sim.recording.markers[0])
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        write_trial_files(sim, tmp)
        t_write = time.perf_counter() - t

    plan = r2g.build(r2g.Params(), _rng(0, 1, 0, 1), _rng(0, 1, 0, 0, 2)).plan
    times = sim.truth.imu_t_ref_ns / 1e9
    t = time.perf_counter()
    plan.evaluate(times)
    t_vec = time.perf_counter() - t
    sl = times[:: max(1, len(times) // 2000)]
    t = time.perf_counter()
    for x in sl:
        plan.evaluate(np.array([x]))
    t_loop = (time.perf_counter() - t) * len(times) / len(sl)

    duration = sim.truth.t_ns[-1] / 1e9
    print(f"R2G, 25 repetitions: {duration:.0f} s of recording, {n_imu} IMU samples, {n_vicon} Vicon frames")
    print(f"simulate (in memory):      {t_sim:6.2f} s")
    print(f"write raw files + truth:   {t_write:6.2f} s")
    print(
        f"analytic evaluation, vectorised: {t_vec * 1e3:7.1f} ms; per-sample loop (baseline): {t_loop:6.2f} s; ratio {t_loop / t_vec:,.0f}x"
    )


if __name__ == "__main__":
    main()
