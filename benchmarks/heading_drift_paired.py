"""Paired comparison of the optimisation's heading-drift correction (issue 31 point 2): ``trajectory_paired.py
--change heading-drift`` under its earlier name (the command docs/accuracy.md names).

    python benchmarks/heading_drift_paired.py --grid all --subjects 6 --first-subject 20 --repetitions 10 --per-trial
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from trajectory_paired import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main(["--change", "heading-drift", *sys.argv[1:]]))
