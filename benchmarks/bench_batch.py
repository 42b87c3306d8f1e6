"""Batch reprocessing of a simulated archive: wall time, files/s, 1 -> 2 worker speed-up, flat peak memory.

    python benchmarks/bench_batch.py            # 11 subjects x 3 trials x 25 repetitions (825 movements)
    python benchmarks/bench_batch.py --small    # 4 subjects x 2 trials x 5 repetitions

Steps: orientation, align, phases, trajectory, evaluate (``phases.repetitions`` = the simulated count).
After a one-file warm-up (imports, JIT caches), every run starts from a fresh copy of the raw archive and runs
in its own subprocess, which reports its peak RSS (``getrusage`` maximum RSS of the process itself or of its
largest worker child, i.e. per process) and its CPU time (itself + its workers): CPU/wall shows how many cores
the run actually obtained on a shared machine.

* A: the first half of the files (N), 1 worker  -> peak memory at N;
* B: all files (2N), 1 worker                    -> wall time, files/s, and peak memory at 2N (flat: B/A ~ 1);
* C: all files (2N), 2 worker processes          -> speed-up B/C;
* D: B's archive again (everything up to date)   -> cost of a no-op rerun with the ledger pre-check, and
  (E) without it (every file opened, every step skips itself);
* the catalog of B's archive, built and then updated with nothing changed.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

STEPS = "orientation,align,phases,trajectory,evaluate"


def _child(args: argparse.Namespace) -> None:
    """Run one batch in this (sub)process and print its figures as JSON."""
    from imulog.batch import run
    from imulog.batch.registry import STEPS as REGISTRY
    from imulog.batch.registry import plan_fingerprint

    files = json.loads(Path(args.files).read_text())
    options = {"phases": {"repetitions": args.repetitions}}
    plan_fingerprint(STEPS.split(","), options)  # import the steps' modules before the clock starts
    for name in STEPS.split(","):
        importlib.import_module(REGISTRY[name].function.split(":")[0])
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu0 = me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime
    t0 = time.perf_counter()
    report = run(
        files,
        STEPS,
        workers=args.workers,
        options=options,
        progress=False,
        ledger=None if args.no_ledger else "auto",
    )
    wall = time.perf_counter() - t0
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime - cpu0
    self_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    children_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    out = {
        "files": len(files),
        "wall_s": wall,
        "cpu_s": cpu,
        "file_s": sum(f.seconds for f in report.files),
        "processed": report.processed,
        "up_to_date": report.up_to_date,
        "failed": report.failed,
        "steps_computed": report.steps_computed,
        "peak_rss_mb": max(self_kb, children_kb) / 1024,
        "self_rss_mb": self_kb / 1024,
        "children_rss_mb": children_kb / 1024,
        "step_s": {k: sum(v) for k, v in report.step_seconds().items()},
        "computed_by_step": {k: len(v) for k, v in report.step_seconds().items()},
        "prechecked": report.prechecked,
        "errors": [f.error for f in report.failures()][:3],
    }
    print(json.dumps(out))


def _batch(files: list[Path], workers: int, repetitions: int, work: Path, no_ledger: bool = False) -> dict:
    listing = work / f"files-{len(files)}-{workers}-{time.monotonic_ns()}.json"
    listing.write_text(json.dumps([str(p) for p in files]))
    cmd = [sys.executable, __file__, "--child", "--files", str(listing), "--workers", str(workers)]
    cmd += ["--repetitions", str(repetitions)] + (["--no-ledger"] if no_ledger else [])
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"batch subprocess failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _copy(raw: Path, dst: Path, files: list[Path]) -> list[Path]:
    out = []
    for p in files:
        q = dst / p.relative_to(raw)
        q.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(p, q)
        out.append(q)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--small", action="store_true", help="4 subjects x 2 trials x 5 repetitions")
    ap.add_argument("--subjects", type=int, default=None)
    ap.add_argument("--trials", type=int, default=None)
    ap.add_argument("--repetitions", type=int, default=None)
    ap.add_argument("--workdir", type=Path, default=None, help="where to put the archive copies (default: a temp dir)")
    ap.add_argument("--keep", action="store_true", help="keep the archives")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--files", help=argparse.SUPPRESS)
    ap.add_argument("--workers", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--no-ledger", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(args)
        return
    subjects = args.subjects or (4 if args.small else 11)
    trials = args.trials or (2 if args.small else 3)
    reps = args.repetitions or (5 if args.small else 25)
    work = Path(args.workdir or tempfile.mkdtemp(prefix="imulog-bench-batch-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        from imulog.batch.simulated import simulate_archive

        print(
            f"archive: {subjects} subjects x {trials} trials x {reps} repetitions = {subjects * trials * reps} "
            f"drinking tasks (the thesis's 'movements'), {4 * subjects * trials * reps} phases; "
            f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}"
        )
        t = time.perf_counter()
        raw_root = work / "raw"
        raw = simulate_archive(raw_root, subjects=subjects, trials=trials, repetitions=reps)
        size_mb = sum(p.stat().st_size for p in raw) / 1e6
        print(f"simulate + write: {len(raw)} files, {size_mb:.0f} MB, {time.perf_counter() - t:.1f} s")
        half = raw[: len(raw) // 2]

        _batch(_copy(raw_root, work / "W", raw[:1]), 1, reps, work)  # warm-up: import and JIT caches
        a = _batch(_copy(raw_root, work / "A", half), 1, reps, work)
        b_files = _copy(raw_root, work / "B", raw)
        b = _batch(b_files, 1, reps, work)
        c = _batch(_copy(raw_root, work / "C", raw), 2, reps, work)
        d = _batch(b_files, 1, reps, work)
        e = _batch(b_files, 1, reps, work, no_ledger=True)
        for name, r in (("A", a), ("B", b), ("C", c), ("D", d), ("E", e)):
            if r["failed"]:
                print(f"run {name}: {r['failed']} files failed, e.g. {r['errors']}")
            print(
                f"run {name}: {r['processed']} processed, {r['up_to_date']} up to date "
                f"({r['prechecked']} by the ledger), steps computed {r['computed_by_step']}"
            )
        print()
        print("| run | files | workers | wall (s) | files/s | s per file | CPU/wall | steps computed | peak RSS (MB) |")
        print("|---|---|---|---|---|---|---|---|---|")
        rows = [
            ("A: first half, fresh", a, 1),
            ("B: all, fresh", b, 1),
            ("C: all, fresh", c, 2),
            ("D: all, up to date (ledger pre-check)", d, 1),
            ("E: all, up to date (no ledger)", e, 1),
        ]
        for name, r, w in rows:
            print(
                f"| {name} | {r['files']} | {w} | {r['wall_s']:.1f} | {r['files'] / r['wall_s']:.2f} | "
                f"{r['file_s'] / r['files']:.2f} | {r['cpu_s'] / r['wall_s']:.2f} | "
                f"{r['steps_computed']} | {r['peak_rss_mb']:.0f} |"
            )
        print()
        print(
            f"speed-up 1 -> 2 workers (B/C): {b['wall_s'] / c['wall_s']:.2f}x; CPU/wall {b['cpu_s'] / b['wall_s']:.2f} "
            f"-> {c['cpu_s'] / c['wall_s']:.2f} (cores actually obtained; load average now {os.getloadavg()[0]:.1f})"
        )
        print(
            f"peak memory at 2N / at N files (B/A, 1 worker): {b['peak_rss_mb'] / a['peak_rss_mb']:.2f} "
            f"({a['peak_rss_mb']:.0f} MB at {a['files']} files, {b['peak_rss_mb']:.0f} MB at {b['files']})"
        )
        print(f"no-op rerun: {d['wall_s']:.2f} s with the ledger, {e['wall_s']:.2f} s opening every file")
        from imulog.batch.catalog import build_catalog

        cat = build_catalog(work / "B", work / "catalog.parquet")
        inc = build_catalog(work / "B", work / "catalog.parquet")
        print(
            f"catalog of {cat.rows} processed trials: {cat.seconds:.2f} s; incremental update (nothing changed): "
            f"{inc.seconds:.2f} s ({inc.reused} rows reused)"
        )
        total = sum(b["step_s"].values())
        print(
            "time per step (B): "
            + ", ".join(f"{k} {v / b['files']:.2f} s/file ({100 * v / total:.0f} %)" for k, v in b["step_s"].items())
        )
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
        else:
            print(f"archives kept in {work}")


if __name__ == "__main__":
    main()
