"""Qualisys QTM .tsv 3D export: no redistributable sample exists, so files are written here in QTM's documented
layout (key/value header, MARKER_NAMES, optional Frame/Time columns) and the stored values compared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError, convert_file, detect

MARKERS = ["RSHO", "RELB", "RWRA"]


def write_qtm(path: Path, n: int = 50, *, time_columns: bool = True, names_row: bool = True) -> np.ndarray:
    rng = np.random.default_rng(5)
    mm = np.round(rng.normal(0, 400, (n, len(MARKERS), 3)), 3)
    mm[7, 1] = 0.0  # QTM writes a missing marker as 0.000 0.000 0.000
    header = [
        f"NO_OF_FRAMES\t{n}",
        "NO_OF_CAMERAS\t8",
        f"NO_OF_MARKERS\t{len(MARKERS)}",
        "FREQUENCY\t200",
        "NO_OF_ANALOG\t0",
        "ANALOG_FREQUENCY\t0",
        "DESCRIPTION\t--",
        "TIME_STAMP\t2021-06-30, 10:12:59.345\t81234.56",
        "DATA_INCLUDED\t3D",
        "MARKER_NAMES\t" + "\t".join(MARKERS),
        "TRAJECTORY_TYPES\t" + "\t".join(["Measured"] * len(MARKERS)),
    ]
    cols = [f"{m} {a}" for m in MARKERS for a in "XYZ"]
    if names_row:
        header.append("\t".join((["Frame", "Time"] if time_columns else []) + cols))
    rows = []
    for i in range(n):
        cells = [f"{v:.3f}" for v in mm[i].ravel()]
        if i == 9:
            cells[6:9] = ["", "", ""]  # empty cells: also a gap
        rows.append("\t".join(([str(i + 1), f"{i / 200:.5f}"] if time_columns else []) + cells))
    path.write_text("\n".join(header + rows) + "\n")
    return mm


@pytest.mark.parametrize("time_columns, names_row", [(True, True), (False, False), (True, False)])
def test_qtm_markers_in_metres_with_gaps(tmp_path, time_columns, names_row):
    path = tmp_path / "reach_3d.tsv"
    mm = write_qtm(path, time_columns=time_columns, names_row=names_row)
    assert detect(path).name == "qualisys"
    rec = convert_file(path)
    (m,) = rec.markers
    assert m.topic == "/markers/qualisys" and m.labels == MARKERS
    valid = ~np.all(mm == 0, axis=2)
    valid[9, 2] = False
    np.testing.assert_array_equal(m.valid, valid)
    np.testing.assert_allclose(m.pos[valid], mm[valid] / 1000.0, rtol=1e-15)  # mm -> m
    assert np.isnan(m.pos[7, 1]).all() and np.isnan(m.pos[9, 2]).all()
    np.testing.assert_array_equal(m.t_ns, np.arange(50) * 5_000_000)  # 200 Hz from Time, Frame or the row
    meta = rec.metadata["imulog.device.qualisys"]
    assert meta["rate_hz"] == 200.0 and meta["missing_as_zero_samples"] == 1
    trial = rec.metadata["imulog.trial"]
    assert trial["start_time"] == "2021-06-30T10:12:59.345000" and trial["time_zone"] == "unknown (device local time)"


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda s: s.rsplit("\n", 6)[0] + "\n", r"line 57: file ends after 45 of NO_OF_FRAMES 50 frames"),
        (lambda s: s.replace("NO_OF_MARKERS\t3", "NO_OF_MARKERS\t4"), r"NO_OF_MARKERS is 4 but MARKER_NAMES lists 3"),
        (lambda s: s.replace("FREQUENCY\t200\n", ""), r"no FREQUENCY line"),
        (lambda s: s.replace("\n3\t", "\n3\tx", 1), r"line 15, column 'Time': 'x0.01000' is not a number"),
        # a cut last row is dropped, which leaves fewer rows than NO_OF_FRAMES: named as cut off
        (lambda s: s.rstrip()[: s.rstrip().rindex("\t")], r"line 61: file ends after 49 of NO_OF_FRAMES 50 frames"),
        (lambda s: s.replace("\n3\t", "\n3\t\t", 1), r"line 15: too many fields: 12 fields, expected 11"),
    ],
)
def test_damaged_qtm_file(tmp_path, damage, message):
    good = tmp_path / "good.tsv"
    write_qtm(good)
    bad = tmp_path / "bad.tsv"
    bad.write_text(damage(good.read_text()))
    with pytest.raises(ConversionError, match=message):
        convert_file(bad)
