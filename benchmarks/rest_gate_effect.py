"""Before and after the accelerometer's rest gate (issue 32): the shared gaitmap foot recording and the simulated
drinking trials, with the trajectory step's rests (gate on) and with the segmentation's still-gyroscope mask alone
(gate off, what the step did before the gate).

* gaitmap: ZUPT stride lengths of both feet against the heel marker (``trajectory_real_data.gaitmap_stride_lengths``),
  mean ± sd of the error and the mean absolute error (cm);
* drinking trials: the accuracy grid of ``trajectory_accuracy.py`` (MAE per axis, cm, mean over repetitions) for
  zupt, zupt_bias and optimized, per condition, gate off and on, and the difference (on - off).

    python benchmarks/rest_gate_effect.py --grid all --subjects 2 --repetitions 8      # ~6 min on a loaded machine
    python benchmarks/rest_gate_effect.py --grid stroke combined-stroke --no-gaitmap
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from trajectory_accuracy import grid_rows  # noqa: E402
from trajectory_real_data import DATA, gaitmap_stride_lengths  # noqa: E402

from imulog.process.rests import RestParams  # noqa: E402
from imulog.process.trajectory_opt import DEFAULT_PARAMS  # noqa: E402


def gaitmap_figures(root: Path) -> list[str]:
    lines = ["| foot | gate | strides | error mean ± sd (cm) | MAE (cm) |", "|---|---|---|---|---|"]
    for foot in ("left", "right"):
        for gate in (False, True):
            e = gaitmap_stride_lengths(root, foot, rest_gate=gate)["error_m"] * 100
            lines.append(
                f"| {foot} | {'on' if gate else 'off'} | {len(e)} | {e.mean():+.2f} ± {e.std(ddof=1):.2f} | "
                f"{np.abs(e).mean():.2f} |"
            )
    return lines


def grid_figures(conditions: list[str], subjects: int, repetitions: int) -> list[str]:
    off = replace(DEFAULT_PARAMS, rests=RestParams(enabled=False))
    rows = {
        gate: {
            (r["condition"], r["method"]): r["mae_cm"]
            for r in grid_rows(conditions, range(subjects), repetitions, params=p)
        }
        for gate, p in (("off", off), ("on", DEFAULT_PARAMS))
    }
    methods = list(dict.fromkeys(m for _, m in rows["on"]))
    lines = [
        "| condition | method | gate off x/y/z (cm) | gate on x/y/z (cm) | on - off (cm) |",
        "|---|---|---|---|---|",
    ]
    for c in dict.fromkeys(c for c, _ in rows["on"]):
        for m in methods:
            a, b = np.array(rows["off"][(c, m)]), np.array(rows["on"][(c, m)])
            fmt = lambda v: " / ".join(f"{x:.2f}" for x in v)  # noqa: E731
            lines.append(f"| {c} | {m} | {fmt(a)} | {fmt(b)} | {' / '.join(f'{x:+.2f}' for x in b - a)} |")
    for m in methods:
        a = np.mean([v for (c, mm), v in rows["off"].items() if mm == m], axis=0)
        b = np.mean([v for (c, mm), v in rows["on"].items() if mm == m], axis=0)
        lines.append(
            f"| **mean** | {m} | {' / '.join(f'{x:.2f}' for x in a)} | {' / '.join(f'{x:.2f}' for x in b)} | "
            f"{' / '.join(f'{x:+.2f}' for x in b - a)} |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--grid", nargs="+", default=["all"], help="accuracy-grid conditions (names or 'all')")
    ap.add_argument("--subjects", type=int, default=2)
    ap.add_argument("--repetitions", type=int, default=8)
    ap.add_argument("--no-gaitmap", action="store_true")
    ap.add_argument("--no-grid", action="store_true")
    args = ap.parse_args(argv)
    if not args.no_gaitmap:
        print("\n".join(gaitmap_figures(args.data / "gaitmap_foot")))
        print()
    if not args.no_grid:
        from imulog.simulate.grid import CONDITIONS

        conditions = list(CONDITIONS) if args.grid == ["all"] else args.grid
        print("\n".join(grid_figures(conditions, args.subjects, args.repetitions)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
