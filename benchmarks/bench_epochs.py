"""Size per hour of a converted home recording against its .cwa, and the epoch step's throughput and memory.

    python benchmarks/bench_epochs.py                 # 1 day at 100 Hz (a 103 MB .cwa)
    python benchmarks/bench_epochs.py --days 7        # the week of issue 28 (770 MB; minutes on 2 cores)

Simulates ``imulog simulate home --days N`` (with one device removal a day), converts it with the original
recorded, not attached (``--attach-original never``: the archive's own size), then runs ``imulog process
epochs``; each command in its own process so its peak memory (max RSS) is its own. Prints bytes per hour of the
.cwa and of the archive, their ratio (issue 28's target: <= 1.3x), the epoch step's wall time, samples per second
and peak memory, and the machine's load average.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_CHILD = (
    "import resource, runpy, sys\n"
    "sys.argv = ['imulog', *sys.argv[1:]]\n"
    "try:\n"
    "    runpy.run_module('imulog', run_name='__main__')\n"
    "finally:\n"
    "    print('maxrss_kb', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)\n"
)


def run(args: list[str]) -> tuple[float, float]:
    """Run ``imulog ARGS`` in its own process; (wall seconds, that process's peak RSS in MB)."""
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, *args], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    wall = time.perf_counter() - t0
    kb = [int(line.split()[1]) for line in done.stderr.splitlines() if line.startswith("maxrss_kb ")]
    return wall, (kb[-1] / 1024 if kb else float("nan"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=1.0, help="recording length in days (default 1)")
    ap.add_argument("--dir", default=None, help="where to write the files (default: system temp)")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(dir=a.dir) as tmp:
        d = Path(tmp)
        sim_s, _ = run(["simulate", "home", "-o", str(d), "--days", str(a.days), "--set", "removals_per_day=1"])
        cwa = d / "home_s00_t00.cwa"
        trial = d / "home.mcap"
        conv_s, conv_mb = run(["convert", str(cwa), "-o", str(trial), "--attach-original", "never"])
        hours = a.days * 24
        cwa_b, mcap_b = cwa.stat().st_size, trial.stat().st_size
        ep_s, ep_mb = run(["process", "epochs", str(trial)])
        after_b = trial.stat().st_size
        samples = int(round(a.days * 86400 * 100))
        print(f"{a.days:g} day(s) at 100 Hz ({samples / 1e6:.1f} M samples), load {os.getloadavg()[0]:.2f}")
        print(f"  .cwa        {cwa_b / hours / 1e6:8.2f} MB/h  ({cwa_b / 1e6:.1f} MB)")
        print(
            f"  converted   {mcap_b / hours / 1e6:8.2f} MB/h  ({mcap_b / 1e6:.1f} MB, {mcap_b / cwa_b:.2f}x the .cwa; "
            f"convert {conv_s:.1f} s, peak {conv_mb:.0f} MB)"
        )
        print(
            f"  epochs      {ep_s:8.1f} s     ({samples / ep_s / 1e6:.2f} M samples/s, peak {ep_mb:.0f} MB; "
            f"archive +{(after_b - mcap_b) / 1e6:.2f} MB)"
        )
        print(f"  (simulate {sim_s:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
