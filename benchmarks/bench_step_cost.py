"""What appending or replacing a derived channel costs as a function of the trial's size, and how fast ``info`` is.

    python benchmarks/bench_step_cost.py            # trials of 10, 30 and 60 min of 1 kHz 9-axis IMU
    python benchmarks/bench_step_cost.py --minutes 5 20

For each trial: the wall and CPU time (user + system, every thread) of ``append_derived`` with a small derived
channel (1,000 samples; the append writes in place, nothing copied: imulog.archive.journal), of replacing that
channel (the replace path rewrites the file: one pass, dropped records skipped), and of ``imulog info``'s
summary (no data or attachment read); bytes read and written by the process (``/proc/self/io``; the append's
CRC pass reads a memory map, which these counters do not see) show what each path copies.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from imulog.archive import TrialReader, append_derived, write_trial
from imulog.commands.info import trial_summary
from imulog.model import ImuStream, Recording, SignalStream


def _io() -> tuple[int, int]:
    """(bytes read, bytes written) by this process so far (Linux; zeros elsewhere)."""
    try:
        fields = dict(line.split(": ") for line in Path("/proc/self/io").read_text().splitlines())
    except OSError:
        return 0, 0
    return int(fields["rchar"]), int(fields["wchar"])


def _cpu() -> float:
    """CPU seconds (user + system) of this process so far, every thread."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def _trial(path: Path, minutes: float) -> None:
    n = int(minutes * 60 * 1000)
    t = np.arange(n, dtype=np.int64) * 1_000_000
    rng = np.random.default_rng(0)
    imu = ImuStream(
        "wrist", t, acc=rng.normal(0, 1, (n, 3)), gyr=rng.normal(0, 1, (n, 3)), mag=rng.normal(0, 1, (n, 3))
    )
    write_trial(path, Recording(imus=[imu]), overwrite=True)


def measure(path: Path) -> dict[str, float]:
    size = path.stat().st_size
    t = np.arange(1000, dtype=np.int64) * 10_000_000
    small = SignalStream("/derived/bench/x", t, ["v"], ["1"], np.zeros(1000))
    out: dict[str, float] = {"MB": size / 1e6}
    for label, values in (("append", 0.0), ("replace", 1.0)):
        small = SignalStream("/derived/bench/x", t, ["v"], ["1"], np.full(1000, values))
        r0, w0 = _io()
        t0, c0 = time.perf_counter(), _cpu()
        append_derived(path, [small], run={"step": "bench", "params": {"v": values}})
        out[f"{label}_s"], out[f"{label}_cpu_s"] = time.perf_counter() - t0, _cpu() - c0
        r1, w1 = _io()
        out[f"{label}_read_MB"], out[f"{label}_written_MB"] = (r1 - r0) / 1e6, (w1 - w0) / 1e6
    t0 = time.perf_counter()
    with TrialReader(path) as trial:
        trial_summary(trial)
    out["info_s"] = time.perf_counter() - t0
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[10, 30, 60])
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(
        f"{'trial MB':>9} {'append s':>9} {'cpu s':>6} {'read MB':>8} {'written MB':>10} "
        f"{'replace s':>10} {'cpu s':>6} {'written MB':>10} {'info s':>7}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in args.minutes:
            path = Path(tmp) / f"trial_{minutes:g}min.mcap"
            _trial(path, minutes)
            r = measure(path)
            print(
                f"{r['MB']:9.1f} {r['append_s']:9.2f} {r['append_cpu_s']:6.2f} {r['append_read_MB']:8.1f} "
                f"{r['append_written_MB']:10.1f} {r['replace_s']:10.2f} {r['replace_cpu_s']:6.2f} "
                f"{r['replace_written_MB']:10.1f} {r['info_s']:7.3f}"
            )
            path.unlink()


if __name__ == "__main__":
    main()
