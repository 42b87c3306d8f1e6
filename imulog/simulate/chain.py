"""A simulated stand-in for a hand-moved 5-segment chain recording as two CSV files (issue 32).

One IMU per segment at 40 Hz, all five in ONE CSV without a time column (``seg1_acc_x`` ... ``seg5_gyr_z``, g and
deg/s), four markers per segment at 30 Hz in another CSV with one column per marker axis (``seg1_marker1_x``, mm,
empty cells where occluded), and a mapping file beside each (``chain_imu.mapping.json``,
``chain_markers.mapping.json``) so that ``imulog convert chain_imu.csv chain_markers.csv -o chain.mcap`` reads
them with nothing else. Each segment is the ``continuous`` protocol with its own seed (still only at the start,
the end and once for 0.3 s); the five IMUs share one clock, as rows of one file do.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from imulog.simulate.core import SimulatedTrial, simulate

SEGMENTS = 5
G = 9.80665
IMU_HZ, MARKER_HZ = 40.0, 30.0
CLOCK = dict(imu_start_ref_s=1.0, imu_stop_early_s=1.0, device_t0_s=100.0, drift_ppm=20.0)


def write_chain(
    folder: Path, segments: int = SEGMENTS, duration_s: float = 50.0
) -> tuple[Path, Path, list[SimulatedTrial]]:
    """The two CSV files of the chain and a mapping file beside each; returns (imu csv, marker csv, sims)."""
    sims = [
        simulate(
            "continuous",
            subject=s,
            seed=20 + s,
            duration_s=duration_s,
            rests=1,
            rest_s=0.3,
            imu_rate_hz=IMU_HZ,
            vicon_rate_hz=MARKER_HZ,
            drop_probability=0.0,
            **CLOCK,
        )
        for s in range(segments)
    ]
    n_imu = min(len(s.recording.imus[0].t_ns) for s in sims)
    n_mk = min(len(s.recording.markers[0].t_ns) for s in sims)
    names, cols, imu_cols = [], [], {}
    for k, sim in enumerate(sims, start=1):
        imu = sim.recording.imus[0]
        for q, vals, unit, scale in (("acc", imu.acc, "g", 1 / G), ("gyr", imu.gyr, "deg/s", 180 / np.pi)):
            for j, a in enumerate("xyz"):
                name = f"seg{k}_{q}_{a}"
                names.append(name)
                cols.append(vals[:n_imu, j] * scale)
                imu_cols[name] = {"quantity": q, "axis": a, "unit": unit, "sensor": f"seg{k}"}
    imu_csv = folder / "chain_imu.csv"
    np.savetxt(imu_csv, np.column_stack(cols), delimiter=",", header=",".join(names), comments="", fmt="%.6f")
    (folder / "chain_imu.mapping.json").write_text(
        json.dumps(
            {
                "format": "imulog.mapping/1",
                "device": {"name": "chain", "rate_hz": IMU_HZ},
                "time": {"column": None},
                "columns": imu_cols,
            }
        )
    )
    names, cols, mk_cols = [], [], {}
    for k, sim in enumerate(sims, start=1):
        mk = sim.recording.markers[0]
        if len(mk.labels) != 4:
            raise ValueError(f"the continuous protocol gave {len(mk.labels)} markers per segment, not 4")
        for m in range(4):
            for j, a in enumerate("xyz"):
                name = f"seg{k}_marker{m + 1}_{a}"
                names.append(name)
                cols.append(mk.pos[:n_mk, m, j] * 1000.0)  # mm; NaN (occlusion) -> empty cell below
                mk_cols[name] = {"quantity": "marker", "marker": f"seg{k}_marker{m + 1}", "axis": a, "unit": "mm"}
    mk_csv = folder / "chain_markers.csv"
    table = np.column_stack(cols)
    lines = [",".join(names)] + [",".join("" if np.isnan(v) else f"{v:.3f}" for v in row) for row in table]
    mk_csv.write_text("\n".join(lines) + "\n")
    (folder / "chain_markers.mapping.json").write_text(
        json.dumps(
            {
                "format": "imulog.mapping/1",
                "device": {"name": "optical", "rate_hz": MARKER_HZ},
                "time": {"column": None},
                "columns": mk_cols,
            }
        )
    )
    return imu_csv, mk_csv, sims
