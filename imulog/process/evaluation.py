"""Trajectory errors against an optical reference (R2G thesis 3.4, Table 3.1).

Both trajectories are sampled at the same times (N,) in one frame. Each is taken relative to its own
first valid sample (a single IMU reconstructs displacement, not absolute position), then per axis:

* ``mae_cm``: mean absolute error (cm);
* ``rom_pct``: that error as % of the reference's range of motion (max - min) on the axis;
* ``rmse_cm``: root mean square error (cm);
* ``final_cm``: absolute error of the final displacement (cm), plus its 3D norm ``final_norm_cm``;
* ``spearman``: Spearman rank correlation between estimate and reference;
* ``median_cm``, ``p90_cm``: median and 90th percentile of the absolute error (cm), robust to a few bad
  samples; ``rom_cm``: the reference's range of motion (max - min) on the axis.

Per window also ``reach_cm`` (the reference's largest distance from its start, the motion itself),
``rmse_norm_cm`` (3D) and ``exceeds_motion``: the 3D RMS error is larger than the reach, so the estimate
says less about the motion than staying at the start would.

Rows where either trajectory is NaN are ignored. :func:`aggregate` pools per-repetition results into
the thesis's table: method x axis, mean +- standard deviation over repetitions.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy import stats

AXES = ("x", "y", "z")
METRICS = ("mae_cm", "rom_pct", "rmse_cm", "final_cm", "spearman", "median_cm", "p90_cm", "rom_cm")


def relative_to_start(pos: np.ndarray) -> np.ndarray:
    """Positions minus the first row where all coordinates are finite."""
    p = np.asarray(pos, dtype=np.float64)
    ok = np.flatnonzero(np.all(np.isfinite(p), axis=1))
    if len(ok) == 0:
        return np.full_like(p, np.nan)
    return p - p[ok[0]]


def trajectory_errors(estimate_m: np.ndarray, reference_m: np.ndarray, *, align_start: bool = True) -> dict[str, Any]:
    """Error metrics of one trajectory segment (N, D) against the reference (N, D), both in m."""
    est = np.asarray(estimate_m, dtype=np.float64)
    ref = np.asarray(reference_m, dtype=np.float64)
    if est.shape != ref.shape:
        raise ValueError(f"estimate {est.shape} and reference {ref.shape} differ in shape")
    ok = np.all(np.isfinite(est), axis=1) & np.all(np.isfinite(ref), axis=1)
    est, ref = est[ok], ref[ok]
    if len(est) < 2:
        raise ValueError("fewer than 2 valid samples to compare")
    if align_start:
        est, ref = est - est[0], ref - ref[0]
    err = est - ref
    rom = ref.max(axis=0) - ref.min(axis=0)
    mae = np.mean(np.abs(err), axis=0)
    out: dict[str, Any] = {"n_samples": int(len(est))}
    names = AXES[: est.shape[1]] if est.shape[1] <= 3 else [str(i) for i in range(est.shape[1])]
    for j, axis in enumerate(names):
        rho = stats.spearmanr(est[:, j], ref[:, j]).statistic if np.ptp(est[:, j]) > 0 and rom[j] > 0 else np.nan
        out[axis] = {
            "mae_cm": float(100 * mae[j]),
            "rom_pct": float(100 * mae[j] / rom[j]) if rom[j] > 0 else float("nan"),
            "rmse_cm": float(100 * np.sqrt(np.mean(err[:, j] ** 2))),
            "final_cm": float(100 * abs(err[-1, j])),
            "spearman": float(rho),
            "rom_cm": float(100 * rom[j]),
            "median_cm": float(100 * np.median(np.abs(err[:, j]))),
            "p90_cm": float(100 * np.percentile(np.abs(err[:, j]), 90)),
        }
    out["final_norm_cm"] = float(100 * np.linalg.norm(err[-1]))
    out["mae_norm_cm"] = float(100 * np.mean(np.linalg.norm(err, axis=1)))
    out["rmse_norm_cm"] = float(100 * np.sqrt(np.mean(np.sum(err**2, axis=1))))
    out["reach_cm"] = float(100 * np.max(np.linalg.norm(ref - ref[0], axis=1)))
    out["exceeds_motion"] = bool(out["rmse_norm_cm"] > out["reach_cm"])
    return out


def evaluate_segments(
    t_s: np.ndarray,
    estimate_m: np.ndarray,
    reference_m: np.ndarray,
    segments_s: Sequence[tuple[float, float]],
    labels: Sequence[Any] | None = None,
) -> list[dict[str, Any]]:
    """:func:`trajectory_errors` on each [start, end] s window (e.g. one per repetition)."""
    t = np.asarray(t_s, dtype=np.float64)
    results = []
    for k, (t0, t1) in enumerate(segments_s):
        sel = (t >= t0) & (t <= t1)
        if np.count_nonzero(sel) < 2:
            continue
        try:
            r = trajectory_errors(estimate_m[sel], reference_m[sel])
        except ValueError:
            continue
        r["segment"] = labels[k] if labels is not None else k + 1
        r["start_s"], r["end_s"] = float(t0), float(t1)
        results.append(r)
    return results


def summarize(
    results: Iterable[Mapping[str, Any]], axes: Sequence[str] = AXES
) -> dict[str, dict[str, dict[str, float]]]:
    """Mean and standard deviation over results: {axis: {metric: {"mean", "std", "n"}}}."""
    rows = list(results)
    out: dict[str, dict[str, dict[str, float]]] = {}
    for axis in axes:
        out[axis] = {}
        for metric in METRICS:
            # (records of an older imulog lack the robust figures: those metrics are then empty)
            v = np.array([r[axis][metric] for r in rows if axis in r and metric in r[axis]], dtype=np.float64)
            v = v[np.isfinite(v)]
            out[axis][metric] = {
                "mean": float(np.mean(v)) if len(v) else float("nan"),
                "std": float(np.std(v, ddof=1)) if len(v) > 1 else float("nan"),
                "n": int(len(v)),
            }
    return out


def aggregate(
    per_method: Mapping[str, Iterable[Mapping[str, Any]]],
) -> dict[str, dict[str, dict[str, dict[str, float]]]]:
    """Table 3.1: {method: summarize(results of that method)}."""
    return {method: summarize(rows) for method, rows in per_method.items()}


def _fmt(mean: float, std: float) -> str:
    def f(v: float) -> str:
        if not np.isfinite(v):
            return "nan"
        return f"{v:.2f}" if abs(v) < 10 else f"{v:.1f}" if abs(v) < 100 else f"{v:.0f}"

    return f"{f(mean)}±{f(std)}"


def format_table(
    table: Mapping[str, Mapping[str, Mapping[str, Mapping[str, float]]]], axes: Sequence[str] = AXES
) -> str:
    """Plain-text table shaped like the thesis's Table 3.1: method x axis, MAE cm and % of ROM, mean±std."""
    head = ["method"] + [f"MAE {a} (cm)" for a in axes] + [f"{a} (% ROM)" for a in axes] + ["n"]
    lines = []
    for method, summ in table.items():
        cells = [method]
        cells += [_fmt(summ[a]["mae_cm"]["mean"], summ[a]["mae_cm"]["std"]) for a in axes]
        cells += [_fmt(summ[a]["rom_pct"]["mean"], summ[a]["rom_pct"]["std"]) for a in axes]
        cells.append(str(summ[axes[0]]["mae_cm"]["n"]))
        lines.append(cells)
    widths = [max(len(r[i]) for r in [head, *lines]) for i in range(len(head))]
    fmt = "  ".join(f"{{:<{w}}}" for w in widths)
    return "\n".join([fmt.format(*head), fmt.format(*["-" * w for w in widths])] + [fmt.format(*r) for r in lines])


def format_robust(
    table: Mapping[str, Mapping[str, Mapping[str, Mapping[str, float]]]],
    exceeding: Mapping[str, tuple[int, int]],
    baseline: str | None = None,
    axes: Sequence[str] = AXES,
) -> str:
    """Robust figures per method: mean over windows of the median and 90th-percentile absolute error per axis
    (cm), the reference's range of motion per window (cm), windows whose error exceeds the motion (of all),
    and whether the method's MAE beats ``baseline``'s on every axis."""
    head = (
        ["method"] + [f"median {a}" for a in axes] + [f"p90 {a}" for a in axes] + ["ROM x/y/z (cm)", "error > motion"]
    )
    if baseline:
        head.append(f"beats {baseline}")
    base = table.get(baseline) if baseline else None

    def f(v: float) -> str:
        return (
            "nan" if not np.isfinite(v) else f"{v:.2f}" if abs(v) < 10 else f"{v:.1f}" if abs(v) < 100 else f"{v:.0f}"
        )

    lines = []
    for method, summ in table.items():
        cells = [method]
        cells += [f(summ[a]["median_cm"]["mean"]) for a in axes]
        cells += [f(summ[a]["p90_cm"]["mean"]) for a in axes]
        cells.append("/".join(f"{summ[a]['rom_cm']['mean']:.0f}" for a in axes))
        k, n = exceeding.get(method, (0, 0))
        cells.append(f"{k} of {n}")
        if baseline:
            if method == baseline or base is None:
                cells.append("-")
            else:
                better = [summ[a]["mae_cm"]["mean"] < base[a]["mae_cm"]["mean"] for a in axes]
                cells.append(
                    "yes" if all(better) else "no" if not any(better) else f"{sum(better)} of {len(axes)} axes"
                )
        lines.append(cells)
    widths = [max(len(r[i]) for r in [head, *lines]) for i in range(len(head))]
    fmt = "  ".join(f"{{:<{w}}}" for w in widths)
    return "\n".join([fmt.format(*head), fmt.format(*["-" * w for w in widths])] + [fmt.format(*r) for r in lines])
