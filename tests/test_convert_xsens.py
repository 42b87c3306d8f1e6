"""Xsens MT Manager exports: the real files of ../shared/data/devices/xsens_mtmanager (OpenSim test data,
Apache-2.0) against the numbers in the files, and written files for the UTC start time and damaged input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, ConvertOptions, convert_file, detect

from imulog.cli import cli
from imulog.process import quaternion as Q

XSENS = "devices/xsens_mtmanager"


def table(path: Path) -> tuple[list[str], list[list[str]]]:
    """The column names and raw cells of an MT Manager export, split by hand (independent of the converter)."""
    lines = path.read_text().splitlines()
    body = [x for x in lines if not x.startswith("//")]
    sep = next(d for d in ("\t", ";", ",", " ") if d in body[0])
    names = body[0].split(sep)
    return names, [row.split(sep) for row in body[1:]]


def column(path: Path, name: str) -> np.ndarray:
    names, rows = table(path)
    j = names.index(name)
    return np.array([float(r[j]) if r[j] not in ("", "NaN") else math.nan for r in rows])


def test_every_real_export_is_detected_and_matches_the_file(shared_data):
    files = sorted((shared_data / XSENS).glob("MT*.txt"))
    assert len(files) == 12
    for path in files:
        assert detect(path).name == "xsens", path.name
        rec = convert_file(path)
        (imu,) = rec.imus
        serial = path.stem.rsplit("_", 1)[-1]
        assert imu.name == f"mt_{serial.lower()}"  # from // DeviceId or, in old headers, the file name
        assert rec.metadata[f"imulog.device.{imu.name}"]["serial"] == serial
        np.testing.assert_array_equal(imu.acc[:, 2], column(path, "Acc_Z"))  # m/s^2 as written
        if "Gyr_X" in table(path)[0]:
            np.testing.assert_array_equal(imu.gyr[:, 1], column(path, "Gyr_Y"))
        counter = column(path, "PacketCounter")
        np.testing.assert_array_equal(imu.t_ns, np.round(counter * 1e7).astype(np.int64))  # 100 Hz


def test_four_delimiters_give_the_same_numbers(shared_data, tmp_path):
    """Tab (NaN cells), comma, semicolon (;;) and space (runs of spaces = empty fields, not collapsed)."""
    d = shared_data / XSENS
    comma = convert_file(d / "MT2022_ACC_GYRO_ROT_MAT_COMMA_00B42D4B.txt")
    for variant in ("SEMICOLON", "SPACE"):
        other = convert_file(d / f"MT2022_ACC_GYRO_ROT_MAT_{variant}_00B42D4B.txt")
        np.testing.assert_array_equal(other.imus[0].acc, comma.imus[0].acc)
        np.testing.assert_array_equal(other.imus[0].gyr, comma.imus[0].gyr)
        np.testing.assert_array_equal(other.imus[0].t_ns, comma.imus[0].t_ns)
        np.testing.assert_array_equal(other.signals[1].values, comma.signals[1].values)
        assert other.metadata["imulog.device.mt_00b42d4b"]["delimiter"] == variant.lower()
    assert comma.imus[0].acc[0].tolist() == [0.074225, -0.040975, 9.922524]
    # exported without the // lines: still Xsens (serial from the file name), same numbers
    bare = tmp_path / "MT2022_BARE_00B42D4B.txt"
    bare.write_text("\n".join((d / "MT2022_ACC_GYRO_ROT_MAT_SPACE_00B42D4B.txt").read_text().splitlines()[12:]) + "\n")
    assert detect(bare).name == "xsens"
    np.testing.assert_array_equal(convert_file(bare).imus[0].acc, comma.imus[0].acc)
    # the empty SampleTimeFine/Year/... columns carry nothing and are not kept
    assert "SampleTimeFine" not in comma.signals[0].columns and "Year" not in comma.signals[0].columns


def test_nan_cell_is_a_gap_in_the_stream(shared_data, tmp_path):
    from imulog.archive import TrialReader, write_trial

    d = shared_data / XSENS
    nan = convert_file(d / "MT2022_ACC_GYRO_ROT_ALL_TAB_NAN_00B42D4B.txt")
    comma = convert_file(d / "MT2022_ACC_GYRO_ROT_MAT_COMMA_00B42D4B.txt")
    acc = nan.imus[0].acc
    assert math.isnan(acc[0, 0]) and np.isfinite(acc[0, 1:]).all()  # the one NaN cell of the file
    np.testing.assert_array_equal(acc[1:], comma.imus[0].acc[1:])
    assert nan.metadata["imulog.device.mt_00b42d4b"]["samples_with_gaps"] == 1
    write_trial(tmp_path / "nan.mcap", nan)
    with TrialReader(tmp_path / "nan.mcap") as trial:  # the gap survives the archive as NaN, not 0
        stored = trial.read("/imu/mt_00b42d4b").acc
    assert math.isnan(stored[0, 0]) and np.array_equal(stored[1:], acc[1:])


def test_quaternion_rotation_matrix_and_euler_agree(shared_data):
    """The ALL file has Quat_q0..3 (q0 = w), Roll/Pitch/Yaw and Mat[r][c] listed column-major: read by name, the
    matrix and the angles give the quaternion's rotation to within the 6 printed decimals."""
    from imulog.converters.xsens import orientation_wxyz

    rec = convert_file(shared_data / XSENS / "MT2022_ACC_GYRO_ROT_ALL_TAB_NAN_00B42D4B.txt")
    sig, orient = rec.signals
    assert orient.topic == "/orientation/mt_00b42d4b"
    seen = {c: i for i, c in enumerate(sig.columns)}
    q_quat = orient.values
    np.testing.assert_array_equal(q_quat[:, 0], sig.values[:, seen["Quat_q0"]])
    q_mat, _ = orientation_wxyz(sig.values, {c: i for c, i in seen.items() if c.startswith("Mat")})
    q_eul, _ = orientation_wxyz(sig.values, {c: seen[c] for c in ("Roll", "Pitch", "Yaw")})
    assert np.degrees(Q.angle_between(q_quat, q_mat)).max() < 0.01
    assert np.degrees(Q.angle_between(q_quat, q_eul)).max() < 0.01
    # the transposed reading (row-major) would be a different rotation
    r = sig.values[:, [seen[f"Mat[{i}][{j}]"] for i in (1, 2, 3) for j in (1, 2, 3)]].reshape(-1, 3, 3)
    q_transposed = Q.from_rotation_matrix(np.swapaxes(r, 1, 2))
    assert np.degrees(Q.angle_between(q_quat, q_transposed)).min() > 10


def test_old_header_zero_padded_counter_and_mag_as_signal(shared_data):
    path = shared_data / XSENS / "MT_012005D6_031-000_00B421AF.txt"
    rec = convert_file(path)
    (imu,) = rec.imus
    assert imu.name == "mt_00b421af" and len(imu) == 3369
    assert imu.t_ns[0] == 3583 * 10_000_000 and imu.t_ns[-1] == 6951 * 10_000_000  # "03583" -> 35.83 s
    assert imu.mag is None  # arbitrary units: /signals, never uT
    sig = rec.signals[0]
    np.testing.assert_array_equal(sig.values[:, sig.columns.index("Mag_Z")], column(path, "Mag_Z"))
    meta = rec.metadata["imulog.device.mt_00b421af"]
    assert meta["rate_hz"] == 100.0 and "assumed" not in meta and meta["firmware_version"] == "4.0.2"
    assert meta["master"] == "012005D6" and not rec.warnings


def test_missing_rate_is_assumed_out_loud_and_rate_option_wins(shared_data):
    path = shared_data / XSENS / "MT_01200454_000-000_00B40DE4.txt"  # no Update Rate, no SampleTimeFine
    meta = convert_file(path).metadata["imulog.device.mt_00b40de4"]
    assert "assumed 100 Hz" in meta["assumed"][0]
    assert convert_file(path).warnings == meta["assumed"]  # printed by imulog convert, kept in imulog.conversion
    rec = convert_file(path, options=ConvertOptions(rate_hz=60.0))
    assert "assumed" not in rec.metadata["imulog.device.mt_00b40de4"]
    assert np.diff(rec.imus[0].t_ns).tolist() == [16_666_667, 16_666_666, 16_666_667]


UTC_HEADER = "// Update Rate: 100.0Hz\n// DeviceId: 00B4AAAA\n"
UTC_COLS = [
    "PacketCounter",
    "UTC_Nano",
    "UTC_Year",
    "UTC_Month",
    "UTC_Day",
    "UTC_Hour",
    "UTC_Minute",
    "UTC_Second",
    "UTC_Valid",
    "Acc_X",
    "Acc_Y",
    "Acc_Z",
]


def _utc_file(path: Path, rows: list[list[str]]) -> Path:
    path.write_text(UTC_HEADER + "\t".join(UTC_COLS) + "\n" + "\n".join("\t".join(r) for r in rows) + "\n")
    return path


def test_utc_columns_give_the_trial_start_time(tmp_path):
    rows = [
        ["00010", "", "", "", "", "", "", "", "", "0.1", "0.2", "9.8"],  # no UTC fix yet
        ["00011", "250000000", "2023", "7", "14", "9", "30", "5", "7", "0.1", "0.2", "9.8"],
        ["00012", "260000000", "2023", "7", "14", "9", "30", "5", "7", "0.1", "0.2", "9.8"],
    ]
    rec = convert_file(_utc_file(tmp_path / "MT_utc.txt", rows))
    trial = rec.metadata["imulog.trial"]
    # the first sample is 10 ms before the first valid UTC row (09:30:05.250)
    assert trial["start_time"] == "2023-07-14T09:30:05.240000+00:00" and trial["time_zone"] == "UTC"
    rows[1][8] = rows[2][8] = "3"  # UTC_Valid without the 'UTC fully resolved' bit: no start time
    assert "imulog.trial" not in convert_file(_utc_file(tmp_path / "MT_utc2.txt", rows)).metadata


@pytest.mark.parametrize(
    "damage, message",
    [
        (  # a short row inside the data (a cut last row is dropped instead: tests/test_convert_validation.py)
            lambda s: "\n".join(ln[: ln.rindex(",")] if i == 16 else ln for i, ln in enumerate(s.split("\n"))),
            r"line 17: truncated line: 20 fields, expected 21",
        ),
        (lambda s: s.replace("0.045482", "0.04x5482"), r"line 17, column 'Acc_X': '0.04x5482' is not a number"),
        (lambda s: s.replace("51403,", ",", 1), r"line 17, column 'PacketCounter': missing value"),
        (lambda s: s.replace("51403,", "51401,", 1), r"line 17, column 'PacketCounter': PacketCounter"),
    ],
)
def test_damaged_export_is_one_line_naming_the_line_and_leaves_no_output(shared_data, tmp_path, damage, message):
    src = (shared_data / XSENS / "MT2022_ACC_GYRO_ROT_MAT_COMMA_00B42D4B.txt").read_text()
    bad = tmp_path / "MT2022_BAD_00B42D4B.txt"
    bad.write_text(damage(src))
    with pytest.raises(ConversionError, match=message):
        convert_file(bad)
    out = tmp_path / "bad.mcap"
    result = CliRunner().invoke(cli, ["convert", str(bad), "-o", str(out)])
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob("*.mcap*"))


def test_device_orientation_agrees_with_our_filter_on_the_real_trial(shared_data):
    """The matrix read as Mat[r][c] = R[r][c] (sensor to global) must tilt like the IMU: VQF on the raw acc/gyr of
    the real two-sensor trial gives the same inclination as the device's own estimate (transposed, it would not)."""
    from imulog.process.orientation import estimate_orientation

    for serial in ("00B421AF", "00B4227B"):
        rec = convert_file(shared_data / XSENS / f"MT_012005D6_031-000_{serial}.txt")
        imu, device = rec.imus[0], rec.signals[1].values
        ours = estimate_orientation(imu.gyr, imu.acc, 100.0).quat
        err = np.degrees(Q.inclination_error(ours, device))
        assert np.median(err) < 2.0, serial  # measured 0.11 and 0.87 deg
        transposed = Q.conjugate(device)  # R^T: the other reading of the matrix
        assert np.median(np.degrees(Q.inclination_error(ours, transposed))) > 10, serial
