"""Zero-velocity / static agreement on the real recordings in ../shared/data (gaitmap foot, BROAD breaks).

    python benchmarks/segmentation_real.py

gaitmap: per foot, the fraction of strides (provided stride borders) holding exactly one zero-velocity
interval, the fraction of stride borders inside one, and the mean zero-velocity share of a stride.
BROAD 05/14: per-sample agreement of the static mask with ``~movement`` and the mean coverage of the
dataset's five static segments (rest, three 10 s breaks, rest), for each detector.
"""

from __future__ import annotations

import time
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from imulog.process.segmentation.double_threshold import double_threshold
from imulog.process.segmentation.dynamos import dynamos, runs
from imulog.process.segmentation.zero_velocity import GyroNormStaticParams, gyro_norm_static, static_from_movements

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def main() -> None:
    imu = pd.read_csv(DATA / "gaitmap_foot" / "imu_sample.csv", header=[0, 1], index_col=0)
    strides = pd.read_csv(DATA / "gaitmap_foot" / "stride_borders_sample.csv")
    params = GyroNormStaticParams(threshold_rad_s=np.deg2rad(70.0), window_s=0.15, min_static_s=0.05)
    print("| gaitmap foot | strides | exactly one ZV interval | borders inside ZV | ZV share of stride |")
    print("|---|---|---|---|---|")
    for foot in ("left", "right"):
        gyr = np.deg2rad(imu[f"{foot}_sensor"][["gyr_x", "gyr_y", "gyr_z"]].to_numpy())
        static = gyro_norm_static(gyr, 204.8, params)
        mine = strides[strides.foot == foot]
        zs, ze = runs(static)
        one = np.mean([np.sum((zs >= s) & (ze <= e)) == 1 for s, e in zip(mine.start, mine.end, strict=True)])
        borders = np.unique(np.r_[mine.start, mine.end])
        share = np.mean([static[s:e].mean() for s, e in zip(mine.start, mine.end, strict=True)])
        print(
            f"| {foot} | {len(mine)} | {100 * one:.1f} % | {100 * static[borders].mean():.1f} % | {100 * share:.1f} % |"
        )
    print()
    print("| BROAD trial | detector | sample agreement | static segments covered (mean, min) | ms |")
    print("|---|---|---|---|---|")
    for name in ("05_undisturbed_slow_rotation_with_breaks_B", "14_undisturbed_slow_translation_with_breaks_B"):
        with h5py.File(DATA / "broad" / f"{name}.hdf5", "r") as f:
            gyr, movement = np.asarray(f["imu_gyr"]), np.asarray(f["movement"]).astype(bool)
            rate = float(f.attrs["sampling_rate"])
        detectors = {
            "gyro-norm 0.1 rad/s": lambda gyr=gyr, rate=rate: gyro_norm_static(gyr, rate),
            "double-threshold": lambda gyr=gyr, rate=rate: static_from_movements(
                len(gyr), *double_threshold(gyr, rate), rate, 0.0, 0.2
            ),
            "DynAMoS complement": lambda gyr=gyr, rate=rate: static_from_movements(len(gyr), *_dyn(gyr, rate), rate),
        }
        ts, te = runs(~movement)
        for label, detect in detectors.items():
            t0 = time.perf_counter()
            static = detect()
            ms = 1e3 * (time.perf_counter() - t0)
            cover = [static[a:b].mean() for a, b in zip(ts, te, strict=True)]
            print(
                f"| {name[:2]} | {label} | {100 * np.mean(static == ~movement):.1f} % | "
                f"{100 * np.mean(cover):.1f} %, {100 * np.min(cover):.1f} % | {ms:.0f} |"
            )


def _dyn(gyr, rate):
    seg = dynamos(gyr, rate)
    return seg.start, seg.end


if __name__ == "__main__":
    main()
