"""Reports from a catalog: the accuracy table (R2G thesis Table 3.1), per-subject error plots, phase timings.

    from imulog.batch.report import write_report
    files = write_report("catalog.parquet", "report/")

Writes into the output folder:

* ``accuracy.md`` / ``accuracy.csv``: method x axis, MAE (cm) and MAE as % of the reference's range of motion,
  mean ± standard deviation over every evaluated repetition of every trial (the thesis's Table 3.1 pools the
  825 movements of 11 subjects the same way), with the number of repetitions, trials and subjects; the CSV adds
  medians (a mis-segmented repetition with almost no reference motion inflates the mean % ROM);
* ``subject_errors.csv`` and ``subject_errors.png``: mean ± std MAE per subject, method and axis (one panel per
  axis, log scale: integration methods differ by orders of magnitude);
* ``timing.md`` / ``timing.csv``: per phase label, duration (s) and peak angular velocity (rad/s) statistics,
  and ``timing_by_subject.csv``;
* ``report.md``: all tables in one page, linking the plot.

Only the catalog's columns are read (never the trials). Plots need matplotlib (``pip install 'imulog[report]'``);
``plots=False`` writes the tables only.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

from imulog.process.evaluation import AXES, summarize
from imulog.process.trajectory_opt import METHODS

COLUMNS = ["path", "subject", "trial", "task", "evaluation_json", "timing_json", "error"]


def _fmt(mean: float, std: float, digits: int = 2) -> str:
    def f(v: float) -> str:
        return "nan" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"

    return f"{f(mean)} ± {f(std)}"


def _order(methods) -> list[str]:
    """Methods in the docs' order; labels ``method (imu)`` by IMU, then that order."""

    def key(label: str) -> tuple:
        method, _, imu = label.partition(" (")
        return (imu, METHODS.index(method) if method in METHODS else len(METHODS), method)

    return sorted(methods, key=key)


def load_catalog(catalog: str | os.PathLike[str]):
    """The report's columns of the catalog as a pandas DataFrame (rows with errors dropped)."""
    import pandas as pd

    df = pd.read_parquet(catalog, columns=COLUMNS)
    return df[df["error"].isna()].reset_index(drop=True)


def repetition_errors(df) -> list[dict[str, Any]]:
    """Long table: one row per (trial, method, repetition, axis) with mae_cm, rom_pct, rmse_cm, final_cm."""
    rows = []
    for rec, method, content in method_evaluations(df):
        for rep in content.get("repetitions") or []:
            for axis in AXES:
                if axis not in rep:
                    continue
                rows.append(
                    {
                        "path": rec.path,
                        "subject": rec.subject,
                        "trial": rec.trial,
                        "method": method,
                        "repetition": rep.get("repetition"),
                        "axis": axis,
                        **{k: rep[axis].get(k) for k in ("mae_cm", "rom_pct", "rmse_cm", "final_cm", "spearman")},
                    }
                )
    return rows


def method_evaluations(df) -> list[tuple[Any, str, dict[str, Any]]]:
    """``(catalog row, method label, the method's evaluation)`` for every IMU of every trial: the primary IMU's
    record and a setup's other IMUs (``per_imu``). The label is the method, or ``method (imu)`` when the catalog
    holds more than one IMU, so errors of different body segments are never pooled into one row."""
    found = []
    for rec in df.itertuples(index=False):
        if not isinstance(rec.evaluation_json, str):
            continue
        ev = json.loads(rec.evaluation_json)
        found.append((rec, str(ev.get("imu") or "").removeprefix("/imu/"), ev))
        found += [(rec, str(imu), sub) for imu, sub in (ev.get("per_imu") or {}).items() if isinstance(sub, dict)]
    several = len({imu for _, imu, _ in found}) > 1
    return [
        (rec, f"{method} ({imu})" if several and imu else method, content)
        for rec, imu, ev in found
        for method, content in (ev.get("methods") or {}).items()
    ]


def accuracy_table(df) -> list[dict[str, Any]]:
    """Table 3.1 rows: per method and axis, mean/std of MAE (cm) and % ROM over all repetitions."""
    per_method: dict[str, list[dict[str, Any]]] = {}
    trials: dict[str, set] = {}
    subjects: dict[str, set] = {}
    for rec, method, content in method_evaluations(df):
        reps = content.get("repetitions") or []
        per_method.setdefault(method, []).extend(reps)
        if reps:
            trials.setdefault(method, set()).add(rec.path)
            subjects.setdefault(method, set()).add(rec.subject)
    out = []
    for method in _order(per_method):
        summ = summarize(per_method[method])
        for axis in AXES:
            s = summ[axis]
            out.append(
                {
                    "method": method,
                    "axis": axis,
                    "mae_cm_mean": s["mae_cm"]["mean"],
                    "mae_cm_std": s["mae_cm"]["std"],
                    "rom_pct_mean": s["rom_pct"]["mean"],
                    "rom_pct_std": s["rom_pct"]["std"],
                    "mae_cm_median": _median([r[axis]["mae_cm"] for r in per_method[method] if axis in r]),
                    "rom_pct_median": _median([r[axis]["rom_pct"] for r in per_method[method] if axis in r]),
                    "rmse_cm_mean": s["rmse_cm"]["mean"],
                    "n_repetitions": s["mae_cm"]["n"],
                    "n_trials": len(trials.get(method, ())),
                    "n_subjects": len(subjects.get(method, ())),
                }
            )
    return out


def accuracy_markdown(table: list[dict[str, Any]]) -> str:
    """Table 3.1 layout: one row per method, MAE x/y/z (cm) then % ROM x/y/z, mean ± std."""
    by_method: dict[str, dict[str, dict]] = {}
    for r in table:
        by_method.setdefault(r["method"], {})[r["axis"]] = r
    head = ["method"] + [f"MAE {a} (cm)" for a in AXES] + [f"{a} (% ROM)" for a in AXES] + ["repetitions", "subjects"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for method, axes in by_method.items():
        cells = [method]
        cells += [_fmt(axes[a]["mae_cm_mean"], axes[a]["mae_cm_std"]) if a in axes else "" for a in AXES]
        cells += [_fmt(axes[a]["rom_pct_mean"], axes[a]["rom_pct_std"], 1) if a in axes else "" for a in AXES]
        first = next(iter(axes.values()))
        cells += [str(first["n_repetitions"]), str(first["n_subjects"])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _median(values: list[float]) -> float:
    v = sorted(x for x in values if x is not None and math.isfinite(x))
    if not v:
        return float("nan")
    k = len(v) // 2
    return v[k] if len(v) % 2 else (v[k - 1] + v[k]) / 2


def _mean_std(values: list[float]) -> tuple[float, float, int]:
    v = [x for x in values if x is not None and math.isfinite(x)]
    if not v:
        return float("nan"), float("nan"), 0
    mean = sum(v) / len(v)
    std = math.sqrt(sum((x - mean) ** 2 for x in v) / (len(v) - 1)) if len(v) > 1 else float("nan")
    return mean, std, len(v)


def subject_errors(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per subject, method and axis: mean ± std MAE (cm) over that subject's repetitions."""
    groups: dict[tuple, list[float]] = {}
    for r in rows:
        groups.setdefault((str(r["subject"]), r["method"], r["axis"]), []).append(r["mae_cm"])
    out = []
    for (subject, method, axis), vals in sorted(groups.items()):
        mean, std, n = _mean_std(vals)
        out.append({"subject": subject, "method": method, "axis": axis, "mae_cm_mean": mean, "mae_cm_std": std, "n": n})
    return out


def timing_rows(df) -> list[dict[str, Any]]:
    """One row per detected phase: subject, trial, repetition, label, duration_s, peak angular velocity."""
    rows = []
    for rec in df.itertuples(index=False):
        if not isinstance(rec.timing_json, str):
            continue
        timing = json.loads(rec.timing_json)
        phases = timing.get("phases") or []
        if isinstance(phases, str):
            phases = json.loads(phases)
        for ph in phases:
            rows.append(
                {
                    "subject": rec.subject,
                    "trial": rec.trial,
                    "repetition": ph.get("repetition"),
                    "label": ph.get("label"),
                    "duration_s": ph.get("duration_s"),
                    "peak_angular_velocity_rad_s": ph.get("peak_angular_velocity_rad_s"),
                }
            )
    return rows


def timing_stats(rows: list[dict[str, Any]], by_subject: bool = False) -> list[dict[str, Any]]:
    """Per phase label (and subject): n, mean/std/min/max duration (s), mean peak angular velocity (rad/s)."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        key = (str(r["subject"]), r["label"]) if by_subject else (r["label"],)
        groups.setdefault(key, []).append(r)
    order = {label: i for i, label in enumerate(("reach", "lift", "return_bottle", "return_hand"))}
    out = []
    for key in sorted(groups, key=lambda k: (k[:-1], order.get(k[-1], 99), k[-1])):
        items = groups[key]
        d = [float(x["duration_s"]) for x in items if x["duration_s"] is not None]
        mean, std, n = _mean_std(d)
        peak, _, _ = _mean_std(
            [float(x["peak_angular_velocity_rad_s"]) for x in items if x["peak_angular_velocity_rad_s"] is not None]
        )
        row = {"label": key[-1], "n": n, "duration_mean_s": mean, "duration_std_s": std}
        row["duration_min_s"] = min(d) if d else float("nan")
        row["duration_max_s"] = max(d) if d else float("nan")
        row["peak_angular_velocity_mean_rad_s"] = peak
        if by_subject:
            row = {"subject": key[0], **row}
        out.append(row)
    return out


def timing_markdown(stats: list[dict[str, Any]]) -> str:
    head = ["phase", "n", "duration (s)", "min (s)", "max (s)", "peak ω (rad/s)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in stats:
        lines.append(
            f"| {r['label']} | {r['n']} | {_fmt(r['duration_mean_s'], r['duration_std_s'], 3)} | "
            f"{r['duration_min_s']:.3f} | {r['duration_max_s']:.3f} | {r['peak_angular_velocity_mean_rad_s']:.2f} |"
        )
    return "\n".join(lines)


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    import pandas as pd

    pd.DataFrame(rows).to_csv(path, index=False)


def plot_subject_errors(rows: list[dict[str, Any]], path: Path) -> Path:
    """PNG: per axis, mean ± std MAE (cm) per subject, one series per method (log scale)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise RuntimeError(
            "per-subject error plots need matplotlib: pip install 'imulog[report]' (or write tables only: --no-plots)"
        ) from exc
    subjects = sorted({r["subject"] for r in rows})
    methods = _order({r["method"] for r in rows})
    index = {(r["subject"], r["method"], r["axis"]): r for r in rows}
    fig, axes = plt.subplots(1, len(AXES), figsize=(4.2 * len(AXES) + 1.5, 4.0), sharey=True, squeeze=False)
    width = 0.8 / max(1, len(methods))
    for j, axis in enumerate(AXES):
        ax = axes[0][j]
        for k, method in enumerate(methods):
            xs, ys, es = [], [], []
            for i, subject in enumerate(subjects):
                r = index.get((subject, method, axis))
                if r is None or not math.isfinite(r["mae_cm_mean"]):
                    continue
                xs.append(i - 0.4 + width * (k + 0.5))
                ys.append(r["mae_cm_mean"])
                es.append(r["mae_cm_std"] if math.isfinite(r["mae_cm_std"]) else 0.0)
            ax.bar(xs, ys, width=width, yerr=es, capsize=1.5, label=method)
        ax.set_xticks(range(len(subjects)))
        ax.set_xticklabels(subjects, rotation=90 if len(subjects) > 6 else 0)
        ax.set_title(f"{axis} axis")
        ax.set_yscale("log")
        ax.grid(axis="y", which="both", alpha=0.3)
        if j == 0:
            ax.set_ylabel("MAE vs optical reference (cm)")
    axes[0][-1].legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize="small")
    fig.suptitle("Trajectory error per subject (mean ± std over repetitions)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(
    catalog: str | os.PathLike[str], out_dir: str | os.PathLike[str], *, plots: bool = True
) -> dict[str, Path]:
    """Write the report files (see the module docstring) and return them by name."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    df = load_catalog(catalog)
    files: dict[str, Path] = {}
    table = accuracy_table(df)
    reps = repetition_errors(df)
    per_subject = subject_errors(reps)
    trows = timing_rows(df)
    tstats = timing_stats(trows)
    _write_csv(out / "accuracy.csv", table)
    files["accuracy.csv"] = out / "accuracy.csv"
    acc_md = accuracy_markdown(table) if table else "_no evaluated trials in the catalog (run the evaluate step)_"
    (out / "accuracy.md").write_text(acc_md + "\n")
    files["accuracy.md"] = out / "accuracy.md"
    _write_csv(out / "subject_errors.csv", per_subject)
    files["subject_errors.csv"] = out / "subject_errors.csv"
    _write_csv(out / "timing.csv", tstats)
    files["timing.csv"] = out / "timing.csv"
    _write_csv(out / "timing_by_subject.csv", timing_stats(trows, by_subject=True))
    files["timing_by_subject.csv"] = out / "timing_by_subject.csv"
    tim_md = timing_markdown(tstats) if tstats else "_no phase timings in the catalog (run the phases step)_"
    (out / "timing.md").write_text(tim_md + "\n")
    files["timing.md"] = out / "timing.md"
    if plots and per_subject:
        files["subject_errors.png"] = plot_subject_errors(per_subject, out / "subject_errors.png")
    n_subjects = df["subject"].nunique()
    page = [
        "# imulog report",
        "",
        f"Catalog `{catalog}`: {len(df)} trials, {n_subjects} subjects.",
        "",
        "## Trajectory accuracy (method x axis, mean ± std over repetitions)",
        "",
        acc_md,
        "",
        "## Phase timings",
        "",
        tim_md,
        "",
    ]
    if "subject_errors.png" in files:
        page += ["## Errors per subject", "", "![errors per subject](subject_errors.png)", ""]
    (out / "report.md").write_text("\n".join(page))
    files["report.md"] = out / "report.md"
    return files
