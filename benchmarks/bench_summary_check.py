"""What the summary check before a step's rewrite costs (issue 26: summary defects repaired out loud or refused).

    python benchmarks/bench_summary_check.py                 # 2 M samples of 6-axis IMU in 16 kB chunks
    python benchmarks/bench_summary_check.py --samples 500000 --chunk-bytes 2097152

Writes one trial with many chunks, then times ``summary_defects`` (the summary alone) and ``summary_problems``
(doctor's summary checks on the heads of every record of the data section, no chunk decompressed): the two run
before every append, replace or removal (``imulog.archive.append``).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from imulog.archive import _builder, write_trial
from imulog.archive import _mcap as m
from imulog.archive.summary_check import summary_defects
from imulog.archive.summary_walk import summary_problems
from imulog.model import ImuStream, Recording


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2_000_000)
    ap.add_argument("--chunk-bytes", type=int, default=16_000, help="chunk size the trial is written with")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    t = np.arange(args.samples, dtype=np.int64) * 10_000_000
    imu = ImuStream("wrist", t, acc=rng.normal(0, 1, (args.samples, 3)), gyr=rng.normal(0, 0.1, (args.samples, 3)))
    _builder.CHUNK_TARGET_BYTES = args.chunk_bytes
    with tempfile.TemporaryDirectory() as tmp:
        path = write_trial(Path(tmp) / "trial.mcap", Recording(imus=[imu]))
        with open(path, "rb") as f:
            summary = m.read_summary(f, os.fstat(f.fileno()).st_size)
            chunks = len(summary.chunk_indexes)
            t0 = time.perf_counter()
            defects = summary_defects(summary)
            t1 = time.perf_counter()
            problems = summary_problems(f, summary, set())
            t2 = time.perf_counter()
        size = path.stat().st_size
    print(
        f"{size / 1e6:.0f} MB, {chunks} chunks: summary_defects {1e3 * (t1 - t0):.1f} ms ({len(defects)} defects), "
        f"summary_problems {t2 - t1:.2f} s ({len(problems)} problems), load {os.getloadavg()[0]:.1f}"
    )


if __name__ == "__main__":
    main()
