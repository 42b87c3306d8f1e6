"""ActiGraph counts' resampling to 30 Hz: ActiLife's resampler against the polyphase one it replaced at 40-100 Hz.

    python benchmarks/bench_counts_resample.py          # agreement with agcounts + speed on 1 h at 100 Hz

Agreement: largest difference per 10-s epoch and axis, and total counts, against agcounts' stored output
(tests/data/agcounts_10s.csv) for the AX6 and GT9X samples (../shared/data, if present) and the closed-form signals of
tests/data/agcounts_signals.py, with each resampler. Speed: wall and CPU (user+sys) seconds to bring one hour of
100 Hz (3 axes) to 30 Hz, best of 3, both resamplers in this process (the machine is shared: CPU time is the
steadier figure).
"""

from __future__ import annotations

import csv
import importlib.util
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.signal import resample_poly

from imulog.process import epochs as ep
from imulog.process.counts_resample import actilife_to_30hz

REPO = Path(__file__).resolve().parent.parent
DATA = REPO / "tests" / "data"


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def poly_to_30hz(g: np.ndarray, rate: float) -> np.ndarray:
    """The resampler imulog used before (polyphase, anti-aliased)."""
    up, down = ep.counts_factors(rate)
    return g[::down] if up == 1 else resample_poly(g, up, down, axis=0, padtype="line")


def counts(g: np.ndarray, rate: float, resample) -> np.ndarray:
    return ep.counts_per_epoch(ep.CountsFilter()(resample(g, rate)), 10.0)


def reference() -> dict[tuple[str, int], np.ndarray]:
    out: dict[tuple[str, int], list[list[float]]] = {}
    with open(DATA / "agcounts_10s.csv", newline="") as f:
        for r in csv.DictReader(f):
            out.setdefault((r["file"], int(r["rate_hz"])), []).append(
                [float(r[c]) for c in ("counts_x", "counts_y", "counts_z")]
            )
    return {k: np.array(v) for k, v in out.items()}


def shared_g(name: str, topic: str) -> np.ndarray | None:
    """A shared recording (../shared/data/devices/NAME) converted by imulog, acceleration in g; None if absent."""
    from click.testing import CliRunner

    from imulog.archive import TrialReader
    from imulog.cli import cli

    src = REPO / ".." / "shared" / "data" / "devices" / name
    if not src.exists():
        return None
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "t.mcap"
        r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
        if r.exit_code:
            raise SystemExit(r.output)
        with TrialReader(out) as t:
            return np.asarray(t.read(topic).acc, dtype=np.float64) / 9.80665


def main() -> int:
    spec = importlib.util.spec_from_file_location("agcounts_signals", DATA / "agcounts_signals.py")
    sig = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sig)
    ref = reference()
    cases = [(f"closed-form {r} Hz", r, sig.synthetic_acc(r), ref[("synthetic", r)]) for r in sig.RATES_HZ]
    for label, name, topic, rate in (
        ("AX6 sample 100 Hz", "axivity_cwa/ax6_sample.cwa", "/imu/ax6_6011802", 100),
        ("GT9X sample 90 Hz", "actigraph_gt3x/example.gt3x", "/imu/tas1e31150129", 90),
    ):
        g = shared_g(name, topic)
        if g is not None:
            cases.insert(0, (label, rate, g, ref[(name, rate)]))
    print("largest |difference| per 10-s epoch and axis (x, y, z) and total counts, against agcounts 0.2.6")
    print(f"  {'signal':22s} {'ActiLife resampler':>26s} {'polyphase (before)':>30s}   agcounts total")
    for name, rate, acc, r in cases:
        cols = []
        for fn in (ep.to_30hz, poly_to_30hz):
            c = counts(acc, rate, fn)[: len(r)]
            d = np.abs(c - r).max(axis=0).astype(int)
            cols.append(f"{d[0]:3d} {d[1]:3d} {d[2]:3d}  total {int(c.sum()):6d}")
        print(f"  {name:22s} {cols[0]:>26s} {cols[1]:>30s}   {int(r.sum()):6d}")
    hour = np.random.default_rng(0).normal(0.0, 0.3, (360_000, 3)) + [0.0, 0.0, 1.0]
    print("one hour at 100 Hz to 30 Hz (best of 3; wall and CPU s)")
    best = {}
    for name, fn in (("ActiLife", lambda a: actilife_to_30hz(a, 3, 10)), ("polyphase", lambda a: poly_to_30hz(a, 100))):
        runs = []
        for _ in range(3):
            w0, c0 = time.perf_counter(), _cpu()
            fn(hour)
            runs.append((time.perf_counter() - w0, _cpu() - c0))
        best[name] = min(runs, key=lambda x: x[1])
        print(f"  {name:10s} wall {best[name][0]:.3f} s  CPU {best[name][1]:.3f} s")
    print(f"  CPU ratio ActiLife / polyphase: {best['ActiLife'][1] / best['polyphase'][1]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
