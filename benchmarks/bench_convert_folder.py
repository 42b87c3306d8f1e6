"""`imulog convert FOLDER -o OUT/`: how often each file's format is detected, and what the folder costs.

For each folder (default: the device samples of ``../shared/data/devices`` that folder mode converts), in one
process: the folder conversion as the command runs it (``imulog convert FOLDER -o OUT/ --no-attach``, through
click's test runner, without the process start-up), counting every call of the format detector per file; then,
as the peer, one detection of each convertible file alone (``registry.detect``), which is what the folder costs
in detection when each file is detected once. Best of ``--repeat`` runs for the wall time and, beside it, the
process CPU time (user+sys, all threads: steadier than wall time when other work shares the cores); the load
average is printed.

    python benchmarks/bench_convert_folder.py [--repeat 5] [FOLDER ...]
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from collections import Counter
from pathlib import Path
from unittest import mock

from click.testing import CliRunner
from imulog.converters import registry

from imulog.cli import cli

DEVICES = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "devices"
DEFAULT = ("empatica_e4", "axivity_cwa", "xsens_mtmanager", "xdf")
# every name the detector is imported under by the convert commands (patched while counting)
DETECT_NAMES = (
    "imulog.converters.registry.detect",
    "imulog.commands.convert_common.detect",
    "imulog.commands.convert_folders.detect",
)


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def timed(fn, *args) -> tuple[float, float]:
    """(wall s, CPU s) of one call of ``fn(*args)``."""
    w, c = time.perf_counter(), _cpu_s()
    fn(*args)
    return time.perf_counter() - w, _cpu_s() - c


def convert_folder(folder: Path, calls: Counter | None = None) -> None:
    """``imulog convert FOLDER -o OUT/ --no-attach`` in this process; ``calls`` counts detections per file name."""
    real = registry.detect

    def counting(path):
        if calls is not None:
            calls[Path(path).name] += 1
        return real(path)

    patches = []
    for name in DETECT_NAMES:
        module, attr = name.rsplit(".", 1)
        if hasattr(__import__(module, fromlist=[attr]), attr):
            patches.append(mock.patch(name, counting))
    for p in patches:
        p.start()
    try:
        with tempfile.TemporaryDirectory() as d:
            result = CliRunner().invoke(cli, ["convert", str(folder), "-o", f"{d}/out/", "--no-attach"])
    finally:
        for p in patches:
            p.stop()
    if result.exit_code != 0:
        raise SystemExit(f"{folder}: exit {result.exit_code}: {result.output.strip()}")


def detect_each(files: list[Path]) -> None:
    for p in files:
        registry.detect(p)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="*", type=Path)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    folders = args.folders or [DEVICES / name for name in DEFAULT]
    print(f"load average {os.getloadavg()[0]:.1f}; best of {args.repeat}; wall s (CPU user+sys s)")
    for folder in folders:
        convert_folder(folder)  # warm: imports, numba caches, page cache
        calls: Counter = Counter()
        convert_folder(folder, calls)
        files = [folder / name for name in sorted(calls) if not name.upper().startswith(("LICENSE", "NOTICE"))]
        runs = [timed(convert_folder, folder) for _ in range(args.repeat)]
        peer = [timed(detect_each, files) for _ in range(args.repeat)]
        wall, cpu = min(w for w, _ in runs), min(c for _, c in runs)
        pwall, pcpu = min(w for w, _ in peer), min(c for _, c in peer)
        per_file = sorted({calls[p.name] for p in files})
        mb = sum(p.stat().st_size for p in files) / 1e6
        print(
            f"{folder.name}: {len(files)} files, {mb:.2f} MB; detections per file {per_file} "
            f"({sum(calls[p.name] for p in files)} in all); convert {wall:.3f} ({cpu:.3f}); "
            f"one detection of each file {pwall:.3f} ({pcpu:.3f}), {pcpu / cpu:.1%} of the folder's CPU"
        )


if __name__ == "__main__":
    main()
