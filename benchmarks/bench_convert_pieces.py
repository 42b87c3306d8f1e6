"""Host-clock text converted piece by piece against the same file in one piece: peak memory, CPU and wall time.

Writes Shimmer Consensys exports (``sep=`` line, names row, units row; host Unix stamps in ms that repeat and jitter,
so a uniform clock is fitted: docs/converters.md) of ``--hours`` and 4x as many hours at 51.2 Hz, then converts each
with ``imulog convert`` in a fresh subprocess (a) piece by piece (``IMULOG_STREAM_MIN_BYTES=0``, 16 MB pieces: two
passes over the file, the first summing the line) and (b) in one piece (the whole-file path). Peak RSS, user+sys CPU
and wall time are the subprocess's own (``resource.getrusage``); the machine is shared, so CPU time is the figure to
compare.

    .venv/bin/python benchmarks/bench_convert_pieces.py [--hours 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def host_clock_csv(path: Path, n: int, *, rate_hz: float = 51.2, seed: int = 0, late: dict[int, float] | None = None):
    """A Shimmer Consensys export of ``n`` samples whose host Unix stamps (ms) repeat and jitter: packets of 4
    samples stamped on arrival. ``late``: row -> extra delay (s) of that row's stamp. Returns the stamps (ms)."""
    rng = np.random.default_rng(seed)
    t_true_ms = 1.6e12 + np.arange(n) * (1000.0 / rate_hz)
    arrival = t_true_ms[(np.arange(n) // 4) * 4 + 3] + rng.uniform(0, 15, n)  # a packet is stamped when it arrives
    for row, delay_s in (late or {}).items():
        arrival[row] += delay_s * 1000.0
    stamps = np.floor(arrival)  # 1 ms resolution: repeats within a packet
    acc = rng.normal(0, 1, (n, 3)) + [0, 0, 9.81]
    gyr = rng.normal(0, 5, (n, 3))
    pre = "Shimmer_40AC_"
    names = [pre + "Timestamp_Unix_CAL"]
    names += [pre + f"Accel_LN_{a}_CAL" for a in "XYZ"] + [pre + f"Gyro_{a}_CAL" for a in "XYZ"]
    units = ["ms"] + ["m/(s^2)"] * 3 + ["deg/s"] * 3
    with open(path, "w") as f:
        f.write('"sep=;"\n' + ";".join(names) + "\n" + ";".join(units) + "\n")
        np.savetxt(f, np.column_stack([stamps, acc, gyr]), delimiter=";", fmt=["%.0f"] + ["%.5f"] * 6)
    return stamps


_CHILD = """
import json, resource, sys, time
t0 = time.perf_counter()
from imulog.cli import cli
try:
    cli(["convert", sys.argv[1], "-o", sys.argv[2], "--attach-original", "never"], standalone_mode=False)
finally:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    print(json.dumps({"wall_s": time.perf_counter() - t0, "cpu_s": ru.ru_utime + ru.ru_stime,
                      "peak_mb": ru.ru_maxrss / 1024}), file=sys.stderr)
"""


def convert(src: Path, out: Path, pieces: bool) -> dict:
    env = dict(os.environ, IMULOG_STREAM_MIN_BYTES="0" if pieces else str(1 << 60))
    res = subprocess.run([sys.executable, "-c", _CHILD, str(src), str(out)], capture_output=True, text=True, env=env)
    if res.returncode != 0:
        raise SystemExit(res.stderr[-2000:])
    assert ("piece by piece" in res.stdout) == pieces, res.stdout
    out.unlink()
    return json.loads(res.stderr.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=2.0, help="the short file; the long one is 4x (default 2)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rows = []
        for hours in (args.hours, 4 * args.hours):
            src = Path(tmp) / f"shimmer_{hours:g}h.csv"
            n = int(hours * 3600 * 51.2)
            host_clock_csv(src, n)
            size_mb = src.stat().st_size / 1e6
            for pieces in (True, False):
                r = convert(src, Path(tmp) / "out.mcap", pieces)
                rows.append((hours, n, size_mb, "pieces" if pieces else "one piece", r))
                print(
                    f"{hours:5.1f} h  {n / 1e6:5.2f} M samples  {size_mb:6.0f} MB text  {rows[-1][3]:9s}  "
                    f"peak {r['peak_mb']:6.0f} MB  cpu {r['cpu_s']:6.1f} s  wall {r['wall_s']:6.1f} s",
                    flush=True,
                )
        by = {(h, k): r for h, _, _, k, r in rows}
        short, long = args.hours, 4 * args.hours
        print(
            f"peak memory, 4x the hours: pieces {by[(long, 'pieces')]['peak_mb'] / by[(short, 'pieces')]['peak_mb']:.2f}x, "
            f"one piece {by[(long, 'one piece')]['peak_mb'] / by[(short, 'one piece')]['peak_mb']:.2f}x"
        )
        print(
            f"pieces / one piece at {long:g} h: peak {by[(long, 'pieces')]['peak_mb'] / by[(long, 'one piece')]['peak_mb']:.2f}x, "
            f"cpu {by[(long, 'pieces')]['cpu_s'] / by[(long, 'one piece')]['cpu_s']:.2f}x"
        )


if __name__ == "__main__":
    main()
