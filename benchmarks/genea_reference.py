"""imulog's older-Genea reader against the values GGIRread's own test documents for GGIR's ``genea_testfile.bin``.

The file is not redistributed here (GGIR shipped it under the LGPL until it moved to GGIRread); get it from GGIR's
history (``inst/testfiles/genea_testfile.bin``, 262 144 bytes) and pass its path::

    python benchmarks/genea_reference.py genea_testfile.bin

GGIRread's ``test_GeneaBinReader.R`` reads pages 1 to 4 (end exclusive: three pages) and expects 993 samples (it
cuts at the first sample of the last time stamp), a sum of 1 058 559 over its x, y, z in whole mg (two integer
roundings: counts x gain / 8192, then x 1000 / 340), 4 battery readings, the first at 1 269 950 921 s, and the
100th sample's time 1 269 950 922 (its ``expect_equal`` tolerance, 1.5e-8 relative, is about 19 s; GGIRread's own
rule, extrapolating the samples before the second stamp back from it at 1/80 s, puts it at 1 269 950 921.8375). This script reads the same pages from imulog's decode (one page per
piece) and prints both.
"""

from __future__ import annotations

import sys
from datetime import datetime
from pathlib import Path

import imulog.converters.genea as genea
import numpy as np
from imulog.converters._common import G0

EXPECTED = {"rows": 993, "sum_mg": 1058559, "battery": 4, "battery_t0": 1269950921, "t100": 1269950921.8375}


def main(path: Path) -> int:
    genea.PAGES_PER_CHUNK = 1  # one piece per page, so pages 1-3 are pieces 1-3
    pieces = list(genea.iter_chunks(path))
    meta = pieces[0].metadata["imulog.device.genea"]
    start = datetime.fromisoformat(pieces[0].metadata["imulog.trial"]["start_time"])
    t0 = (start - datetime(1970, 1, 1)).total_seconds()
    imu = [p.imus[0] for p in pieces[1:4]]
    t = t0 + np.concatenate([i.t_ns for i in imu]) / 1e9
    g = np.concatenate([i.acc for i in imu]) / G0
    gains = np.array(meta["calibration"]["gain"], float)
    offsets = np.array(meta["calibration"]["offset"], float)
    signed = np.rint(g * (8192 * 340 / gains) - offsets)  # the stored counts with the axis signs applied
    at_stamp = np.flatnonzero(np.abs(t - np.round(t)) < 1e-6)
    rows = int(at_stamp[-1]) + 1  # GGIRread keeps up to the first sample of the last stamp
    mg = np.rint(np.rint((signed + offsets) * gains / 8192) * 1000 / 340)[:rows]
    bat = np.concatenate([p.signals[0].t_ns for p in pieces[1:4]]) / 1e9 + t0
    ours = {
        "rows": rows,
        "sum_mg": int(mg.sum()),
        "battery": len(bat),
        "battery_t0": int(np.floor(bat[0] + 1e-6)),
        "t100": round(float(t[99]), 4),
    }
    exact = (signed + offsets) * gains / 8192 * 1000 / 340
    print(f"{'quantity':12} {'GGIRread test':>14} {'imulog':>14}")
    for k, v in EXPECTED.items():
        print(f"{k:12} {v:>14} {ours[k]:>14}  {'equal' if v == ours[k] else 'DIFFERENT'}")
    print(f"imulog's exact mg vs GGIRread's rounded mg: max |difference| {np.abs(exact[:rows] - mg).max():.2f} mg")
    return 0 if ours == EXPECTED else 1


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1])))
