"""Per-repetition time of every trajectory method on a simulated R2G trial, and the optimisation against a
generic solver baseline in the same process.

Baseline: the thesis solved the optimisation with MATLAB fmincon (interior point, 200 iterations, numeric
gradients). Here the same quadratic cost is handed to ``scipy.optimize.minimize`` (L-BFGS-B with
finite-difference gradients; the end points are fixed, which is the return-to-start constraint) for one axis
of one repetition, for ``--baseline-iterations`` iterations; its time per iteration is extrapolated to the
thesis's 200 iterations x 3 axes, and compared with imulog's direct sparse KKT solve (all three axes).

    python benchmarks/bench_trajectory.py [--repetitions 10] [--baseline-iterations 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parent))

from trajectory_accuracy import simulated_inputs  # noqa: E402

from imulog.process.integration import zupt  # noqa: E402
from imulog.process.minjerk import r2g_reference  # noqa: E402
from imulog.process.trajectory_opt import (  # noqa: E402
    METHODS,
    OptimizationParams,
    TrajectoryParams,
    optimize_repetition,
    reconstruct,
    repetition_windows,
    trial_waypoints,
)


def _cost_matrix(t, z, ref, bounds, static, params: OptimizationParams):
    """The optimisation's stacked least-squares rows for one axis (same terms as optimize_repetition)."""
    from imulog.process.trajectory_opt import _symmetry_rows

    n = len(t)
    dt = np.diff(t)
    dt_s = np.concatenate([[dt[0]], 0.5 * (dt[1:] + dt[:-1]), [dt[-1]]])
    diff = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n), format="csr")
    w = np.sqrt(dt) / dt / params.sigma_data_mps
    blocks = [sp.diags(w) @ diff]
    rhs = [w * np.diff(z)]
    w = np.sqrt(dt_s) / np.where(static, params.sigma_ref_static_m, params.sigma_ref_moving_m)
    blocks.append(sp.diags(w))
    rhs.append(w * ref)
    for a, b in ((0, 3), (1, 2)):
        r, c, v, idx = _symmetry_rows(t, tuple(bounds[a]), tuple(bounds[b]))
        blocks.append(
            sp.diags(np.sqrt(dt_s[idx]) / params.sigma_symmetry_m) @ sp.csr_matrix((v, (r, c)), shape=(len(idx), n))
        )
        rhs.append(np.zeros(len(idx)))
    sel = np.flatnonzero(static[:-1] & static[1:])
    w = np.sqrt(dt[sel]) / dt[sel] / params.sigma_static_vel_mps
    blocks.append(sp.diags(w) @ diff[sel])
    rhs.append(np.zeros(len(sel)))
    return sp.vstack(blocks, format="csr"), np.concatenate(rhs)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repetitions", type=int, default=10)
    ap.add_argument("--baseline-iterations", type=int, default=5)
    args = ap.parse_args(argv)
    d = simulated_inputs(0, seed=0, repetitions=args.repetitions)
    t, acc, static = d["t_s"], d["acc_world"], d["static"]
    reps = [r for r in repetition_windows(t, d["phase_bounds"], static) if len(r.phase_bounds_s) == 4]
    params = TrajectoryParams()
    z_all = np.full_like(acc, np.nan)
    for r in reps:
        sl = slice(r.start, r.stop)
        z_all[sl] = zupt(acc[sl], t[sl], static[sl])[1]
    wp = trial_waypoints(d["anthropometrics"], t, z_all, reps)
    # warm-up (numba compilation of the Kalman filter)
    r0 = reps[0]
    sl0 = slice(r0.start, r0.stop)
    reconstruct("kalman", t[sl0], acc[sl0], static[sl0], params=params)
    n_samples = [r.stop - r.start for r in reps]
    print(f"# {len(reps)} R2G repetitions, {np.mean(n_samples):.0f} samples each on average (~115 Hz)")
    print("method      median ms/rep   max ms/rep")
    for m in METHODS:
        if m == "zupt_bias":
            continue  # needs the orientation; its cost is ZUPT plus one small least squares per trial
        times = []
        for r in reps:
            sl = slice(r.start, r.stop)
            t0 = time.perf_counter()
            reconstruct(m, t[sl], acc[sl], static[sl], phase_bounds_s=r.phase_bounds_s, waypoints=wp, params=params)
            times.append(time.perf_counter() - t0)
        print(f"{m:<11} {1000 * np.median(times):>12.2f} {1000 * np.max(times):>12.2f}")
    # optimisation alone (initial estimate given) vs the generic-solver baseline, one repetition
    r = reps[len(reps) // 2]
    sl = slice(r.start, r.stop)
    ts, zs, st = t[sl], z_all[sl], static[sl]
    ref = r2g_reference(ts, r.phase_bounds_s, wp)
    op = params.optimized
    t0 = time.perf_counter()
    res = optimize_repetition(ts, zs, ref, r.phase_bounds_s, st, op)
    ours = time.perf_counter() - t0
    a_mat, b_vec = _cost_matrix(ts, zs[:, 0], ref[:, 0], r.phase_bounds_s, st, op)
    n = len(ts)
    inner = slice(1, n - 1)

    def f(x):
        p = np.concatenate([[0.0], x, [0.0]])
        return float(np.sum((a_mat @ p - b_vec) ** 2))

    iters = {"n": 0}

    def count(_):
        iters["n"] += 1

    t0 = time.perf_counter()
    out = minimize(f, zs[inner, 0], method="L-BFGS-B", callback=count, options={"maxiter": args.baseline_iterations})
    base = time.perf_counter() - t0
    per_iter = base / max(iters["n"], 1)
    extrapolated = per_iter * 200 * 3
    optimum = f(res.position[inner, 0])
    print(f"# optimisation of one repetition ({n} samples x 3 axes): sparse KKT solve {1000 * ours:.1f} ms")
    print(
        f"# baseline L-BFGS-B, numeric gradients, 1 axis: {iters['n']} iterations in {base:.2f} s "
        f"({1000 * per_iter:.0f} ms/iteration), cost {out.fun:.4g} vs optimum {optimum:.4g}; "
        f"extrapolated to 200 iterations x 3 axes: {extrapolated:.1f} s = {extrapolated / ours:.0f}x imulog"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
