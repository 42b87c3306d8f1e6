"""Orientation throughput (samples/s) on 3.6 M samples, all backends and baselines in one run.

    python benchmarks/bench_orientation.py [--samples 3600000] [--ahrs-samples 30000]

Input: BROAD trial 02 (real IMU data, 285.7 Hz) tiled to ``--samples`` rows. Timed:

* imulog ``madgwick_imu`` / ``madgwick_marg`` (numba; compile time excluded by a warm-up call),
* imulog's default backend through :func:`imulog.process.orientation.estimate_orientation`
  (static detection, gap filling and the VQF offline call included),
* baselines: ``ahrs.filters.Madgwick`` (pure Python: timed on ``--ahrs-samples`` rows and reported
  per sample, it would take minutes on 3.6 M), ``imufusion.Ahrs`` (per-sample Python loop, the
  way its API is used), ``vqf.VQF.updateBatch`` (causal, C++ batch) and ``vqf.offlineVQF``.

Targets (issue 11): Madgwick >= 10 M samples/s; the default backend no slower than VQF's batch call
(the ``offlineVQF`` call it wraps; the causal ``VQF.updateBatch`` is listed too).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import h5py
import numpy as np

from imulog.process.madgwick import madgwick_imu, madgwick_marg
from imulog.process.orientation import DEFAULT_BACKEND, OrientationParams, estimate_orientation

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "broad" / "02_undisturbed_slow_rotation_B.hdf5"


def timed(fn, *args, repeat: int = 1, **kwargs) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn(*args, **kwargs)
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=3_600_000)
    ap.add_argument("--ahrs-samples", type=int, default=30_000)
    ap.add_argument("--imufusion-samples", type=int, default=0, help="0 = all samples")
    args = ap.parse_args()

    with h5py.File(DATA, "r") as h:
        acc0, gyr0, mag0 = h["imu_acc"][:], h["imu_gyr"][:], h["imu_mag"][:]
        rate = float(h.attrs["sampling_rate"])
    n = args.samples
    reps = n // len(acc0) + 1
    acc = np.ascontiguousarray(np.tile(acc0, (reps, 1))[:n])
    gyr = np.ascontiguousarray(np.tile(gyr0, (reps, 1))[:n])
    mag = np.ascontiguousarray(np.tile(mag0, (reps, 1))[:n])
    dt = 1.0 / rate
    rows: list[tuple[str, int, float]] = []

    madgwick_imu(gyr[:100], acc[:100], dt)  # compile / load cache
    madgwick_marg(gyr[:100], acc[:100], mag[:100], dt)
    rows.append(("imulog madgwick_imu (numba, 6D)", n, timed(madgwick_imu, gyr, acc, dt, 0.03, repeat=3)))
    rows.append(("imulog madgwick_marg (numba, 9D)", n, timed(madgwick_marg, gyr, acc, mag, dt, 0.03, repeat=3)))
    rows.append(
        (
            f"imulog default backend ({DEFAULT_BACKEND}, 6D)",
            n,
            timed(estimate_orientation, gyr, acc, rate, None, OrientationParams()),
        )
    )

    from vqf import VQF, offlineVQF

    rows.append(("vqf.offlineVQF (6D)", n, timed(offlineVQF, gyr, acc, None, dt)))
    rows.append(("vqf.VQF.updateBatch (causal, 6D)", n, timed(lambda: VQF(dt).updateBatch(gyr, acc))))

    import imufusion

    m = args.imufusion_samples or n

    def run_fusion():
        a = imufusion.Ahrs()
        a.set_settings(imufusion.AhrsSettings(sample_rate=rate, convention=imufusion.CONVENTION_NWU, gain=0.5))
        g_dps = np.rad2deg(gyr[:m])
        a_g = acc[:m] / 9.80665
        out = np.empty((m, 4))
        for i in range(m):
            a.update_no_magnetometer(g_dps[i], a_g[i])
            out[i] = a.get_quaternion()
        return out

    rows.append(("imufusion.Ahrs (Python loop, 6D)", m, timed(run_fusion)))

    from ahrs.filters import Madgwick

    k = args.ahrs_samples
    rows.append(
        ("ahrs.filters.Madgwick (6D)", k, timed(lambda: Madgwick(gyr=gyr[:k], acc=acc[:k], frequency=rate, gain=0.03)))
    )

    rate_of = {name: cnt / sec for name, cnt, sec in rows}
    print(f"{'method':<44} {'samples':>10} {'seconds':>9} {'samples/s':>12}")
    for name, cnt, sec in rows:
        print(f"{name:<44} {cnt:>10d} {sec:>9.3f} {cnt / sec:>12,.0f}")
    mad = rate_of["imulog madgwick_imu (numba, 6D)"]
    default = rate_of[f"imulog default backend ({DEFAULT_BACKEND}, 6D)"]
    print()
    print(
        f"madgwick_imu vs ahrs Madgwick: {mad / rate_of['ahrs.filters.Madgwick (6D)']:.0f}x; "
        f"target >= 10 M samples/s: {'MET' if mad >= 10e6 else 'NOT MET'} ({mad / 1e6:.1f} M/s)"
    )
    print(f"madgwick_marg: {rate_of['imulog madgwick_marg (numba, 9D)'] / 1e6:.1f} M samples/s")
    ratio = default / rate_of["vqf.offlineVQF (6D)"]
    print(
        f"default backend vs the vqf.offlineVQF batch call it wraps: {ratio:.2f}x "
        f"({'MET' if ratio >= 0.95 else 'NOT MET'}: no slower, 5 % timing tolerance)"
    )
    print(f"default backend vs causal VQF.updateBatch: {default / rate_of['vqf.VQF.updateBatch (causal, 6D)']:.2f}x")


if __name__ == "__main__":
    main()
