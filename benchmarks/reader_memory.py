"""What ``TrialReader.iter_blocks`` holds on a long file: traced peak of reading the IMU block by block, before and
after the reader stopped parsing every ChunkIndex of the file, in one process.

    python benchmarks/reader_memory.py                         # imulog simulate home --days 0.05 0.2 0.5, converted
    python benchmarks/reader_memory.py --days 0.05 0.5 --chunk-kib 16   # written whole with 16 KiB chunks
    python benchmarks/reader_memory.py --trial a.mcap b.mcap

Per trial: samples and chunks, the bytes the open reader holds (the summary section as read, its record table),
and the ``tracemalloc`` peak of ``iter_blocks`` over the first ``/imu/`` channel in the open reader, "after" as the
reader now does it and "before" with every ChunkIndex parsed and kept first (``summary.chunk_indexes``, what the
reader did on its first read), with the difference per chunk of the file.
``--chunk-kib``: the simulated ``.cwa`` is read whole and written with ``write_trial`` at that chunk size (many
small chunks: the per-chunk bookkeeping then shows; the default 2 MiB gives a few dozen chunks a day).
"""

from __future__ import annotations

import argparse
import gc
import subprocess
import sys
import tempfile
import tracemalloc
from pathlib import Path

IMULOG = [sys.executable, "-m", "imulog"]


def simulated(folder: Path, days: float, chunk_kib: int | None) -> Path:
    """``imulog simulate home --days D`` converted (``imulog convert``), or written whole at ``chunk_kib``."""
    sim = folder / f"home_{days:g}"
    subprocess.run([*IMULOG, "simulate", "home", "-o", sim, "--days", str(days)], check=True, capture_output=True)
    cwa, trial = next(sim.glob("*.cwa")), folder / f"home_{days:g}.mcap"
    if chunk_kib is None:
        subprocess.run([*IMULOG, "convert", cwa, "-o", trial], check=True, capture_output=True)
        return trial
    from imulog.converters import axivity

    from imulog.archive import _builder, write_trial

    _builder.CHUNK_TARGET_BYTES = chunk_kib * 1024
    return write_trial(trial, axivity.read_cwa(cwa), attach_sources="never")


def traced(fn) -> tuple[int, int]:
    """(bytes still held, peak bytes) traced while ``fn()`` runs."""
    gc.collect()
    tracemalloc.start()
    try:
        fn()
        gc.collect()
        return tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()


def measure(trial: Path) -> dict[str, float]:
    """Samples, chunks, bytes held by the open reader, and the peak of iter_blocks before/after (bytes)."""
    from imulog.archive import TrialReader

    def read_blocks(reader, topic) -> int:
        return sum(len(b) for b in reader.iter_blocks(topic))

    with TrialReader(trial) as reader:  # warm: imports and first-use caches
        topic = next(t for t in reader.topics() if t.startswith("/imu/"))
        samples = read_blocks(reader, topic)
    held = {}
    opened = traced(lambda: held.setdefault("r", TrialReader(trial)))[0]
    reader = held["r"]
    try:
        after = traced(lambda: read_blocks(reader, topic))[1]
        before = traced(lambda: (reader.summary.chunk_indexes, read_blocks(reader, topic)))[1]
        chunks = reader.summary.chunk_count
    finally:
        reader.close()
    return {"samples": samples, "chunks": chunks, "open": opened, "before": before, "after": after}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--days", type=float, nargs="+", default=[0.05, 0.2, 0.5])
    ap.add_argument("--chunk-kib", type=int, help="write the simulated recording whole with chunks of this size")
    ap.add_argument("--trial", type=Path, nargs="+", help="existing trials instead of simulated ones")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="reader_memory_") as tmp:
        trials = args.trial or [simulated(Path(tmp), d, args.chunk_kib) for d in args.days]
        print(
            f"{'trial':24s} {'samples':>10s} {'chunks':>7s} {'open kB':>8s} {'before MB':>10s} {'after MB':>9s}"
            f" {'saved B/chunk':>14s}"
        )
        for trial in trials:
            r = measure(trial)
            saved = (r["before"] - r["after"]) / r["chunks"]
            print(
                f"{trial.name:24s} {r['samples']:10d} {r['chunks']:7d} {r['open'] / 1e3:8.1f}"
                f" {r['before'] / 1e6:10.2f} {r['after'] / 1e6:9.2f} {saved:14.0f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
