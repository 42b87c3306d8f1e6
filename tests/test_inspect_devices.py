"""`imulog convert --inspect` on every folder of ../shared/data/devices (issue 25): every data file is named with its
format, nothing is written, no Python warning or traceback reaches the user, and the warnings say what is true."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
NOT_DATA = (".npz", ".md", ".tsv")


def test_inspect_every_device_folder(shared_data: Path, tmp_path: Path):
    devices = shared_data / "devices"
    folders = sorted(p for p in devices.iterdir() if p.is_dir())
    proc = subprocess.run(
        [sys.executable, "-m", "imulog", "convert", "--inspect", *map(str, folders)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = proc.stdout + proc.stderr
    assert "Warning" not in out and "Traceback" not in out, out[-3000:]  # e.g. numpy's RuntimeWarning lines
    assert list(tmp_path.iterdir()) == []  # nothing written
    for f in sorted(p for d in folders for p in d.iterdir()):
        if (
            f.name.startswith(("LICENSE", "NOTICE", "README"))
            or f.suffix in NOT_DATA
            or f.name.endswith("_header.json")
        ):
            continue  # licences, reference decodes, NilsPodLib's header (read with its _data.csv)
        # a vendor's export beside its device file is one recording with it: named as skipped, with the reason,
        # in the line `imulog convert FOLDER` prints (stderr)
        named = f"\n{f.name}: format " in "\n" + proc.stdout or f"\nskipped {f}: an export of " in "\n" + proc.stderr
        assert named, f.name
    igu = devices / "actigraph_gt3x" / "example-IMU.csv"
    assert f"\nskipped {igu}: an export of example.gt3x" in "\n" + proc.stderr
    # the Trigno exports' ACC channels hold no data (EDF physical min == max): said so, not blamed on a unit
    assert "/imu/mini_sensor_10: every acc value is 0 (the channel holds no data)" in proc.stdout
    assert "median |acc| is 0" not in proc.stdout
