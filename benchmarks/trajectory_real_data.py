"""Trajectory errors on real recordings in ../shared/data (reported in docs/trajectory.md).

* BROAD trial 14 (``14_undisturbed_slow_translation_with_breaks_B``, Laidig et al., CC-BY-4.0): hand-moved
  IMU with OptiTrack position. Orientation from ``imulog.process.orientation`` (VQF offline, 6D), its
  global frame rotated onto the optical frame with one constant rotation fitted to ``opt_quat`` over the
  trial (the align step's job with Vicon); rests = ``~movement``; each movement between two rests is one
  window; errors per axis against ``opt_pos`` (NaN rows skipped), relative to the window start.
* gaitmap foot data (MIT): foot IMU at 204.8 Hz and foot markers at 100 Hz. Orientation as above; zero
  velocity = gyro norm below a threshold; ZUPT over the gait sequence; stride length = horizontal distance
  between the foot positions at the provided stride borders (mid-stance to mid-stance), against the
  same from the heel marker (``*_FCC``).

    python benchmarks/trajectory_real_data.py [--data ../shared/data]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.evaluation import summarize, trajectory_errors
from imulog.process.integration import DdiParams, ZuptParams, double_integrate, zupt
from imulog.process.rest_runs import static_runs

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
BROAD_14 = "broad/14_undisturbed_slow_translation_with_breaks_B.hdf5"


def _orientation(gyr: np.ndarray, acc: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from imulog.process.orientation import estimate_orientation, gravity_free_acceleration

    est = estimate_orientation(gyr, acc, rate)
    return est.quat, gravity_free_acceleration(est.quat, acc, est.static), est.static


def broad_zupt(path: Path) -> dict:
    """Per-movement errors on a BROAD trial: {method: [trajectory_errors...]} for ``zupt`` (Bai, linear
    de-drift), ``plain`` (velocity reset at rests only) and ``ddi`` (window mean removed)."""
    import h5py

    with h5py.File(path, "r") as f:
        rate = float(f.attrs["sampling_rate"])
        acc, gyr = f["imu_acc"][:], f["imu_gyr"][:]
        opt_pos, opt_quat = f["opt_pos"][:], f["opt_quat"][:]
        movement = f["movement"][:].astype(bool)
    t = np.arange(len(acc)) / rate
    q_est, acc_g, _ = _orientation(gyr, acc, rate)
    ok = np.all(np.isfinite(opt_quat), axis=1)
    q_g2w = quat.average(quat.multiply(opt_quat[ok], quat.conjugate(q_est[ok])))
    acc_w = quat.rotate(q_g2w, acc_g)
    rest = ~movement
    out: dict[str, list[dict]] = {"ddi": [], "zupt": [], "plain": []}
    for s, e in static_runs(movement):
        i0, i1 = max(s - 1, 0), min(e + 1, len(t))
        sl = slice(i0, i1)
        est = {
            "zupt": zupt(acc_w[sl], t[sl], rest[sl], ZuptParams())[1],
            "ddi": double_integrate(acc_w[sl], t[sl], DdiParams(remove_mean=True))[1],
            "plain": zupt(acc_w[sl], t[sl], rest[sl], ZuptParams(dedrift=False))[1],
        }
        for m, p in est.items():
            r = trajectory_errors(p, opt_pos[sl])
            r.update(start_s=float(t[i0]), duration_s=float(t[i1 - 1] - t[i0]))
            out[m].append(r)
    return out


def _gaitmap_tables(root: Path):
    import pandas as pd

    imu = pd.read_csv(root / "imu_sample.csv", header=[0, 1], index_col=0)
    mocap = pd.read_csv(root / "mocap_sample.csv", header=[0, 1], index_col=0)
    strides = pd.read_csv(root / "stride_borders_sample.csv")
    return imu, mocap, strides


def gaitmap_stride_lengths(
    root: Path, foot: str = "left", gyro_threshold_rad_s: float = 0.6, rest_gate: bool = True
) -> dict:
    """IMU (ZUPT) and marker stride lengths (m) for one foot of the gaitmap sample. ``rest_gate``: keep only the
    still-gyroscope samples the accelerometer confirms (:func:`imulog.process.rests.true_rests`, as the trajectory
    step does)."""
    imu, mocap, strides = _gaitmap_tables(root)
    rate_imu, rate_mocap = 204.8, 100.0
    sensor = f"{foot}_sensor"
    acc = imu[sensor][["acc_x", "acc_y", "acc_z"]].to_numpy(float)
    gyr = np.radians(imu[sensor][["gyr_x", "gyr_y", "gyr_z"]].to_numpy(float))
    t = np.arange(len(acc)) / rate_imu
    q_est, acc_g, _ = _orientation(gyr, acc, rate_imu)
    gnorm = np.linalg.norm(gyr, axis=1)
    k = max(int(round(0.05 * rate_imu)), 1)
    static = np.convolve(gnorm < gyro_threshold_rad_s, np.ones(k) / k, mode="same") > 0.999
    if rest_gate:
        from imulog.process.rests import true_rests

        static = true_rests(static, acc_g, rate_imu, orientation=q_est)
    _, pos = zupt(acc_g, t, static, ZuptParams())
    heel = mocap[f"{foot[0].upper()}_FCC"][["x", "y", "z"]].to_numpy(float) / 1000.0
    t_m = np.arange(len(heel)) / rate_mocap
    st = strides[strides["foot"] == foot]
    imu_len, mocap_len = [], []
    for s, e in zip(st["start"].to_numpy(), st["end"].to_numpy(), strict=True):
        # stride borders are IMU sample indices; lengths are horizontal displacements
        imu_len.append(float(np.linalg.norm(pos[e, :2] - pos[s, :2])))
        ps = np.array([np.interp(t[s], t_m, heel[:, j]) for j in range(2)])
        pe = np.array([np.interp(t[e], t_m, heel[:, j]) for j in range(2)])
        mocap_len.append(float(np.linalg.norm(pe - ps)))
    imu_len, mocap_len = np.array(imu_len), np.array(mocap_len)
    return {"foot": foot, "imu_m": imu_len, "mocap_m": mocap_len, "error_m": imu_len - mocap_len}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=DATA)
    args = ap.parse_args(argv)
    res = broad_zupt(args.data / BROAD_14)
    print(f"# BROAD {BROAD_14}: {len(res['zupt'])} movements between rests, errors per axis (mean±std over movements)")
    print("method  axis  MAE cm        RMSE cm       final cm      % ROM        spearman")
    for m in ("plain", "ddi", "zupt"):
        s = summarize(res[m])
        for a in "xyz":
            v = s[a]
            print(
                f"{m:<7} {a:<5} {v['mae_cm']['mean']:6.1f}±{v['mae_cm']['std']:<5.1f} {v['rmse_cm']['mean']:6.1f}±{v['rmse_cm']['std']:<5.1f} "
                f"{v['final_cm']['mean']:6.1f}±{v['final_cm']['std']:<5.1f} {v['rom_pct']['mean']:5.1f}±{v['rom_pct']['std']:<5.1f} "
                f"{v['spearman']['mean']:.2f}"
            )
    for r in res["zupt"]:
        print(
            f"  zupt movement at {r['start_s']:.1f} s ({r['duration_s']:.1f} s): MAE x/y/z "
            + "/".join(f"{r[a]['mae_cm']:.1f}" for a in "xyz")
            + " cm, ROM "
            + "/".join(f"{r[a]['rom_cm']:.0f}" for a in "xyz")
            + " cm"
        )
    root = args.data / "gaitmap_foot"
    for foot in ("left", "right"):
        g = gaitmap_stride_lengths(root, foot)
        e = g["error_m"] * 100
        print(
            f"# gaitmap {foot} foot: {len(e)} strides, marker stride length {100 * g['mocap_m'].mean():.1f}±{100 * g['mocap_m'].std(ddof=1):.1f} cm, "
            f"ZUPT error {e.mean():+.1f}±{e.std(ddof=1):.1f} cm (mean abs {np.abs(e).mean():.1f} cm, "
            f"{100 * np.abs(e).mean() / (100 * g['mocap_m'].mean()):.1f} %)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
