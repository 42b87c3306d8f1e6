"""Week-long wrist recordings: peak memory and time of every command at 1 and 7 days (issue 17's targets).

    python benchmarks/bench_long.py                    # 1 and 7 days at 100 Hz (a 774 MB .cwa; ~10 min)
    python benchmarks/bench_long.py --days 0.25 1      # quicker
    python benchmarks/bench_long.py --trials day.mcap week.mcap --commands phases   # copies of processed trials

For each length: ``imulog simulate home --days D`` writes an Axivity AX6 .cwa (accelerometer + gyroscope,
100 Hz), then ``imulog convert``, ``imulog process orientation``, ``imulog process phases``, ``imulog process
metrics``, ``imulog info`` and ``imulog view --save`` run as separate processes (``--trials``: on copies of
trials already converted, one per length, for the commands named by ``--commands``); the peak resident memory of each (``ru_maxrss`` of the child)
and its wall time are printed, with the ratio of the longest to the shortest length. The machine's load average
is printed too: times are only comparable within one run.

Targets (issue 17): peak RSS at most 1 GB for every command, and at most 10 % more at 7 days than at 1 day.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMANDS = [
    ("convert", ["convert", "{cwa}", "-o", "{mcap}"]),
    # --force: on copies of processed trials (--trials) a step already up to date would do nothing
    ("orientation", ["process", "orientation", "{mcap}", "--force"]),
    ("phases", ["process", "phases", "{mcap}", "--force"]),
    ("metrics", ["process", "metrics", "{mcap}", "--force"]),
    ("info", ["info", "{mcap}"]),
    ("view", ["view", "{mcap}", "--save", "{rrd}"]),
]


def run(args: list[str]) -> tuple[float, float]:
    """(seconds, peak RSS MB) of one command in a child process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    elapsed = time.perf_counter() - t0
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(args)} failed:\n{err[-2000:]}")
    return elapsed, usage.ru_maxrss / 1024.0  # kB on Linux


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, nargs="+", default=[1.0, 7.0], help="recording lengths, days")
    ap.add_argument("--dir", default=None, help="scratch folder (needs ~3 GB per simulated week)")
    ap.add_argument("--trials", nargs="+", default=None, help="converted trials, one per --days value (copied)")
    ap.add_argument("--commands", nargs="+", default=[n for n, _ in COMMANDS], choices=[n for n, _ in COMMANDS])
    args = ap.parse_args(argv)
    if args.trials and len(args.trials) != len(args.days):
        ap.error(f"--trials needs one trial per --days value ({len(args.days)})")
    commands = [(n, t) for n, t in COMMANDS if n in args.commands and not (args.trials and n == "convert")]
    imulog = [sys.executable, "-m", "imulog"]
    results: dict[float, dict[str, tuple[float, float]]] = {}
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        for i, days in enumerate(args.days):
            folder = Path(tmp) / f"d{days:g}"
            folder.mkdir()
            paths = {"cwa": folder / "home_s00_t00.cwa", "mcap": folder / "home.mcap", "rrd": folder / "home.rrd"}
            if args.trials:
                shutil.copy(args.trials[i], paths["mcap"])
            else:
                subprocess.run([*imulog, "simulate", "home", "-o", str(folder), "--days", str(days)], check=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            results[days] = {}
            for name, template in commands:
                results[days][name] = run([*imulog, *[a.format(**paths) for a in template]])
                print(f"{days:g} d {name}: {results[days][name][0]:.1f} s, {results[days][name][1]:.0f} MB, "
                      f"load {os.getloadavg()[0]:.1f}", flush=True)
            sizes = {k: p.stat().st_size / 1e6 for k, p in paths.items() if p.exists()}
            print(f"{days:g} d: " + ", ".join(f"{k} {v:.0f} MB" for k, v in sizes.items()), flush=True)
            for p in paths.values():
                p.unlink(missing_ok=True)
    one, five, _ = os.getloadavg()
    print(f"load average {one:.1f} (1 min), {five:.1f} (5 min) on {os.cpu_count()} cores; "
          f"self peak {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    lo, hi = min(args.days), max(args.days)
    print(f"{'command':12s}" + "".join(f"{f'{d:g} d s':>10s}{f'{d:g} d MB':>11s}" for d in args.days)
          + f"{'RSS ratio':>11s}  verdict")
    ok_all = True
    for name, _ in commands:
        row = "".join(f"{results[d][name][0]:10.1f}{results[d][name][1]:11.0f}" for d in args.days)
        ratio = results[hi][name][1] / results[lo][name][1]
        ok = max(results[d][name][1] for d in args.days) <= 1024 and ratio <= 1.10
        ok_all &= ok
        print(f"{name:12s}{row}{ratio:10.2f}x  {'meets target' if ok else 'MISSES (<= 1 GB, <= 1.10x)'}")
    return 0 if ok_all else 1


if __name__ == "__main__":
    raise SystemExit(main())
