"""How many samples a rest detector calls rest while the sensor moves, on simulated continuous motion (issue 32).

For each seed: ``imulog.simulate`` protocol ``continuous`` (60 s of motion, one 0.3 s rest, six glides where the
wrist stops turning but keeps translating), orientation by imulog (VQF offline, 6D), the phases step's static
mask (DynAMoS movements, protocol ``movements``: the gyroscope), then :func:`imulog.process.rests.true_rests`
(the trajectory step's accelerometer gate). Printed: seconds of false rest (static while the truth moves) and of
true rest kept, for the gyroscope alone and after the gate.

    python benchmarks/rest_gate.py --seeds 0 1
"""

from __future__ import annotations

import argparse
import dataclasses

from imulog.process.orientation import estimate_orientation, gravity_free_acceleration
from imulog.process.rests import RestParams, true_rests
from imulog.process.segmentation.pipeline import PhaseParams, segment_phases
from imulog.simulate.core import simulate


def rest_figures(seed: int, params: RestParams | None = None, sensor_frame: bool = True) -> dict[str, float]:
    """False rests and true rests kept (s) for one simulated continuous trial, gyroscope alone and gated
    (``sensor_frame``: the gate also measures the variation in the sensor frame, as the trajectory step does)."""
    sim = simulate("continuous", seed=seed)
    imu, truth = sim.recording.imus[0], sim.truth.imu_static_mask
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) / 1e9)
    est = estimate_orientation(imu.gyr, imu.acc, rate)
    acc = gravity_free_acceleration(est.quat, imu.acc, est.static)
    gyro = segment_phases(imu.gyr, rate, PhaseParams(protocol="movements"), imu.acc).static
    gated = true_rests(gyro, acc, rate, params or RestParams(), orientation=est.quat if sensor_frame else None)
    return {
        "true_rest_s": float(truth.sum() / rate),
        "gyro_false_s": float((gyro & ~truth).sum() / rate),
        "gyro_true_s": float((gyro & truth).sum() / rate),
        "gated_false_s": float((gated & ~truth).sum() / rate),
        "gated_true_s": float((gated & truth).sum() / rate),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--max-mean", type=float, default=None, help="RestParams.max_mean_mps2 (default: off)")
    ap.add_argument("--no-sensor-frame", action="store_true", help="the gravity-free variation only (before)")
    args = ap.parse_args(argv)
    params = dataclasses.replace(RestParams(), max_mean_mps2=args.max_mean)
    print("| seed | false rest, gyroscope (s) | false rest, gated (s) | true rest kept, gyroscope / gated (s) |")
    print("|---|---|---|---|")
    for seed in args.seeds:
        f = rest_figures(seed, params, sensor_frame=not args.no_sensor_frame)
        print(
            f"| {seed} | {f['gyro_false_s']:.2f} | {f['gated_false_s']:.2f} | "
            f"{f['gyro_true_s']:.2f} / {f['gated_true_s']:.2f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
