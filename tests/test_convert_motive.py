"""OptiTrack Motive CSV: the real format 1.21 take (../shared/data/devices/optitrack_motive, cmuphyscomp/hmv-s16,
BSD-3-Clause) against its numbers, and a format 1.23 file written here with 1.23's header differences."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError, convert_file, detect

MOTIVE = "devices/optitrack_motive/sample_optitrack_take.csv"


def test_format_121_take_matches_the_file(shared_data):
    path = shared_data / MOTIVE
    assert detect(path).name == "motive"
    rec = convert_file(path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    data = rows[7:]
    assert len(data) == 250
    (pose,) = rec.poses
    assert pose.topic == "/poses/rigid_body_1"
    xyzw = np.array([[float(r[j]) for j in (2, 3, 4, 5)] for r in data])
    np.testing.assert_array_equal(pose.orientation, xyzw[:, [3, 0, 1, 2]])  # X,Y,Z,W in the file -> w,x,y,z
    np.testing.assert_array_equal(pose.position, np.array([[float(r[j]) for j in (6, 7, 8)] for r in data]))
    np.testing.assert_array_equal(pose.t_ns, np.round(np.array([float(r[1]) for r in data]) * 1e9).astype(np.int64))
    markers = next(m for m in rec.markers if m.name == "motive")
    names = rows[3]
    assert markers.labels[:3] == ["Unlabeled:108", "Unlabeled:110", "Unlabeled:111"]
    assert "Rigid Body 1:Marker1" in markers.labels
    j = names.index("Unlabeled:108")
    cells = [r[j] for r in data]
    valid = np.array([c != "" for c in cells])
    np.testing.assert_array_equal(markers.valid[:, 0], valid)  # empty cells = occluded = invalid
    np.testing.assert_array_equal(markers.pos[valid, 0, 0], [float(c) for c in cells if c])
    occluded = markers.labels.index("Unlabeled:105")
    assert not markers.valid[:, occluded].any() and np.isnan(markers.pos[:, occluded]).all()
    model = next(m for m in rec.markers if m.name == "motive_rigid_body_markers")
    assert model.labels == ["Rigid Body 1_1", "Rigid Body 1_2", "Rigid Body 1_3"]
    meta = rec.metadata["imulog.device.motive"]
    assert (meta["format_version"], meta["rate_hz"], meta["length_units"]) == ("1.21", 120.0, "Meters")
    trial = rec.metadata["imulog.trial"]
    assert trial["start_time"] == "2016-01-05T15:49:50.755000"  # 03.49.50.755 PM, the capture PC's local time
    assert trial["time_zone"] == "unknown (device local time)"


def write_motive_123(path: Path, n: int = 40) -> dict[str, np.ndarray]:
    """Format 1.23 (Motive 3): ',Type,' / ',Name,' / ',ID,' label rows, 'Time (Seconds)', extra header keys, mm."""
    rng = np.random.default_rng(7)
    t = np.arange(n) / 240.0
    xyzw = rng.normal(0, 1, (n, 4))
    xyzw /= np.linalg.norm(xyzw, axis=1, keepdims=True)
    pos_mm = rng.normal(0, 500, (n, 3))
    marker_mm = rng.normal(0, 500, (n, 3))
    marker_mm[10:15] = np.nan  # occluded
    head = (
        "Format Version,1.23,Take Name,wrist_reach,Take Notes,,Capture Frame Rate,240.000000,Export Frame Rate,"
        "240.000000,Capture Start Time,2023-11-08 10.04.31.118 AM,Capture Start Frame,1043,Total Frames in Take,"
        f"{n},Total Exported Frames,{n},Rotation Type,Quaternion,Length Units,Millimeters,Coordinate Space,Global"
    )
    lines = [
        head,
        "",
        ",Type," + ",".join(["Rigid Body"] * 8 + ["Marker"] * 3),
        ",Name," + ",".join(["Wrist"] * 8 + ["Wrist:Marker1"] * 3),
        ",ID," + ",".join(["1"] * 8 + ["2"] * 3),
        ",," + ",".join(["Rotation"] * 4 + ["Position"] * 3 + ["Mean Marker Error"] + ["Position"] * 3),
        "Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,,X,Y,Z",
    ]
    for i in range(n):
        m = ["" if np.isnan(v) else f"{v:.6f}" for v in marker_mm[i]]
        cells = [str(i), f"{t[i]:.6f}", *(f"{v:.6f}" for v in xyzw[i]), *(f"{v:.6f}" for v in pos_mm[i]), "0.25", *m]
        lines.append(",".join(cells))
    path.write_text("\r\n".join(lines) + "\r\n")
    return {"xyzw": np.round(xyzw, 6), "pos_m": np.round(pos_mm, 6) / 1000, "marker_m": np.round(marker_mm, 6) / 1000}


def test_format_123_header_differences_and_millimetres(tmp_path):
    path = tmp_path / "wrist_reach.csv"
    truth = write_motive_123(path)
    assert detect(path).name == "motive"
    rec = convert_file(path)
    (pose,) = rec.poses
    assert pose.topic == "/poses/wrist"
    np.testing.assert_allclose(pose.orientation, truth["xyzw"][:, [3, 0, 1, 2]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(pose.position, truth["pos_m"], rtol=1e-12)  # mm -> m
    (markers,) = rec.markers
    assert markers.labels == ["Wrist:Marker1"]
    assert (~markers.valid[:, 0]).sum() == 5 and not markers.valid[10:15, 0].any()
    np.testing.assert_allclose(markers.pos[:, 0], truth["marker_m"], rtol=1e-12)
    (err,) = rec.signals
    assert err.columns == ["Mean Marker Error"] and err.values[0, 0] == pytest.approx(0.00025)  # mm -> m
    assert pose.t_ns[1] == 4_167_000  # the Time column as printed (0.004167 s), not a rate-derived clock
    assert rec.metadata["imulog.trial"]["start_time"] == "2023-11-08T10:04:31.118000"


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda s: s.replace("Rotation Type,Quaternion", "Rotation Type,XYZ"), r"Rotation Type XYZ: export again"),
        (lambda s: s.replace("Length Units,Millimeters", "Length Units,Furlongs"), r"unknown Length Units"),
        # a short row above the last is an error; a cut last row is dropped with a warning (test_convert_validation)
        (lambda s: s.replace(s.split("\r\n")[-3], s.split("\r\n")[-3].rsplit(",", 1)[0]), "line 46: truncated line"),
        (
            lambda s: re.sub(r"\r\n20,[^,]*,", "\r\n20,0.0x,", s, count=1),
            r"line 28, column 'Time \(Seconds\)': '0.0x' is not",
        ),
        (lambda s: "\r\n".join(s.split("\r\n")[:5]), r"no 'Frame,Time,...' row"),
    ],
)
def test_damaged_motive_file(tmp_path, damage, message):
    good = tmp_path / "good.csv"
    write_motive_123(good)
    bad = tmp_path / "bad.csv"
    bad.write_bytes(damage(good.read_bytes().decode()).encode())
    with pytest.raises(ConversionError, match=message):
        convert_file(bad)


def test_skeleton_bones_are_poses_too(tmp_path):
    path = tmp_path / "skeleton.csv"
    truth = write_motive_123(path)
    path.write_bytes(path.read_bytes().replace(b",Type,Rigid Body", b",Type,Bone").replace(b",Rigid Body", b",Bone"))
    (pose,) = convert_file(path).poses
    assert pose.topic == "/poses/wrist"
    np.testing.assert_allclose(pose.position, truth["pos_m"], rtol=1e-12)
