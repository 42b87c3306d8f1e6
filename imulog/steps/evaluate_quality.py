"""What ``imulog evaluate`` says about the repetitions it cannot trust: phases forced by event correction,
low confidence, and the repetition flags (issue 31), each with the errors of those repetitions apart."""

from __future__ import annotations

from typing import Any

import numpy as np


def phase_quality_summary(
    evaluation: dict[str, Any],
    timing: dict[str, Any],
    low: float = 0.5,
    flagged: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """How the trajectory errors depend on how much event correction forced the phases (issue 19).

    ``evaluation``: the ``imulog.evaluation`` record; ``timing``: the ``imulog.timing`` record of the phases step
    (``repetition_quality``); ``flagged``: the repetition flags (``imulog.trajectory["flagged_repetitions"]``).
    Returns the repetitions with forced phases, those below confidence ``low``, the flagged ones with their
    reasons and, per method, the mean MAE over the axes (cm) on confident and on low-confidence repetitions, and
    on unflagged and flagged ones. Empty when the phases carry no quality record (phases step of an older
    imulog)."""
    quality = {int(q["repetition"]): q for q in timing.get("repetition_quality") or []}
    if not quality:
        return {}
    forced = sorted(k for k, q in quality.items() if int(q.get("forced") or 0) > 0)
    low_reps = sorted(k for k, q in quality.items() if float(q.get("confidence", 1.0)) < low)
    reasons = {int(f["repetition"]): list(f.get("reasons") or []) for f in flagged or []}
    per_method: dict[str, dict[str, Any]] = {}
    per_flag: dict[str, dict[str, Any]] = {}
    for method, rec in (evaluation.get("methods") or {}).items():
        groups: dict[str, list[float]] = {"confident": [], "low_confidence": []}
        by_flag: dict[str, list[float]] = {"unflagged": [], "flagged": []}
        for row in rec.get("repetitions") or []:
            values = [row[a]["mae_cm"] for a in ("x", "y", "z") if isinstance(row.get(a), dict) and "mae_cm" in row[a]]
            if not values:
                continue
            k = int(row.get("repetition", -1))
            groups["low_confidence" if k in low_reps else "confident"].append(float(np.mean(values)))
            by_flag["flagged" if k in reasons else "unflagged"].append(float(np.mean(values)))
        per_method[method] = _means(groups)
        per_flag[method] = _means(by_flag)
    out = {
        "forced_repetitions": forced,
        "low_confidence_repetitions": low_reps,
        "threshold": low,
        "methods": per_method,
    }
    if flagged:  # the repetition flags and each method's errors on flagged and unflagged repetitions apart
        out["flagged_repetitions"] = [{"repetition": k, "reasons": v} for k, v in reasons.items()]
        out["flagged_methods"] = per_flag
    return out


def _means(groups: dict[str, list[float]]) -> dict[str, dict[str, Any]]:
    return {k: {"n": len(v), "mae_cm": round(float(np.mean(v)), 3) if v else None} for k, v in groups.items()}


def format_phase_quality(summary: dict[str, Any]) -> str:
    """Lines for ``imulog evaluate``: which repetitions' phases were forced and their errors apart."""
    if not summary:
        return ""
    lines = [
        "phases forced by event correction in repetitions "
        f"{', '.join(map(str, summary['forced_repetitions'])) or '-'}; confidence < {summary['threshold']} in "
        f"{', '.join(map(str, summary['low_confidence_repetitions'])) or '-'}"
    ]
    for method, groups in summary["methods"].items():
        c, lo = groups["confident"], groups["low_confidence"]
        if lo["n"]:
            lines.append(
                f"  {method}: mean MAE {c['mae_cm']} cm on {c['n']} confident, {lo['mae_cm']} cm on {lo['n']} "
                "low-confidence repetitions"
            )
    flagged = summary.get("flagged_repetitions") or []
    if flagged:
        shown = ", ".join(f"{f['repetition']} ({', '.join(f['reasons'])})" for f in flagged[:12])
        lines.append(f"flagged repetitions: {shown}{f' +{len(flagged) - 12} more' if len(flagged) > 12 else ''}")
        for method, groups in (summary.get("flagged_methods") or {}).items():
            u, f = groups["unflagged"], groups["flagged"]
            if f.get("n"):
                lines.append(
                    f"  {method}: mean MAE {u['mae_cm']} cm on {u['n']} unflagged, {f['mae_cm']} cm on {f['n']} "
                    "flagged repetitions"
                )
    return "\n".join(lines)
