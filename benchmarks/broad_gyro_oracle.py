"""How much a gyroscope calibration can give VQF offline on BROAD, and how close vqf_gyrocal's self-calibration gets.

    python benchmarks/broad_gyro_oracle.py [--data DIR] [--trials 02,05,14 | --exclude 02,05,14]

Per trial: the gyroscope's sensitivity matrix ``S`` (gyr = S w + b) fitted by least squares against the optical
reference's angular rate (``opt_quat``, central differences, both smoothed over 15 samples; the "oracle", which
uses the ground truth and so is not an estimator), then the inclination RMSE (degrees, movement samples, 6D) of
VQF offline on the raw gyroscope, of ``vqf_gyrocal`` (its own estimate ``M``), and of VQF offline on the
oracle-calibrated gyroscope ``S^-1 (gyr - b) + b``. Also printed: the diagonals of ``S - I`` and of
``M^-1 - I`` in percent (they agree where the self-calibration finds the sensor's own error). A diagnostic of
where the gap to the reference lies, not a tuning tool: ``vqf_gyrocal``'s settings are not read from it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from broad_orientation import BROAD, load, select_files
from vqf import offlineVQF

from imulog.numeric import moving_mean
from imulog.process import quaternion as quat
from imulog.process.alignment_frames import angular_velocity_from_rotations
from imulog.process.orientation import orientation_errors
from imulog.process.orientation_gyrocal import vqf_gyrocal


def reference_sensitivity(data: dict, smooth: int = 15) -> tuple[np.ndarray, np.ndarray]:
    """``(S, b)`` with gyr ~ S w_ref + b by least squares over samples with a finite reference rate (rad/s)."""
    w = angular_velocity_from_rotations(quat.to_rotation_matrix(data["opt_quat"]), data["rate"])
    ok = np.all(np.isfinite(w), axis=1)
    ok &= moving_mean((~ok).astype(float), smooth) == 0  # no gap inside the smoothing window
    w_s = moving_mean(np.where(np.isfinite(w), w, 0.0), smooth)
    g_s = moving_mean(data["imu_gyr"], smooth)
    ok &= np.linalg.norm(w_s, axis=1) < 10.0
    x = np.linalg.lstsq(np.column_stack([w_s[ok], np.ones(ok.sum())]), g_s[ok], rcond=None)[0]
    return x[:3].T, x[3]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=BROAD)
    ap.add_argument("--trials", default="", help="comma-separated trial numbers to use")
    ap.add_argument("--exclude", default="", help="comma-separated trial numbers to leave out")
    args = ap.parse_args()
    files = select_files(args.data, args.trials, args.exclude)
    print("| trial | vqf_offline | vqf_gyrocal | oracle-calibrated VQF offline | S - I diag % | M^-1 - I diag % |")
    print("|---|---:|---:|---:|---|---|")
    rows = []
    for f in files:
        d = load(f)
        gyr, acc, dt = np.ascontiguousarray(d["imu_gyr"]), np.ascontiguousarray(d["imu_acc"]), 1.0 / d["rate"]
        s, b = reference_sensitivity(d)
        oracle_gyr = np.ascontiguousarray((gyr - b) @ np.linalg.inv(s).T + b)
        q_cal, m = vqf_gyrocal(gyr, acc, d["rate"])
        errs = [
            orientation_errors(q, d["opt_quat"], d["movement"])["inclination_rmse_deg"]
            for q in (offlineVQF(gyr, acc, None, dt)["quat6D"], q_cal, offlineVQF(oracle_gyr, acc, None, dt)["quat6D"])
        ]
        rows.append(errs)
        ds = np.round((np.diag(s) - 1) * 100, 2).tolist()
        dm = np.round((np.diag(np.linalg.inv(m)) - 1) * 100, 2).tolist()
        print(f"| {f.stem.split('_')[0]} | {errs[0]:.3f} | {errs[1]:.3f} | {errs[2]:.3f} | {ds} | {dm} |")
    r = np.array(rows)
    print(
        f"\nmean over {len(r)} trials: vqf_offline {r[:, 0].mean():.3f}, vqf_gyrocal {r[:, 1].mean():.3f} "
        f"({r[:, 1].mean() / r[:, 0].mean():.3f}x), oracle-calibrated {r[:, 2].mean():.3f} "
        f"({r[:, 2].mean() / r[:, 0].mean():.3f}x)"
    )


if __name__ == "__main__":
    main()
