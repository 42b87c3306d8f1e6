"""Peak memory and time of ``imulog salvage`` on a long trial cut at two thirds (issue 26).

    python benchmarks/bench_salvage.py                  # 60 min of 1 kHz 9-axis IMU (about 270 MB), cut at 2/3
    python benchmarks/bench_salvage.py --minutes 10

Writes the trial, copies its first two thirds (no summary: an interrupted copy), then salvages it in a child
process and prints that process's peak RSS (``VmHWM``: ``ru_maxrss`` would count the parent's, the child being
spawned from it) and wall time; the time includes the
``doctor`` check of the output that salvage runs before it writes, and the IMU channel, recovered in part,
is decoded once more to recompute its channel record.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CHILD = """
import re, sys, time
from imulog.archive.salvage import salvage
t0 = time.perf_counter()
report = salvage(sys.argv[1], sys.argv[2])
wall = time.perf_counter() - t0
c = report.channels["/imu/wrist"]
peak = int(re.search(r"VmHWM:\\s+(\\d+)", open("/proc/self/status").read()).group(1)) / 1024
print(f"{wall:.1f} {peak:.0f} {c['messages']} {c['partial']}")
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    args = ap.parse_args()
    from imulog.archive import write_trial
    from imulog.model import ImuStream, Recording

    n = int(args.minutes * 60 * 1000)
    rng = np.random.default_rng(0)
    t = np.arange(n, dtype=np.int64) * 1_000_000
    imu = ImuStream(
        "wrist", t, acc=rng.normal(0, 1, (n, 3)), gyr=rng.normal(0, 0.1, (n, 3)), mag=rng.normal(0, 30, (n, 3))
    )
    with tempfile.TemporaryDirectory() as tmp:
        trial = write_trial(Path(tmp) / "trial.mcap", Recording(imus=[imu]))
        del imu, t
        size = trial.stat().st_size
        cut = Path(tmp) / "cut.mcap"
        with open(trial, "rb") as src, open(cut, "wb") as dst:
            remaining = size * 2 // 3
            while remaining:
                block = src.read(min(8 << 20, remaining))
                dst.write(block)
                remaining -= len(block)
        out = subprocess.run(
            [sys.executable, "-c", CHILD, str(cut), str(Path(tmp) / "fixed.mcap")],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split()
    wall, rss, messages, partial = out
    print(
        f"{args.minutes:g} min, {size / 1e6:.0f} MB cut at {size * 2 // 3 / 1e6:.0f} MB: salvage {wall} s, "
        f"peak RSS {rss} MB, {messages} IMU messages kept (partial: {partial}), load {os.getloadavg()[0]:.1f}"
    )


if __name__ == "__main__":
    main()
