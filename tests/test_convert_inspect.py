"""Grouped two-row headers with a reference orientation, recognised formats without a reader, --inspect."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, UnknownFormatError, convert_file, detect

from imulog.cli import cli

DEG = np.pi / 180


def _grouped(tmp: Path, *, trailing_header: bool, trailing_data: bool, units: bool = False) -> tuple[Path, dict]:
    """The IMU + Vicon CSV layout: a group row (time label, Vicon Orientation, IMU Acceleration, IMU Gyroscope)
    and an axis row, semicolons, trailing delimiters where asked; motion a real limb could make."""
    n = 400
    t = np.arange(n) / 100
    ang = 0.8 * np.sin(2 * np.pi * 0.5 * t)
    q = np.column_stack([np.cos(ang / 2), np.sin(ang / 2), 0 * t, 0 * t])
    acc = np.column_stack([0 * t, 9.81 * np.sin(ang), 9.81 * np.cos(ang)])
    gyr = np.column_stack([np.gradient(ang, t) / DEG, 0 * t, 0 * t])
    acc_label, gyr_label = (
        ("IMU Acceleration (m/s^2)", "IMU Gyroscope (deg/s)") if units else ("IMU Acceleration", "IMU Gyroscope")
    )
    end_h, end_d = (";" if trailing_header else ""), (";" if trailing_data else "")
    lines = [
        f"Time (s);Vicon Orientation;;;;{acc_label};;;{gyr_label};;{end_h}",
        f";W;X;Y;Z;X;Y;Z;X;Y;Z{end_h}",
    ]
    vals = np.column_stack([t, q, acc, gyr])
    lines += [";".join(f"{v:.6f}" for v in row) + end_d for row in vals]
    path = tmp / "imu_vicon.csv"
    path.write_text("\n".join(lines) + "\n")
    rounded = np.round(vals, 6)
    return path, {"t": rounded[:, 0], "q": rounded[:, 1:5], "acc": rounded[:, 5:8], "gyr": rounded[:, 8:11]}


@pytest.mark.parametrize(
    ("trailing_header", "trailing_data"), [(True, False), (False, False), (True, True), (False, True)]
)
def test_grouped_header_with_reference_orientation(tmp_path, trailing_header, trailing_data):
    path, exp = _grouped(tmp_path, trailing_header=trailing_header, trailing_data=trailing_data)
    rec = convert_file(path)
    (imu,) = rec.imus
    np.testing.assert_allclose(imu.acc, exp["acc"], rtol=1e-15)  # m/s^2, inferred from the values
    np.testing.assert_allclose(imu.gyr, exp["gyr"] * DEG, rtol=1e-15)  # deg/s, inferred
    np.testing.assert_array_equal(imu.t_ns, np.round(exp["t"] * 1e9).astype(np.int64))
    (orient,) = [s for s in rec.signals if s.topic.startswith("/orientation/")]
    assert orient.topic == "/orientation/vicon" and orient.columns == ["qw", "qx", "qy", "qz"]
    np.testing.assert_array_equal(orient.values, exp["q"])
    np.testing.assert_array_equal(orient.t_ns, imu.t_ns)
    assert rec.metadata["imulog.device.vicon"]["orientation"]["topic"] == "/orientation/vicon"
    assert any("no units in the header" in w for w in rec.warnings)


def test_grouped_header_units_in_group_labels(tmp_path):
    path, exp = _grouped(tmp_path, trailing_header=True, trailing_data=False, units=True)
    rec = convert_file(path)
    assert rec.imus[0].meta["units"] == {"acc": "m/s^2", "gyr": "deg/s"}
    assert not any("no units" in w for w in rec.warnings)


def test_quaternion_group_missing_a_component(tmp_path):
    path = tmp_path / "q.csv"
    path.write_text(
        "Time (s);Vicon Orientation;;;IMU Acceleration (g);;\n;W;X;Y;X;Y;Z\n0;1;0;0;0;0;1\n0.01;1;0;0;0;0;1\n"
    )
    with pytest.raises(ConversionError, match=r"q\.csv: orientation group 'vicon': no quaternion column z"):
        convert_file(path)


# ---------------------------------------------------------------------------------- recognised, not read
# (GENEActiv, EDF/BDF, TRC and scalar .mot/.sto have readers now: their damaged headers are each reader's own
# one-line ConversionError, tests/test_convert_{geneactiv,edf,opensim}.py)
@pytest.mark.parametrize(
    ("content", "name", "named"),
    [
        (b"# OpenSignals Text File Format\n# odd variant\n1\t2\n", "x.txt", "OpenSignals"),
        (b"PK\x03\x04" + b"\x00" * 26 + b"xl/workbook.xml", "a.xlsx", "Excel"),
        (b"MATLAB 5.0 MAT-file, Platform: GLNXA64", "d.mat", "MATLAB"),
        (b"PAR1\x00\x00", "d.parquet", "Parquet"),
        (b"GENEA" + bytes(range(1, 200)), "old.bin", "older Genea"),  # no CRLF header: the genea reader declines
    ],
)
def test_recognised_formats_without_a_reader_are_named(tmp_path, content, name, named):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(UnknownFormatError) as err:
        detect(path)
    msg = str(err.value)
    assert named in msg and "recognised as" in msg and "\n" not in msg
    assert "unknown format" not in msg


def test_shared_companion_file_names_its_format(shared_data: Path):
    """A NilsPod _header.json holds no samples: named, with the file to convert instead."""
    path = shared_data / "devices" / "nilspod" / "NilsPodX-6F13_20210109_162824_header.json"
    with pytest.raises(UnknownFormatError) as err:
        detect(path)
    msg = str(err.value)
    assert "recognised as NilsPod session header" in msg and "_data.csv" in msg and "\n" not in msg


def test_inspect_prints_columns_streams_start_and_warnings_without_writing(tmp_path):
    path, _ = _grouped(tmp_path, trailing_header=True, trailing_data=False)
    before = set(tmp_path.iterdir())
    result = CliRunner().invoke(cli, ["convert", "--inspect", str(path)])
    assert result.exit_code == 0, result.output
    out = result.output
    assert "imu_vicon.csv: format delimited" in out
    assert "column 2 'Vicon Orientation/W' -> /orientation/vicon qw" in out
    assert "column 6 'IMU Acceleration/X' -> /imu/imu acc x [unit from the values]" in out
    assert "/imu/imu: 400 samples, 100 Hz" in out
    assert "start time: none in the file" in out
    assert "warning: imu_vicon.csv: no units in the header: assumed acc in m/s^2" in out
    assert set(tmp_path.iterdir()) == before  # nothing written


def test_inspect_json_and_errors(tmp_path):
    path, _ = _grouped(tmp_path, trailing_header=False, trailing_data=False, units=True)
    result = CliRunner().invoke(cli, ["convert", "--inspect", "--json", str(path)])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    (report,) = doc["inspect"]
    assert report["inputs"] == {"imu_vicon.csv": "delimited"}
    assert {s["topic"] for s in report["streams"]} == {"/imu/imu", "/orientation/vicon"}
    assert report["warnings"] == [] and doc["errors"] == []
    bad = tmp_path / "bad.csv"
    bad.write_text("Time (s),Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n0,1,2\n")
    result = CliRunner().invoke(cli, ["convert", "--inspect", str(bad)])
    assert result.exit_code == 1
    assert "bad.csv: line 2: truncated line" in result.output


def test_grouped_position_and_orientation_become_a_reference_pose(tmp_path):
    n = 300
    t = np.arange(n) / 100
    ang = 0.8 * np.sin(2 * np.pi * 0.5 * t)
    q = np.round(np.column_stack([np.cos(ang / 2), np.sin(ang / 2), 0 * t, 0 * t]), 6)
    p = np.round(np.column_stack([100 + 50 * np.sin(t), 200 + 0 * t, 900 + 10 * np.cos(t)]), 6)
    acc = np.round(np.column_stack([0 * t, 9.81 * np.sin(ang), 9.81 * np.cos(ang)]), 6)
    lines = ["Time (s);Vicon Position (mm);;;Vicon Orientation;;;;IMU Acceleration (m/s^2);;;", ";X;Y;Z;W;X;Y;Z;X;Y;Z;"]
    lines += [";".join(f"{v:.6f}" for v in [t[i], *p[i], *q[i], *acc[i]]) for i in range(n)]
    path = tmp_path / "pose.csv"
    path.write_text("\n".join(lines) + "\n")
    rec = convert_file(path)
    (pose,) = rec.poses
    assert pose.topic == "/poses/vicon"
    np.testing.assert_allclose(pose.position, p / 1000, rtol=1e-12)  # mm -> m
    np.testing.assert_allclose(pose.orientation, q, rtol=1e-15)
    assert not rec.signals and not rec.markers
    path.write_text("\n".join([lines[0].replace(" (mm)", ""), *lines[1:]]) + "\n")
    with pytest.raises(ConversionError, match=r"position group 'Vicon Position' has no length unit"):
        convert_file(path)
