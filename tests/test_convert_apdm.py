"""APDM Opal: the two real CSV layouts of ../shared/data/devices/apdm_csv (OpenSim test data, Apache-2.0) against
the numbers in the files, and an HDF5 file written here in APDM's layout (/Sensors/<case ID>/..., /Processed)."""

from __future__ import annotations

import csv
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, convert_file, detect

from imulog.archive import TrialReader, check_file
from imulog.cli import cli

APDM = "devices/apdm_csv"


def rows(path: Path) -> list[list[str]]:
    with open(path, newline="") as f:
        return list(csv.reader(f))


def test_labelled_csv_matches_the_file(shared_data):
    path = shared_data / APDM / "imuData01.csv"
    assert detect(path).name == "apdm"
    rec = convert_file(path)
    assert [i.name for i in rec.imus] == ["static", "upper", "middle", "lower"]
    table = rows(path)
    names, units, data = table[2], table[3], table[4:]
    assert len(data) == 1024
    for imu in rec.imus:
        label = imu.name.capitalize()
        for quantity, attr in (("Acceleration", "acc"), ("Angular Velocity", "gyr"), ("Magnetic Field", "mag")):
            cols = [names.index(f"{label}/{quantity}/{a}") for a in "XYZ"]
            expected = np.array([[float(r[c]) for c in cols] for r in data])
            np.testing.assert_array_equal(getattr(imu, attr), expected)  # SI units in the file: m/s^2, rad/s, uT
        assert units[names.index(f"{label}/Temperature/Scalar")] == "deg C"
        temp = np.array([float(r[names.index(f"{label}/Temperature/Scalar")]) for r in data])
        np.testing.assert_array_equal(imu.temperature, temp)
        (orient,) = [s for s in rec.signals if s.topic == f"/orientation/{imu.name}"]
        cols = [names.index(f"{label}/Orientation/{a}") for a in ("Scalar", "X", "Y", "Z")]
        np.testing.assert_array_equal(orient.values, np.array([[float(r[c]) for c in cols] for r in data]))
        (sig,) = [s for s in rec.signals if s.topic == f"/signals/{imu.name}"]
        assert sig.columns == ["pressure"] and sig.units == ["kPa"]
    t = np.array([float(r[0]) for r in data])
    np.testing.assert_array_equal(rec.imus[0].t_ns, np.round(t * 1e9).astype(np.int64))  # s from the start
    meta = rec.metadata["imulog.device.static"]
    assert meta["rate_hz"] == 128.0 and meta["test_name"] == "Pendulum Test 01" and meta["label"] == "Static"
    assert "imulog.trial" not in rec.metadata  # the file records no absolute time


def test_format7_case_ids_epoch_time_and_barometer_bit_pattern(shared_data):
    path = shared_data / APDM / "apdm_format7.csv"
    assert detect(path).name == "apdm"
    rec = convert_file(path)
    table = rows(path)
    labels = [(table[0][j], table[0][j + 3]) for j in range(1, len(table[0]), 14)]
    assert labels[0] == ("5718", "Lumbar") and len(labels) == 6
    for k, (case_id, label) in enumerate(labels):
        imu = rec.imus[k]
        assert imu.name == label.lower().replace(" ", "_")
        assert rec.metadata[f"imulog.device.{imu.name}"]["serial"] == case_id
        base = 1 + 14 * k
        acc = np.array([[float(r[base + i]) for i in range(3)] for r in table[3:]])
        gyr = np.array([[float(r[base + 3 + i]) for i in range(3)] for r in table[3:]])
        np.testing.assert_array_equal(imu.acc, acc)
        np.testing.assert_array_equal(imu.gyr, gyr)
        baro = [s for s in rec.signals if s.topic == f"/signals/{imu.name}"][0].values[:, 0]
        bits = np.array([int(r[base + 9].split(".")[0]) for r in table[3:]], dtype=np.int64).view(np.float64)
        np.testing.assert_array_equal(baro, bits)
        assert baro.min() > 95 and baro.max() < 105  # kPa once reinterpreted
    assert rec.signals[0].values[0, 0] == pytest.approx(101.71941376)
    us = [int(r[0]) for r in table[3:]]
    np.testing.assert_array_equal(rec.imus[0].t_ns, np.array(us) * 1000)  # us since 1970 kept as the clock
    trial = rec.metadata["imulog.trial"]
    assert trial["time_zone"] == "UTC"
    assert datetime.fromisoformat(trial["start_time"]) == datetime(2019, 2, 22, 23, 51, 44, 438281, tzinfo=UTC)


def write_apdm_h5(path: Path, n: int = 256, rate: float = 128.0, tz_hours: float = -8.0) -> dict:
    """An APDM HDF5 file in the layout skdh's ReadApdmH5 and APDM's docs read (v5: /Sensors, /Processed)."""
    import h5py

    rng = np.random.default_rng(3)
    t0_us = 1_600_000_000_000_000  # 2020-09-13T12:26:40Z
    truth = {}
    with h5py.File(path, "w") as f:
        f.attrs["FileFormatVersion"] = 5
        for case_id, label in (("XI-010203", "Right Wrist"), ("XI-040506", "Sternum")):
            g = f.create_group(f"Sensors/{case_id}")
            cfg = g.create_group("Configuration")
            cfg.attrs["Label 0"] = label.encode()
            cfg.attrs["Sample Rate"] = np.uint16(rate)
            cfg.attrs["Timezone Offset"] = tz_hours
            time = t0_us + np.round(np.arange(n) * 1e6 / rate).astype(np.uint64)
            acc = rng.normal(0, 1, (n, 3)) + [0, 0, 9.81]
            gyr = rng.normal(0, 0.3, (n, 3))
            mag = rng.normal(20, 5, (n, 3))
            q = rng.normal(0, 1, (n, 4))
            q /= np.linalg.norm(q, axis=1, keepdims=True)
            g["Time"] = time
            g["Accelerometer"] = acc
            g["Gyroscope"] = gyr
            g["Magnetometer"] = mag
            g["Temperature"] = np.full(n, 31.5)
            g["Barometer"] = np.full(n, 101.3)
            f.create_group(f"Processed/{case_id}")["Orientation"] = q
            truth[case_id] = {"time": time, "acc": acc, "gyr": gyr, "mag": mag, "q": q}
    return truth


def test_hdf5_export(tmp_path):
    path = tmp_path / "walk_20200913.h5"
    truth = write_apdm_h5(path)
    assert detect(path).name == "apdm"  # not the BROAD HDF5 converter
    rec = convert_file(path)
    by_name = {i.name: i for i in rec.imus}
    assert set(by_name) == {"right_wrist", "sternum"}
    imu = by_name["right_wrist"]
    t = truth["XI-010203"]
    np.testing.assert_array_equal(imu.t_ns, t["time"].astype(np.int64) * 1000)
    np.testing.assert_array_equal(imu.acc, t["acc"])
    np.testing.assert_array_equal(imu.gyr, t["gyr"])
    np.testing.assert_array_equal(imu.mag, t["mag"])
    (orient,) = [s for s in rec.signals if s.topic == "/orientation/right_wrist"]
    np.testing.assert_array_equal(orient.values, t["q"])
    meta = rec.metadata["imulog.device.right_wrist"]
    assert (meta["serial"], meta["label"], meta["rate_hz"]) == ("XI-010203", "Right Wrist", 128.0)
    trial = rec.metadata["imulog.trial"]
    assert trial["start_time"] == "2020-09-13T04:26:40-08:00" and trial["time_zone"] == "-08:00"
    out = tmp_path / "apdm.mcap"
    result = CliRunner().invoke(cli, ["convert", str(path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert check_file(out).ok
    with TrialReader(out) as trial:
        np.testing.assert_array_equal(trial.read("/imu/sternum").acc, truth["XI-040506"]["acc"])


def test_hdf5_damage_is_named(tmp_path):
    import h5py

    path = tmp_path / "cut.h5"
    write_apdm_h5(path)
    with h5py.File(path, "a") as f:
        del f["Sensors/XI-040506/Gyroscope"]
        f["Sensors/XI-040506/Gyroscope"] = np.zeros((10, 3))
    with pytest.raises(ConversionError, match=r"/Sensors/XI-040506/Gyroscope has shape \(10, 3\), Time has 256"):
        convert_file(path)
    data = (tmp_path / "cut.h5").read_bytes()
    (tmp_path / "trunc.h5").write_bytes(data[: len(data) // 2])
    out = tmp_path / "trunc.mcap"
    result = CliRunner().invoke(cli, ["convert", str(tmp_path / "trunc.h5"), "-o", str(out), "--format", "apdm"])
    assert result.exit_code == 1 and "trunc.h5" in result.output and not out.exists()
    assert len(result.output.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "name, damage, message",
    [
        # a short row above the last is an error; a cut last row is dropped with a warning (test_convert_validation)
        ("imuData01.csv", lambda s: s.replace(s.splitlines()[-2], s.splitlines()[-2][:-30]), r"line 1027: truncated"),
        ("imuData01.csv", lambda s: s.replace("9.804986382", "9.80x", 1), r"line 5, column 'Static/Acceleration/Z'"),
        (
            "imuData01.csv",
            lambda s: s.replace("Static/Angular Velocity/Z", "Static/Angular Velocity/Q"),
            r"lacks an axis",
        ),
        ("apdm_format7.csv", lambda s: s.replace("1550879504446093", "1550879504438281"), r"line 5.*duplicated time"),
        ("apdm_format7.csv", lambda s: "\n".join(s.splitlines()[:2]), r"line 2: file ends inside the 3 header rows"),
    ],
)
def test_damaged_csv_is_one_line(shared_data, tmp_path, name, damage, message):
    bad = tmp_path / name
    bad.write_text(damage((shared_data / APDM / name).read_text()))
    with pytest.raises(ConversionError, match=message):
        convert_file(bad)


def test_orientation_is_scalar_first_sensor_to_global(shared_data):
    """APDM's Orientation columns (Scalar,X,Y,Z) tilt like VQF on the same acc/gyr (pendulum trial: measured 0.03,
    0.3, 0.4 and 2.4 deg median), and in Format=7 they rotate the measured gravity onto the vertical."""
    from imulog.process import quaternion as Q
    from imulog.process.orientation import estimate_orientation

    rec = convert_file(shared_data / APDM / "imuData01.csv")
    for imu in rec.imus:
        device = next(s for s in rec.signals if s.topic == f"/orientation/{imu.name}").values
        ours = estimate_orientation(imu.gyr, imu.acc, 128.0).quat
        assert np.median(np.degrees(Q.inclination_error(ours, device))) < 5.0, imu.name
        if imu.name != "static":  # a moving sensor: the inverse rotation would tilt differently
            assert np.median(np.degrees(Q.inclination_error(ours, Q.conjugate(device)))) > 30.0, imu.name
    rec = convert_file(shared_data / APDM / "apdm_format7.csv")
    for imu in rec.imus:
        device = next(s for s in rec.signals if s.topic == f"/orientation/{imu.name}").values
        up = Q.rotate(device, imu.acc)
        assert np.all(up[:, 2] / np.linalg.norm(up, axis=1) > 0.85), imu.name  # walking: measured >= 0.89


def test_hdf5_format_3_layout(tmp_path):
    """The older layout (Motion Studio / Mobility Lab 1): CaseIdList/MonitorLabelList root attributes and
    /<case ID>/Calibrated/... data sets, as the MATLAB and Python readers of those files address them."""
    import h5py

    rng = np.random.default_rng(9)
    n = 100
    time = 1_390_000_000_000_000 + np.arange(n, dtype=np.uint64) * 7812  # 128 Hz, us since 1970
    acc, gyr, q = rng.normal(0, 1, (n, 3)), rng.normal(0, 1, (n, 3)), rng.normal(0, 1, (n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)  # orientations are unit quaternions (others are refused)
    path = tmp_path / "20140126-134055-Base.h5"
    with h5py.File(path, "w") as f:
        f.attrs["FileFormatVersion"] = 3
        f.attrs["CaseIdList"] = np.array([b"SI-001007"])
        f.attrs["MonitorLabelList"] = np.array([b"Left Wrist"])
        g = f.create_group("SI-001007")
        g.attrs["SampleRate"] = np.uint16(128)
        g["Time"] = time
        g["Calibrated/Accelerometers"] = acc
        g["Calibrated/Gyroscopes"] = gyr
        g["Calibrated/Orientation"] = q
    assert detect(path).name == "apdm"
    rec = convert_file(path)
    (imu,) = rec.imus
    assert imu.name == "left_wrist" and imu.mag is None
    np.testing.assert_array_equal(imu.acc, acc)
    np.testing.assert_array_equal(imu.gyr, gyr)
    np.testing.assert_array_equal(imu.t_ns, time.astype(np.int64) * 1000)
    np.testing.assert_array_equal(rec.signals[0].values, q)
    meta = rec.metadata["imulog.device.left_wrist"]
    assert meta["serial"] == "SI-001007" and meta["rate_hz"] == 128.0 and "format 3-4" in meta["format"]
    assert rec.metadata["imulog.trial"]["start_time"] == "2014-01-17T23:06:40+00:00"
