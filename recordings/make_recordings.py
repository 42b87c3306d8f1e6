"""Regenerate the small simulated recordings in this folder (deterministic: same files every run).

    python recordings/make_recordings.py            # writes recordings/sim/

* ``r2g_s00_t00_*``: R2G drinking task, 5 repetitions, timing shortened (2 s statics, 3.5 s rest,
  6 s opening static) to keep the files small; LSM9DS1-like noise, drifting clocks, dropped
  samples and marker gaps as in a default simulation.

(Other protocols are one command away -- ``imulog simulate slide|nhpt|adl -o DIR`` -- and are not
stored, to keep the repository's recordings under ~2 MB.)

Each trial: ``_imu.csv`` + ``_imu.mapping.json`` (BlueBuddy-style text), ``_vicon.csv`` (Nexus CSV),
``_meta.json`` (for ``imulog convert --meta-file``), ``_truth.json`` + ``_truth.npz`` (compact
ground truth: per-IMU-sample kinematics are rebuilt on load). See docs/simulate.md.
"""

from __future__ import annotations

import sys
from pathlib import Path

from imulog.simulate import simulate, write_trial_files

HERE = Path(__file__).resolve().parent

TRIALS = {
    "r2g": {
        "repetitions": 5,
        "static_s": 2.0,
        "static_jitter_s": 0.3,
        "rest_s": 3.5,
        "rest_jitter_s": 0.5,
        "opening_static_s": 6.0,
        "post_wave_static_s": 3.0,
        "closing_static_s": 2.0,
    },
}


def main(out_dir: Path = HERE / "sim") -> list[dict[str, Path]]:
    written = []
    for protocol, overrides in TRIALS.items():
        sim = simulate(protocol, subject=0, trial=0, seed=2026, **overrides)
        written.append(write_trial_files(sim, out_dir, compact_truth=True))
    return written


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "sim"
    for paths in main(out):
        for path in paths.values():
            print(f"{path.stat().st_size:>9}  {path}")
