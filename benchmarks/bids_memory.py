"""Peak memory of ``imulog export --to bids`` on a long wrist recording (the export read each channel whole).

    python benchmarks/bids_memory.py                              # a simulated day at 50 Hz (~10 min, 2 cores)
    python benchmarks/bids_memory.py --days 0.25 --rate-hz 100
    python benchmarks/bids_memory.py --trial home.mcap --compare before_bids/   # an existing trial; same bytes?
    python benchmarks/bids_memory.py --orientation --keep day_bids/  # with its orientation (ORNT columns); kept

Writes ``imulog simulate home --days D --set rate_hz=R`` and ``imulog convert`` of its ``.cwa`` (unless
``--trial``; with ``--orientation`` then ``imulog process orientation``, so that the export lines the quaternions
up with the IMU's samples), then runs ``/usr/bin/time -v imulog export TRIAL --to bids -o OUT/`` as a child and prints its
"Maximum resident set size", wall time, the ``_motion.tsv`` sizes and whether ``bidsschematools`` matches every
file name to a BIDS rule. ``--compare DIR``: whether every file equals the one of another export of the trial
(e.g. one made by an earlier commit with ``imulog export home.mcap ...`` beside the trial: the sidecars record
the trial's path as given, and the script gives its name), byte for byte. Run once per commit to compare; the machine's load is printed.

Measured (2026-12-07/08, 2 cores shared, load 10-18, two runs each; figures in benchmarks/README.md): the day at
50 Hz with its orientation processed, ``--trial``: 438,764 / 436,204 kB peak with the quaternion line-up that
concatenated each block (``e9131d5``), 446,296 / 431,504 kB with the one that holds at most two blocks, i.e. the
same within the spread (the line-up's own traced peak: 12.9 MB at 400,000 rows and 14.0 MB at 1.6 M before,
10.7 MB at both after, tests/test_export_bids.py); ``--compare``: True; every file name matched by
``bidsschematools``.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

IMULOG = [sys.executable, "-m", "imulog"]


def simulated_trial(folder: Path, days: float, rate_hz: float, orientation: bool = False) -> Path:
    """``imulog simulate home`` converted into ``folder/home.mcap`` (and its orientation processed)."""
    sim = folder / "home"
    subprocess.run(
        [*IMULOG, "simulate", "home", "-o", sim, "--days", str(days), "--set", f"rate_hz={rate_hz:g}"], check=True
    )
    trial = folder / "home.mcap"
    subprocess.run([*IMULOG, "convert", next(sim.glob("*.cwa")), "-o", trial], check=True)
    if orientation:
        subprocess.run([*IMULOG, "process", "orientation", trial], check=True)
    return trial


def measured_export(trial: Path, out: Path) -> dict[str, str]:
    """The export under ``/usr/bin/time -v``: peak RSS (kB) and wall time as it prints them."""
    done = subprocess.run(  # run beside the trial: the sidecars record its name, as `imulog export home.mcap`
        ["/usr/bin/time", "-v", *IMULOG, "export", trial.name, "--to", "bids", "-o", out.resolve()],
        capture_output=True,
        text=True,
        check=True,
        cwd=trial.resolve().parent,
    )
    fields = {}
    for key in ("Maximum resident set size (kbytes)", "Elapsed (wall clock) time (h:mm:ss or m:ss)"):
        m = re.search(re.escape(key) + r": (\S+)", done.stderr)
        fields[key] = m.group(1) if m else "?"
    return fields


def same_files(a: Path, b: Path) -> bool:
    """Every file of ``a`` and ``b`` present in both and equal byte for byte."""
    names = sorted(str(p.relative_to(a)) for p in a.rglob("*") if p.is_file())
    if names != sorted(str(p.relative_to(b)) for p in b.rglob("*") if p.is_file()):
        return False
    return all(filecmp.cmp(a / n, b / n, shallow=False) for n in names)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--days", type=float, default=1.0)
    ap.add_argument("--rate-hz", type=float, default=50.0)
    ap.add_argument("--trial", type=Path, help="an existing trial instead of a simulated one")
    ap.add_argument("--compare", type=Path, help="another export of the same trial to compare byte for byte")
    ap.add_argument("--orientation", action="store_true", help="process the simulated trial's orientation first")
    ap.add_argument("--keep", type=Path, help="move the export to this folder (to --compare another commit's with)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bids_memory_") as tmp:
        folder = Path(tmp)
        trial = args.trial or simulated_trial(folder, args.days, args.rate_hz, args.orientation)
        out = folder / "bids"
        print(f"load average {os.getloadavg()[0]:.1f}; exporting {trial} ({trial.stat().st_size / 1e6:.0f} MB)")
        fields = measured_export(trial, out)
        for key, value in fields.items():
            print(f"{key}: {value}")
        for p in sorted(out.rglob("*_motion.tsv")):
            print(f"{p.name}: {p.stat().st_size / 1e6:.0f} MB")
        from bidsschematools import validator

        unmatched = validator.validate_bids(str(out))["path_tracking"]
        print(f"bidsschematools: {unmatched or 'every file name matches a BIDS rule'}")
        if args.compare is not None:
            print(f"same bytes as {args.compare}: {same_files(out, args.compare)}")
        if args.keep is not None:
            shutil.move(out, args.keep)
            print(f"kept in {args.keep}")


if __name__ == "__main__":
    main()
