"""Orientation accuracy on the BROAD trials in ../shared/data/broad, per trial and per backend.

    python benchmarks/broad_orientation.py [--mag] [--no-ahrs] [--data DIR] [--trials 02,05,14 | --exclude 02,05,14]
        [--backends vqf_offline,vqf_gyrocal]

``--data DIR`` reads every ``*.hdf5`` of a BROAD folder (default ../shared/data/broad, the three shared trials;
the full dataset is github dlaidig/broad ``data_hdf5/``, CC-BY-4.0); ``--trials``/``--exclude`` select trials by
their number. Besides the table it prints, per backend, the mean inclination RMSE over the trials, its ratio to
VQF offline's, the worst per-trial ratio, and the CPU time (user+sys of this process) and wall time spent in
that backend (the machine may be loaded: compare ratios within one run).

Prints a Markdown table of inclination and heading-free orientation RMSE (degrees) against BROAD's
optical quaternion ``opt_quat`` over the ``movement`` samples (rows with lost optical tracking
skipped; ``--all-samples`` for every sample), following BROAD's own evaluation (``example_code/broad_utils.py`` in dlaidig/broad): the
error quaternion in the global frame is ``q_imu * q_opt^-1``; the inclination error is its tilt
part, which does not depend on the (arbitrary, for 6D) heading of the estimate. BROAD's ``opt_quat``
is expressed in an ENU frame while a 6D estimate's global frame has its own heading, so for the
heading-free error the constant heading rotation between the two global frames is estimated (least
squares over the movement samples) and removed before the total rotation angle is taken. The IMU
and optical body frames are already aligned in BROAD (``info`` attribute of every file).

Backends: imulog's ``madgwick`` (thesis setting, AQUA init, beta 0.03), ``vqf``, ``vqf_offline``
(the default), ``imufusion``; and, as an external baseline, ``ahrs.filters.Madgwick`` (beta 0.03,
identity start) unless ``--no-ahrs``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import h5py
import numpy as np

from imulog.process.orientation import (
    DEFAULT_BACKEND,
    OrientationParams,
    available_backends,
    estimate_orientation,
    orientation_errors,
)

BROAD = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "broad"


def load(path: Path) -> dict:
    with h5py.File(path, "r") as h:
        d = {k: h[k][:] for k in h}
        d["rate"] = float(h.attrs["sampling_rate"])
    return d


def select_files(data: Path, trials: str = "", exclude: str = "") -> list[Path]:
    """The ``*.hdf5`` trials of ``data`` whose number is in ``trials`` (comma-separated; empty: all) and not in
    ``exclude``."""
    keep = {t for t in trials.split(",") if t}
    drop = {t for t in exclude.split(",") if t}
    number = lambda f: f.stem.split("_")[0]  # noqa: E731
    files = [f for f in sorted(data.glob("*.hdf5")) if (not keep or number(f) in keep) and number(f) not in drop]
    if not files:
        raise SystemExit(f"no BROAD .hdf5 files in {data} (after --trials/--exclude)")
    return files


def cpu_s() -> float:
    """User + system CPU time of this process (s)."""
    t = os.times()
    return t.user + t.system


def evaluate(
    data: dict,
    *,
    use_mag: bool = False,
    ahrs: bool = True,
    all_samples: bool = False,
    backends: list[str] | None = None,
    timing: dict[str, list[float]] | None = None,
) -> dict[str, dict[str, float]]:
    """Errors per backend for one BROAD trial (dict backend -> orientation_errors dict); CPU and wall seconds
    per backend are added to ``timing`` (backend -> [cpu, wall])."""
    if all_samples:
        data = {**data, "movement": np.ones(len(data["movement"]), dtype=bool)}
    out = {}
    timing = {} if timing is None else timing
    for backend in backends or available_backends():
        c0, w0 = cpu_s(), time.perf_counter()
        r = estimate_orientation(
            data["imu_gyr"],
            data["imu_acc"],
            data["rate"],
            data["imu_mag"],
            OrientationParams(backend=backend, use_mag=use_mag),
        )
        spent = timing.setdefault(backend, [0.0, 0.0])
        spent[0] += cpu_s() - c0
        spent[1] += time.perf_counter() - w0
        out[backend] = orientation_errors(r.quat, data["opt_quat"], data["movement"])
    if ahrs:
        from ahrs.filters import Madgwick

        kw = {"mag": data["imu_mag"]} if use_mag else {"q0": np.array([1.0, 0.0, 0.0, 0.0])}
        q = Madgwick(gyr=data["imu_gyr"], acc=data["imu_acc"], frequency=data["rate"], gain=0.03, **kw).Q
        out["ahrs Madgwick"] = orientation_errors(q, data["opt_quat"], data["movement"])
    return out


def forward_backward(data: dict, offline: bool) -> np.ndarray:
    """Candidate default: VQF run forwards and on the time-reversed recording (gyro negated), the
    backward estimate's heading matched to the forward one, and the two averaged (slerp 0.5)."""
    from vqf import VQF, offlineVQF

    from imulog.process import quaternion as quat

    dt = 1.0 / data["rate"]
    gyr, acc = np.ascontiguousarray(data["imu_gyr"]), np.ascontiguousarray(data["imu_acc"])
    g_rev, a_rev = np.ascontiguousarray(-gyr[::-1]), np.ascontiguousarray(acc[::-1])
    if offline:
        qf = offlineVQF(gyr, acc, None, dt)["quat6D"]
        qb = offlineVQF(g_rev, a_rev, None, dt)["quat6D"][::-1]
    else:
        qf = VQF(dt).updateBatch(gyr, acc)["quat6D"]
        qb = VQF(dt).updateBatch(g_rev, a_rev)["quat6D"][::-1]
    qb = quat.multiply(quat.heading_offset(qb, qf), qb)
    return quat.slerp(qf, qb, 0.5)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mag", action="store_true", help="9D (fuse the magnetometer)")
    ap.add_argument("--no-ahrs", action="store_true", help="skip the slow pure-Python ahrs baseline")
    ap.add_argument("--data", type=Path, default=BROAD)
    ap.add_argument("--candidates", action="store_true", help="also evaluate forward-backward VQF schemes (6D)")
    ap.add_argument(
        "--all-samples", action="store_true", help="evaluate every sample, not only BROAD's movement phases"
    )
    ap.add_argument("--trials", default="", help="comma-separated trial numbers to use (e.g. 02,05,14)")
    ap.add_argument("--exclude", default="", help="comma-separated trial numbers to leave out")
    ap.add_argument("--backends", default="", help="comma-separated backends (default: all available)")
    args = ap.parse_args()
    files = select_files(args.data, args.trials, args.exclude)
    backends = [b for b in args.backends.split(",") if b] or None
    if backends and "vqf_offline" not in backends:
        backends.insert(0, "vqf_offline")  # the baseline every ratio is taken against
    results = {}
    timing: dict[str, list[float]] = {}
    evaluate(load(files[0]), use_mag=args.mag, ahrs=False, backends=backends)  # warm-up: numba compiles untimed
    for f in files:
        data = load(f)
        results[f.stem] = evaluate(
            data,
            use_mag=args.mag,
            ahrs=not args.no_ahrs,
            all_samples=args.all_samples,
            backends=backends,
            timing=timing,
        )
        if args.all_samples:
            data["movement"] = np.ones(len(data["movement"]), dtype=bool)
        if args.candidates:
            for name, offline in (("fwd-bwd VQF online", False), ("fwd-bwd VQF offline", True)):
                q = forward_backward(data, offline)
                results[f.stem][name] = orientation_errors(q, data["opt_quat"], data["movement"])
    backends = list(next(iter(results.values())))
    trials = list(results)
    short = [t.split("_")[0] for t in trials]
    samples = "all samples" if args.all_samples else "movement phases"
    print(f"{'9D' if args.mag else '6D'}, {samples}; default backend: {DEFAULT_BACKEND}\n")
    print(
        "| backend | "
        + " | ".join(f"incl. {s}" for s in short)
        + " | "
        + " | ".join(f"heading-free {s}" for s in short)
        + " |"
    )
    print("|---|" + "---:|" * (2 * len(trials)))
    for b in backends:
        inc = [f"{results[t][b]['inclination_rmse_deg']:.2f}" for t in trials]
        hf = [f"{results[t][b]['heading_free_rmse_deg']:.2f}" for t in trials]
        print(f"| {b} | " + " | ".join(inc) + " | " + " | ".join(hf) + " |")
    print()
    print(f"{len(trials)} trials; mean inclination RMSE, ratio to vqf_offline's mean, worst per-trial ratio, time:\n")
    print("| backend | mean incl. (deg) | ratio | worst trial ratio | CPU s | wall s | CPU vs vqf_offline |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    base = np.array([results[t]["vqf_offline"]["inclination_rmse_deg"] for t in trials])
    for b in backends:
        inc = np.array([results[t][b]["inclination_rmse_deg"] for t in trials])
        cpu, wall = timing.get(b, [float("nan"), float("nan")])
        rel = cpu / timing["vqf_offline"][0] if "vqf_offline" in timing else float("nan")
        worst = np.argmax(inc / base)
        print(
            f"| {b} | {inc.mean():.3f} | {inc.mean() / base.mean():.3f} | {(inc / base)[worst]:.3f} ({short[worst]}) "
            f"| {cpu:.1f} | {wall:.1f} | {rel:.2f}x |"
        )
    print()
    ok = all(
        results[t][DEFAULT_BACKEND]["inclination_rmse_deg"] <= results[t]["vqf_offline"]["inclination_rmse_deg"] + 1e-9
        for t in trials
    )
    print(f"default <= VQF offline (inclination) on every trial: {ok}")


if __name__ == "__main__":
    main()
