"""How exactly do the noise-free simulated IMU signals integrate back to the true positions?

    python benchmarks/simulate_integration.py

Strapdown double integration (trapezoid, true orientation, true initial state) over every R2G task
(from 1 s before the reach to 1 s after the return of the hand, ~20 s) of 4 noise-free 25-task trials,
directly and with the velocity reset where the truth is exactly still (ZUPT), at the 114.9 Hz device
rate. The direct residual comes from the trapezoid rule at the minimum-jerk onsets and offsets (the
jerk jumps there); it shrinks as dt^2 (compare ``--rate 1000``).
"""

from __future__ import annotations

import argparse

import numpy as np

from imulog.process import quaternion as quat
from imulog.simulate import simulate


def task_errors(sim, zupt: bool) -> list[float]:
    tr, imu = sim.truth, sim.recording.imus[0]
    aw = quat.rotate(tr.imu_orientation, imu.acc) - [0.0, 0.0, 9.81]
    out = []
    for rep in range(1, int(tr.phases.task_index.max()) + 1):
        sel = tr.phases.task_index == rep
        m = (tr.imu_t_ref_ns >= tr.phases.start_ns[sel].min() - 1e9) & (
            tr.imu_t_ref_ns <= tr.phases.end_ns[sel].max() + 1e9
        )
        t, a, still = tr.imu_t_ref_ns[m] / 1e9, aw[m], tr.imu_static_mask[m]
        dt = np.diff(t)
        dv = 0.5 * (a[1:] + a[:-1]) * dt[:, None]
        v = np.zeros_like(a)
        v[0] = tr.imu_velocity[m][0]
        for k in range(1, len(t)):
            v[k] = 0.0 if (zupt and still[k]) else v[k - 1] + dv[k - 1]
        p = tr.imu_position[m][0] + np.vstack([np.zeros(3), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt[:, None], axis=0)])
        out.append(1e3 * float(np.abs(p - tr.imu_position[m]).max()))
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rate", type=float, default=114.9, help="IMU device rate, Hz")
    parser.add_argument("--seeds", type=int, default=4)
    args = parser.parse_args()
    errors: dict[bool, list[float]] = {False: [], True: []}
    for seed in range(args.seeds):
        sim = simulate("r2g", seed=seed, noise_free=True, imu_rate_hz=args.rate)
        for zupt in (False, True):
            errors[zupt] += task_errors(sim, zupt)
    for zupt, label in ((False, "direct"), (True, "ZUPT  ")):
        e = np.array(errors[zupt])
        print(
            f"{label} {len(e)} tasks at {args.rate:g} Hz: max position error median {np.median(e):.2f}, p95 {np.percentile(e, 95):.2f}, max {e.max():.2f} mm"
        )


if __name__ == "__main__":
    main()
