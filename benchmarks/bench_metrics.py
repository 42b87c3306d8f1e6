"""Speed of the clinical metrics on a long wrist recording, against a per-sample loop baseline.

Run: ``python benchmarks/bench_metrics.py [--hours 1] [--rate 115]``. Prints samples/s of each metric (vectorised numpy)
and of a line-by-line loop transcription of Doshi's Appendix A.2/A.3 (the published MATLAB) run in the same
process on a shorter excerpt, and their ratio. Figures are pessimistic on a loaded machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from imulog.process.metrics import (
    ActivityCountParams,
    activity_count_dead_period,
    activity_count_sign,
    arm_usage,
    distance_histogram,
)


def synthetic(n: int, rate: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    active = (np.sin(2 * np.pi * t / 37.0) > 0.3).astype(float)
    tilt = 0.5 * active * np.sin(2 * np.pi * t / 2.3) ** 2
    return np.column_stack([np.sin(tilt), 0.2 * tilt, np.cos(tilt)]) + rng.normal(0, 0.005, (n, 3))


def loop_baseline(acc: np.ndarray, rate: float, m: int, dead: int, floor: float, win: int) -> tuple[int, float]:
    """Per-sample Python loops as in Appendix A.2 (activity count) and A.3 (windowed distance)."""
    n = acc.shape[0]
    mov = acc.copy()
    for i in range(m, n - m):
        mov[i] = acc[i - m : i + m + 1].sum(axis=0) / (2 * m + 1)
    h = acc - mov
    for j in range(3):
        for i in range(n):
            if abs(h[i, j]) <= floor:
                h[i, j] = 0.0
    norm = np.sqrt((h * h).sum(axis=1))
    count, zeros, in_act = 0, dead, False
    for i in range(n):
        if norm[i] != 0:
            if not in_act:
                count += 1
                in_act = True
            zeros = 0
        else:
            zeros += 1
            if zeros >= dead:
                in_act = False
    dt = 1.0 / rate
    dist = np.zeros((n, 3))
    vel = np.zeros((n, 3))
    for j in range(3):
        for k in range(n):
            if k % win == 0:
                continue
            s = 1.0 if acc[k, j] > acc[k - 1, j] else -1.0
            vel[k, j] = vel[k - 1, j] + s * dt * h[k, j]
            dist[k, j] = dist[k - 1, j] + dt * vel[k - 1, j]
    return count, float(dist.max())


def timed(fn, *args) -> float:
    t0 = time.perf_counter()
    fn(*args)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--rate", type=float, default=115.0)
    ap.add_argument("--baseline-s", type=float, default=120.0, help="excerpt length for the loop baseline, s")
    args = ap.parse_args()
    n = int(args.hours * 3600 * args.rate)
    acc = synthetic(n, args.rate)
    params = ActivityCountParams.for_rate(args.rate, noise_floor_g=0.02)
    rows = {
        "arm_usage": timed(arm_usage, acc),
        "activity_count_sign": timed(activity_count_sign, acc),
        "activity_count_dead_period": timed(activity_count_dead_period, acc, params),
        "distance_histogram": timed(distance_histogram, acc, args.rate),
    }
    total = sum(rows.values())
    print(f"{n} samples ({args.hours} h at {args.rate} Hz)")
    for name, sec in rows.items():
        print(f"  {name:<28} {sec * 1e3:8.1f} ms  {n / sec / 1e6:8.2f} M samples/s")
    nb = int(args.baseline_s * args.rate)
    excerpt = acc[:nb]
    t_loop = timed(
        loop_baseline,
        excerpt,
        args.rate,
        params.m_samples,
        params.dead_samples,
        params.noise_floor_g,
        int(5 * args.rate),
    )
    t_vec = timed(activity_count_dead_period, excerpt, params) + timed(distance_histogram, excerpt, args.rate)
    print(f"baseline (per-sample loops, Doshi A.2/A.3) on {nb} samples: {nb / t_loop / 1e6:.3f} M samples/s")
    print(f"vectorised activity + distance on the same excerpt: {nb / t_vec / 1e6:.2f} M samples/s")
    print(f"speed-up vs loops: {t_loop / t_vec:.0f}x;  all four metrics on {args.hours} h: {total:.2f} s")


if __name__ == "__main__":
    main()
