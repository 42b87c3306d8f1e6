"""OpenSense .sto orientation files (../shared/data/devices/opensense_sto, OpenSim, Apache-2.0) against the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError, convert_file, detect

STO = "devices/opensense_sto"


def parse(path: Path) -> tuple[list[str], np.ndarray, dict[str, np.ndarray]]:
    """Columns, time and w,x,y,z per column, read by hand from the text."""
    lines = path.read_text().splitlines()
    end = next(i for i, x in enumerate(lines) if x.strip() == "endheader")
    cols = lines[end + 1].split("\t")
    data = [x.split("\t") for x in lines[end + 2 :] if x.strip()]
    t = np.array([float(r[0]) for r in data])
    q = {c: np.array([[float(v) for v in r[j].split(",")] for r in data]) for j, c in enumerate(cols) if j}
    return cols, t, q


@pytest.mark.parametrize(
    "name, n_imus, rows, t0",
    [
        ("MT_012005D6_009-quaternions_calibration_trial_Facing_negX.sto", 8, 401, 678.0),
        ("myComplexTasksTrial_orientations.sto", 7, 6, 0.0),
    ],
)
def test_orientation_file_matches_the_text(shared_data, name, n_imus, rows, t0):
    path = shared_data / STO / name
    assert detect(path).name == "opensim-sto"
    rec = convert_file(path)
    cols, t, q = parse(path)
    assert len(rec.signals) == n_imus and not rec.imus
    for sig, col in zip(rec.signals, cols[1:], strict=True):
        assert col.endswith("_imu") and sig.topic == f"/orientation/{col}"
        assert sig.columns == ["qw", "qx", "qy", "qz"]
        np.testing.assert_array_equal(sig.values, q[col])  # cells hold w,x,y,z
    assert len(rec.signals[0]) == rows
    np.testing.assert_array_equal(rec.signals[0].t_ns, np.round(t * 1e9).astype(np.int64))
    assert rec.signals[0].t_ns[0] == int(t0 * 1e9)  # time kept as written (678 s, not shifted to 0)
    meta = rec.metadata["imulog.device.opensense"]
    assert meta["rate_hz"] == 100.0 and meta["data_type"] == "Quaternion"


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda s: s.replace("endheader", "endhead"), r"no 'endheader' line"),
        # a short row above the last is an error; a cut last row is dropped with a warning (test_convert_validation)
        (lambda s: s.replace(s.splitlines()[-2], s.splitlines()[-2].rsplit(",", 1)[0]), r"line 11: truncated line"),
        (lambda s: s.replace("DataType=Quaternion", "DataType=Mat33"), r"DataType=Mat33 is not supported"),
        (lambda s: s.replace("\n0.01\t", "\n0\t", 1), r"line 8, column 'time': duplicated time stamp"),
    ],
)
def test_damaged_sto(shared_data, tmp_path, damage, message):
    bad = tmp_path / "bad.sto"
    bad.write_text(damage((shared_data / STO / "myComplexTasksTrial_orientations.sto").read_text()))
    with pytest.raises(ConversionError, match=message):
        convert_file(bad)
