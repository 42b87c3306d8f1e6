"""The final table of ``benchmarks/bench_long.py`` (issue 24's "Done when"): per command its peak RSS, CPU and
wall time at each length, the growth of peak RSS from the shortest to the longest, and PASS/FAIL against 1 GB and
1.15x; and the same as a summary file (``.json``, or Markdown for any other suffix) that the docs can cite.

Pure functions of the measured results, apart from :func:`write_summary` (writes the file) and :func:`run_info`
(asks git for the commit)."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

MAX_RSS_MB = 1024.0  # issue 24: every command in at most 1 GB
MAX_GROWTH = 1.15  # issue 24: peak memory from the shortest to the longest recording

#: one command at one length: (wall s, peak RSS MB, CPU s: user + sys of the child) or the failure's message
Result = tuple[float, float, float] | str


def table_rows(names: list[str], results: dict[float, dict[str, Result]], days: list[float]) -> list[dict]:
    """One row per command: ``runs`` (per length ``{"rss_mb", "cpu_s", "wall_s"}``, ``{"failed": msg}`` or
    ``None`` when not run), ``growth`` (peak RSS at the longest over the shortest length; ``None`` with one length
    or a failure), ``peak_mb`` and ``verdict`` ("PASS" or "FAIL") with ``why`` (the limits missed, or the
    failure)."""
    lo, hi = min(days), max(days)
    rows = []
    for name in names:
        got = {d: results.get(d, {}).get(name) for d in days}
        runs: dict[str, dict | None] = {}
        for d, r in got.items():
            if r is None:
                runs[f"{d:g}"] = None
            elif isinstance(r, str):
                runs[f"{d:g}"] = {"failed": r}
            else:
                runs[f"{d:g}"] = {"wall_s": round(r[0], 1), "rss_mb": round(r[1], 1), "cpu_s": round(r[2], 1)}
        why = [f"{d:g} d failed: {r}" for d, r in got.items() if isinstance(r, str)]
        why += [f"{d:g} d not run" for d, r in got.items() if r is None]
        measured = [r for r in got.values() if isinstance(r, tuple)]
        peak = max((r[1] for r in measured), default=None)
        growth = None
        if not why and hi != lo:
            growth = got[hi][1] / got[lo][1]
        if peak is not None and peak > MAX_RSS_MB:
            why.append(f"peak {peak:.0f} MB > {MAX_RSS_MB:.0f} MB")
        if growth is not None and growth > MAX_GROWTH:
            why.append(f"growth {growth:.2f}x > {MAX_GROWTH}x")
        rows.append(
            {
                "command": name,
                "runs": runs,
                "peak_mb": None if peak is None else round(peak, 1),
                "growth": None if growth is None else round(growth, 3),
                "verdict": "FAIL" if why else "PASS",
                "why": "; ".join(why),
            }
        )
    return rows


def _cell(run: dict | None, key: str, fmt: str) -> str:
    if run is None:
        return "not run"
    if "failed" in run:
        return "FAILED"
    return format(run[key], fmt)


def format_table(rows: list[dict], days: list[float]) -> str:
    """The rows as a fixed-width text table: peak RSS (MB), CPU (s, user + sys of the child) and wall (s) at
    each length, the growth and the verdict with its reasons."""
    keys = [f"{d:g}" for d in days]
    columns = [(f"{k} d MB", k, "rss_mb", ".0f") for k in keys]
    columns += [(f"{k} d CPU s", k, "cpu_s", ".1f") for k in keys]
    columns += [(f"{k} d wall s", k, "wall_s", ".1f") for k in keys]
    widths = [max(len(label), 7) + 2 for label, *_ in columns]
    head = f"{'command':15s}" + "".join(f"{c[0]:>{w}s}" for c, w in zip(columns, widths, strict=True))
    lines = [head + f"{'growth':>8s}  verdict"]
    for row in rows:
        cells = [_cell(row["runs"][k], key, fmt) for _, k, key, fmt in columns]
        line = f"{row['command']:15s}" + "".join(f"{c:>{w}s}" for c, w in zip(cells, widths, strict=True))
        growth = "-" if row["growth"] is None else f"{row['growth']:.2f}x"
        line += f"{growth:>8s}  {row['verdict']}" + (f" ({row['why']})" if row["why"] else "")
        lines.append(line)
    return "\n".join(lines)


def run_info(repo: Path) -> dict:
    """The commit measured (``git rev-parse HEAD`` of ``repo``) and whether ``imulog/`` differs from it; ``None``
    outside a git work tree."""

    def git(*args: str) -> str | None:
        try:
            out = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, check=True)
        except (OSError, subprocess.CalledProcessError):
            return None
        return out.stdout.strip()

    commit = git("rev-parse", "HEAD")
    changed = git("status", "--porcelain", "--", "imulog")
    return {"commit": commit, "imulog_changed": None if commit is None else bool(changed)}


def summary(rows: list[dict], days: list[float], meta: dict) -> dict:
    """What the summary file holds: ``meta`` (commit, times, load averages, command line), the limits and the
    rows."""
    return {
        **meta,
        "days": days,
        "limits": {"rss_mb": MAX_RSS_MB, "growth": MAX_GROWTH},
        "cpu_count": os.cpu_count(),
        "passed": all(r["verdict"] == "PASS" for r in rows),
        "commands": rows,
    }


def markdown(doc: dict) -> str:
    """The summary as a Markdown table: command, peak RSS per length, growth, CPU / wall per length, verdict."""
    keys = [f"{d:g}" for d in doc["days"]]
    lines = [
        f"`{doc.get('argv', '')}` on commit {(doc.get('commit') or 'unknown')[:7]}"
        + (" (imulog/ changed)" if doc.get("imulog_changed") else "")
        + f", {doc.get('start', '')} to {doc.get('end', '')}, load average {doc.get('load', '')} on"
        f" {doc['cpu_count']} cores; CPU = user + sys of the child"
        + (
            f"; numba's cache warmed by a {doc['warm_days']:g}-day run first"
            if doc.get("warm_days")
            else "; no warm-up (the first length includes numba's compilation)"
            if "warm_days" in doc
            else ""
        )
        + ("; interrupted (what was not measured: not run)" if doc.get("interrupted") else ""),
        "",
        "| command | "
        + " | ".join(f"{k} d: peak RSS" for k in keys)
        + " | growth | "
        + " | ".join(f"{k} d: CPU / wall" for k in keys)
        + " | verdict |",
        "|---" * (3 + 2 * len(keys)) + "|",
    ]
    for row in doc["commands"]:
        rss = [_cell(row["runs"][k], "rss_mb", ".0f") + (" MB" if _ok(row["runs"][k]) else "") for k in keys]
        cpu = [
            f"{row['runs'][k]['cpu_s']:.1f} / {row['runs'][k]['wall_s']:.1f} s"
            if _ok(row["runs"][k])
            else _cell(row["runs"][k], "cpu_s", "")
            for k in keys
        ]
        growth = "-" if row["growth"] is None else f"{row['growth']:.2f}x"
        verdict = row["verdict"] + (f": {row['why']}" if row["why"] else "")
        lines.append(
            f"| `{row['command']}` | "
            + " | ".join(rss)
            + f" | {growth} | "
            + " | ".join(cpu)
            + f" | {verdict.replace('|', '/')} |"
        )
    return "\n".join(lines) + "\n"


def _ok(run: dict | None) -> bool:
    return run is not None and "failed" not in run


def write_summary(path: Path, doc: dict) -> None:
    """``doc`` to ``path``: JSON for a ``.json`` suffix, else Markdown."""
    path = Path(path)
    text = json.dumps(doc, indent=1) + "\n" if path.suffix.lower() == ".json" else markdown(doc)
    path.write_text(text)
