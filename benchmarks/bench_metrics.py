"""Speed of the clinical metrics on a long wrist recording, against a plain vectorised numpy/scipy version.

    python benchmarks/bench_metrics.py [--hours 8] [--rate 100]

The peer (issue 17) is what a scientist fluent in numpy would write for the same definitions in a notebook:
``reshape``-and-``mean`` for arm use's 0.1 s windows, ``scipy.ndimage.uniform_filter1d`` for the moving averages,
``np.flatnonzero``/``np.diff`` for the dead periods, and a window-shaped ``cumsum`` for the distance. Both sides
run on the same signal in one process, best of ``--repeat``, and their results are compared (counts equal,
percentages and distances to 1e-9) so the ratio is between equal computations. Load average printed.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from scipy.ndimage import uniform_filter1d

from imulog.process.metrics import ActivityCountParams, ArmUsageParams, activity_count_dead_period, arm_usage
from imulog.process.metrics.distance import DistanceHistogramParams, windowed_distance


def synthetic(n: int, rate: float, seed: int = 0) -> np.ndarray:
    """Bouts of arm movement between rests, with sensor noise; g."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    active = (np.sin(2 * np.pi * t / 37.0) > 0.3).astype(float)
    tilt = 0.5 * active * np.sin(2 * np.pi * t / 2.3) ** 2
    return np.column_stack([np.sin(tilt), 0.2 * tilt, np.cos(tilt)]) + rng.normal(0, 0.005, (n, 3))


# ---------------------------------------------------------------- the peer: plain vectorised numpy / scipy
def peer_arm_usage(acc: np.ndarray, rate: float, noise_g: float, ref_hz: float = 10.0) -> float:
    k = int(round(rate / ref_hz))
    m = len(acc) // k
    windows = acc[: m * k].reshape(m, k, 3).mean(axis=1)
    if len(acc) > m * k:  # the last, partial window
        windows = np.vstack([windows, acc[m * k :].mean(axis=0)])
    active = np.zeros(len(windows), bool)
    active[1:] = (np.abs(np.diff(windows, axis=0)) > noise_g).any(axis=1)
    return 100.0 * active.sum() / len(windows)


def peer_activity_count(acc: np.ndarray, m: int, dead: int, floor: float) -> int:
    ma = uniform_filter1d(acc, size=2 * m + 1, axis=0, mode="nearest")
    ma[:m], ma[-m:] = acc[:m], acc[-m:]  # the thesis copies the edges
    h = acc - ma
    h[np.abs(h) <= floor] = 0.0
    idx = np.flatnonzero(np.sqrt((h * h).sum(axis=1)))
    if not len(idx):
        return 0
    return 1 + int(np.count_nonzero(np.diff(idx) - 1 >= dead))


def peer_distance(acc: np.ndarray, rate: float, m: int, window_s: float) -> np.ndarray:
    win = int(round(window_s * rate))
    ma = uniform_filter1d(acc, size=2 * m + 1, axis=0, mode="nearest")
    ma[:m], ma[-m:] = acc[:m], acc[-m:]
    h = acc - ma
    sign = np.ones_like(acc)
    sign[1:] = np.where(acc[1:] > acc[:-1], 1.0, -1.0)
    dv = sign * h / rate
    n = len(acc) // win * win
    dv = dv[:n].reshape(-1, win, 3)
    dv[:, 0] = 0.0
    vel = np.cumsum(dv, axis=1)
    ds = np.zeros_like(vel)
    ds[:, 1:] = vel[:, :-1] / rate
    return np.cumsum(ds, axis=1).reshape(-1, 3)


def best(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=8.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    n = int(args.hours * 3600 * args.rate)
    acc = synthetic(n, args.rate)
    t_ns = (np.arange(n) * (1e9 / args.rate)).astype(np.int64)
    act = ActivityCountParams.for_rate(args.rate, noise_floor_g=0.02)
    dist = DistanceHistogramParams()
    m = max(1, int(round(dist.m_s * args.rate)))
    whole_windows = n // int(round(dist.window_s * args.rate)) * int(round(dist.window_s * args.rate))
    rows = [
        (
            "arm usage",
            lambda: arm_usage(acc, ArmUsageParams(0.022), t_ns=t_ns).overall_percent,
            lambda: peer_arm_usage(acc, args.rate, 0.022),
        ),
        (
            "activity count (method 2)",
            lambda: activity_count_dead_period(acc, act).count,
            lambda: peer_activity_count(acc, act.m_samples, act.dead_samples, act.noise_floor_g),
        ),
        (
            "windowed distance",
            lambda: windowed_distance(acc, args.rate, dist)[:whole_windows],
            lambda: peer_distance(acc, args.rate, m, dist.window_s),
        ),
    ]
    one, five, _ = os.getloadavg()
    print(f"{n:,} samples ({args.hours:g} h at {args.rate:g} Hz); best of {args.repeat}; load {one:.1f} / {five:.1f}")
    print(f"{'metric':28s}{'imulog s':>10s}{'peer s':>10s}{'imulog M/s':>12s}{'speed ratio':>13s}  results")
    for name, ours_fn, peer_fn in rows:
        t_ours, ours = best(ours_fn, args.repeat)
        t_peer, theirs = best(peer_fn, args.repeat)
        same = np.allclose(ours, theirs, rtol=1e-9, atol=1e-9)
        print(
            f"{name:28s}{t_ours:10.3f}{t_peer:10.3f}{n / t_ours / 1e6:12.1f}{t_peer / t_ours:12.2f}x  "
            f"{'equal' if same else 'DIFFER'}"
        )
    print("speed ratio = peer time / imulog time (> 1: imulog faster)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
