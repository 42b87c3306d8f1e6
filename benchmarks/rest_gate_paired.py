"""Paired comparison of the accelerometer's rest gate over many simulated trials (issue 32).

``rest_gate_effect.py`` gives the grid's mean MAE over 2 trials x 8 repetitions per condition, gate off and on.
A difference there can be one repetition. This script runs the same pipeline (``trajectory_accuracy``'s
simulated R2G trials, subject k with seed k) for ``--subjects`` trials, pairs every repetition gate off / gate on
by (subject, repetition index), and prints per condition and method, per axis (cm): the mean of off, the mean of
on, the mean paired difference on - off with its 95 % bootstrap interval, the median difference, and how many
repetitions got worse / better by more than 0.5 cm. Repetitions the gate changes nothing at are counted too.

    python benchmarks/rest_gate_paired.py --grid stroke combined-stroke --subjects 12 --repetitions 8

``--first-subject N`` runs subjects (and seeds) N, N+1, ... (held-out seeds); ``--static gyro-norm`` gives the
phases step a zero-velocity mask from the angular rate alone (every gyroscope-still translation is a candidate
rest: the gate's hardest input); ``--methods`` any of ``trajectory_opt.METHODS``, comma-separated.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from trajectory_accuracy import evaluate_trial, simulated_inputs  # noqa: E402

from imulog.process.rests import RestParams  # noqa: E402
from imulog.process.trajectory_opt import DEFAULT_PARAMS  # noqa: E402


def paired_errors(
    name: str, subjects: range, repetitions: int, methods: tuple[str, ...], static: str = "movements"
) -> dict:
    """{method: (off (K, 3), on (K, 3), keys [(subject, repetition), ...])} MAE per axis (cm) of the K
    repetitions found with both gates; ``static``: the phases step's zero-velocity mask."""
    from imulog.simulate.grid import condition

    off = replace(DEFAULT_PARAMS, rests=RestParams(enabled=False))
    out: dict[str, tuple[list, list, list]] = {m: ([], [], []) for m in methods}
    for s in subjects:
        by_gate = {}
        for gate, p in (("off", off), ("on", DEFAULT_PARAMS)):
            inputs = simulated_inputs(
                s, seed=s, repetitions=repetitions, rests=p.rests, static=static, **condition(name)
            )
            records, _, _ = evaluate_trial(inputs, methods, p)
            by_gate[gate] = {m: {r["repetition"]: [r[a]["mae_cm"] for a in "xyz"] for r in records[m]} for m in methods}
        for m in methods:
            for k in sorted(set(by_gate["off"][m]) & set(by_gate["on"][m])):
                out[m][0].append(by_gate["off"][m][k])
                out[m][1].append(by_gate["on"][m][k])
                out[m][2].append((s, k))
    return {m: (np.array(a), np.array(b), keys) for m, (a, b, keys) in out.items()}


def bootstrap_ci(d: np.ndarray, n: int = 2000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """95 % bootstrap interval of the mean of ``d`` (K, 3) per column."""
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(d), size=(n, len(d)))
    means = d[idx].mean(axis=1)
    return np.percentile(means, 2.5, axis=0), np.percentile(means, 97.5, axis=0)


def rows(
    conditions: list[str],
    subjects: int,
    repetitions: int,
    methods: tuple[str, ...],
    first: int = 0,
    static: str = "movements",
) -> list[str]:
    f = lambda v: " / ".join(f"{x:.2f}" for x in v)  # noqa: E731
    g = lambda v: " / ".join(f"{x:+.2f}" for x in v)  # noqa: E731
    lines = [
        "| condition | method | pairs | off x/y/z (cm) | on x/y/z (cm) | mean on - off (cm) | 95 % CI of the mean "
        "difference (cm) | median difference (cm) | worse / better by > 0.5 cm (3D sum) | unchanged |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    worse: list[str] = []
    for name in conditions:
        subjects_k = range(first, first + subjects)
        for m, (a, b, keys) in paired_errors(name, subjects_k, repetitions, methods, static).items():
            if not len(a):
                continue
            d = b - a
            lo, hi = bootstrap_ci(d)
            s = d.sum(axis=1)
            ci = " / ".join(f"[{x:+.2f}, {y:+.2f}]" for x, y in zip(lo, hi, strict=True))
            lines.append(
                f"| {name} | {m} | {len(d)} | {f(a.mean(0))} | {f(b.mean(0))} | {g(d.mean(0))} | {ci} | "
                f"{g(np.median(d, axis=0))} | {(s > 0.5).sum()} / {(s < -0.5).sum()} | "
                f"{int((np.abs(d).max(axis=1) < 1e-9).sum())} |"
            )
            print(lines[-1], flush=True, file=sys.stderr)
            for i in np.flatnonzero(np.abs(s) > 0.5):
                worse.append(f"{name} {m} subject {keys[i][0]} repetition {keys[i][1]}: {f(a[i])} -> {f(b[i])} cm")
    if worse:
        lines += ["", "Repetitions that changed by more than 0.5 cm (3D sum of the per-axis MAE), off -> on:", ""]
        lines += [f"- {w}" for w in worse]
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--grid", nargs="+", default=["stroke", "combined-stroke"])
    ap.add_argument("--subjects", type=int, default=12)
    ap.add_argument("--repetitions", type=int, default=8)
    ap.add_argument("--first-subject", type=int, default=0, help="subjects (and seeds) N, N+1, ... (held-out runs)")
    ap.add_argument("--methods", default="zupt,zupt_bias")
    ap.add_argument(
        "--static",
        default="movements",
        choices=("movements", "gyro-norm"),
        help="the phases step's zero-velocity mask (gyro-norm: the angular rate alone; the gate's hardest input)",
    )
    args = ap.parse_args(argv)
    methods = tuple(args.methods.split(","))
    print("\n".join(rows(args.grid, args.subjects, args.repetitions, methods, args.first_subject, args.static)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
