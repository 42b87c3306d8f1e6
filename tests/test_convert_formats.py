"""Converters against real recordings (../shared/data) and files written in the documented layouts.

Expected values are computed independently here (pandas/h5py/ezc3d on the source file, unit factors written
out), never copied from the converters' output.
"""

from __future__ import annotations

import json
import math
from importlib.metadata import entry_points
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from imulog.converters import ConversionError, ConvertOptions, available, convert_file, convert_files, detect
from imulog.converters.registry import ENTRY_POINT_GROUP, group_directory

G = 9.80665
DEG = math.pi / 180.0
BUILTIN = {"delimited", "xsens", "adc", "vicon-csv", "c3d", "broad-hdf5", "gaitmap"}


# --------------------------------------------------------------------------------- registry / sniffing
def test_builtin_converters_are_registered_as_entry_points():
    names = {ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)}
    assert names >= BUILTIN
    assert set(available()) >= BUILTIN


@pytest.mark.parametrize(
    "rel, fmt",
    [
        ("imu_text/fusion_sensor_data.csv", "delimited"),
        ("imu_text/shimmer_consensys_export.csv", "delimited"),
        ("vicon_nexus/markers.csv", "vicon-csv"),
        ("vicon_nexus/analogs.csv", "vicon-csv"),
        ("vicon_nexus/markers_analogs.c3d", "c3d"),
        ("c3d/ktk_sample_propulsion_upperlimb.c3d", "c3d"),
        ("broad/02_undisturbed_slow_rotation_B.hdf5", "broad-hdf5"),
        ("gaitmap_foot/imu_sample.csv", "gaitmap"),
        ("gaitmap_foot/mocap_sample.csv", "gaitmap"),
        ("gaitmap_foot/stride_borders_sample.csv", "gaitmap"),
    ],
)
def test_sniff_detects_each_real_file(shared_data, rel, fmt):
    assert detect(shared_data / rel).name == fmt


@pytest.mark.parametrize("rel", ["README.md", "broad/trials.json", "broad/LICENSE", "imu_text/LICENSE_Fusion.md"])
def test_non_recordings_are_not_claimed(shared_data, rel):
    with pytest.raises(ConversionError, match="unknown format"):
        detect(shared_data / rel)


def test_every_recording_in_shared_data_converts(shared_data):
    # devices/ (issue 14's device exports) has its own tests: tests/test_convert_{xsens,apdm,...}.py
    groups = [(n, fs) for n, fs in group_directory(shared_data) if not n.startswith("devices/")]
    converted = {name: convert_files(files) for name, files in groups}
    # every data file of the README is in exactly one trial
    files = sorted(p.name for _, fs in groups for p in fs)
    assert files == sorted(
        [
            "02_undisturbed_slow_rotation_B.hdf5",
            "05_undisturbed_slow_rotation_with_breaks_B.hdf5",
            "14_undisturbed_slow_translation_with_breaks_B.hdf5",
            "ktk_sample_propulsion_upperlimb.c3d",
            "imu_sample.csv",
            "mocap_sample.csv",
            "stride_borders_sample.csv",
            "fusion_sensor_data.csv",
            "shimmer_consensys_export.csv",
            "analogs.csv",
            "markers.csv",
            "markers_analogs.c3d",
        ]
    )
    # markers.csv + analogs.csv are one trial; the C3D of the same trial is another
    nexus = converted["vicon_nexus/vicon_nexus"]
    assert {s.topic for s in nexus.streams()} == {"/markers/vicon", "/analog/vicon"}
    gait = converted["gaitmap_foot/sample"]
    assert {s.topic for s in gait.streams()} == {
        "/imu/left_sensor",
        "/imu/right_sensor",
        "/markers/mocap",
        "/events/strides",
    }
    for rec in converted.values():
        assert rec.sources and all(Path(s).is_file() for s in rec.sources)
        for stream in rec.streams():
            if hasattr(stream, "t_ns"):
                assert np.all(np.diff(stream.t_ns) > 0), stream


# ------------------------------------------------------------------------------------ delimited text
def test_fusion_csv_values_equal_the_text_after_unit_conversion(shared_data):
    path = shared_data / "imu_text/fusion_sensor_data.csv"
    rec = convert_file(path)
    df = pd.read_csv(path)
    (imu,) = rec.imus
    assert len(imu) == len(df) == 13514
    np.testing.assert_array_equal(imu.t_ns, np.round(df["Time (s)"].to_numpy() * 1e9).astype(np.int64))
    acc = df[[f"Accelerometer {a} (g)" for a in "XYZ"]].to_numpy() * G
    gyr = df[[f"Gyroscope {a} (deg/s)" for a in "XYZ"]].to_numpy() * DEG
    mag = df[[f"Magnetometer {a} (uT)" for a in "XYZ"]].to_numpy()
    np.testing.assert_allclose(imu.acc, acc, rtol=1e-15, atol=0)
    np.testing.assert_allclose(imu.gyr, gyr, rtol=1e-15, atol=0)
    np.testing.assert_allclose(imu.mag, mag, rtol=1e-15, atol=0)
    meta = rec.metadata["imulog.device.imu"]
    assert meta["units"] == {"acc": "g", "gyr": "deg/s", "mag": "uT"}
    assert 99 < meta["rate_hz"] < 100.5
    assert rec.sources == [str(path)]


def test_shimmer_export_reads_sep_line_units_row_and_host_clock(shared_data):
    path = shared_data / "imu_text/shimmer_consensys_export.csv"
    rec = convert_file(path)
    df = pd.read_csv(path, sep=";", skiprows=[0, 2])
    units = pd.read_csv(path, sep=";", skiprows=[0], nrows=1).iloc[0]
    pre = "Shimmer_40AC_"
    assert units[pre + "Accel_LN_X_CAL"] == "m/(s^2)" and units[pre + "Gyro_X_CAL"] == "deg/s"
    (imu,) = rec.imus
    assert imu.name == "shimmer_40ac" and len(imu) == len(df) == 90
    np.testing.assert_allclose(imu.acc, df[[pre + f"Accel_LN_{a}_CAL" for a in "XYZ"]].to_numpy(), rtol=1e-15)
    np.testing.assert_allclose(imu.gyr, df[[pre + f"Gyro_{a}_CAL" for a in "XYZ"]].to_numpy() * DEG, rtol=1e-15)
    np.testing.assert_allclose(imu.temperature, df[pre + "Temperature_BMP280_CAL"].to_numpy(), rtol=1e-15)
    assert imu.mag is None  # 'local_flux' is a normalised field, not uT: kept as a signal, as found
    (sig,) = rec.signals
    k = sig.columns.index(pre + "Mag_X_CAL")
    assert sig.units[k] == "local_flux"
    np.testing.assert_array_equal(sig.values[:, k], df[pre + "Mag_X_CAL"].to_numpy())
    # host Unix stamps repeat (1 ms resolution): a uniform clock is fitted, within the host jitter of the stamps
    host_ns = df[pre + "Timestamp_Unix_CAL"].to_numpy() * 1e6
    assert np.any(np.diff(host_ns) == 0)
    assert np.all(np.diff(imu.t_ns) > 0)
    assert np.abs(imu.t_ns - host_ns).max() < 40e6
    rate = rec.metadata["imulog.device.shimmer_40ac"]["rate_hz"]
    assert 50.5 < rate < 52.0  # Shimmer's 51.2 Hz
    assert rec.metadata["imulog.device.shimmer_40ac"]["serial"] == "40AC"


def _write_bluebuddy(tmp: Path, *, toml: bool = False) -> tuple[Path, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    n = 500
    t_ms = np.round(np.cumsum(rng.uniform(8.5, 8.9, n)), 3)
    vals = np.round(rng.normal(0, 1, (n, 9)), 4)
    csv = tmp / "s01_t01_imu.csv"
    lines = ["timestamp,ax,ay,az,gx,gy,gz,mx,my,mz"] + [
        f"{t_ms[i]:.3f}," + ",".join(f"{v:.4f}" for v in vals[i]) for i in range(n)
    ]
    csv.write_text("\n".join(lines) + "\n")
    doc = {
        "format": "imulog.mapping/1",
        "device": {
            "name": "wrist",
            "model": "BlueBuddy",
            "serial": "BB-7",
            "rate_hz": 115.0,
            "acc_range_g": 16,
            "gyr_range_dps": 2000,
        },
        "delimiter": ",",
        "time": {"column": "timestamp", "unit": "ms"},
        "columns": {
            **{f"a{a}": {"quantity": "acc", "axis": a, "unit": "g"} for a in "xyz"},
            **{f"g{a}": {"quantity": "gyr", "axis": a, "unit": "dps"} for a in "xyz"},
            **{f"m{a}": {"quantity": "mag", "axis": a, "unit": "gauss"} for a in "xyz"},
        },
    }
    if toml:
        body = [
            'format = "imulog.mapping/1"',
            'delimiter = ","',
            "[device]",
            'name = "wrist"\nmodel = "BlueBuddy"\nserial = "BB-7"\nrate_hz = 115.0\nacc_range_g = 16\ngyr_range_dps = 2000',
            "[time]",
            'column = "timestamp"\nunit = "ms"',
        ]
        for col, spec in doc["columns"].items():
            body.append(
                f'[columns.{col}]\nquantity = "{spec["quantity"]}"\naxis = "{spec["axis"]}"\nunit = "{spec["unit"]}"'
            )
        (tmp / "s01_t01_imu.mapping.toml").write_text("\n".join(body) + "\n")
    else:
        (tmp / "s01_t01_imu.mapping.json").write_text(json.dumps(doc))
    return csv, t_ms, vals


@pytest.mark.parametrize("toml", [False, True])
def test_mapping_file_beside_the_csv_gives_units_and_device(tmp_path, toml):
    csv, t_ms, vals = _write_bluebuddy(tmp_path, toml=toml)
    rec = convert_file(csv)
    (imu,) = rec.imus
    assert imu.name == "wrist"
    np.testing.assert_array_equal(imu.t_ns, np.round(t_ms * 1e6).astype(np.int64))
    np.testing.assert_allclose(imu.acc, vals[:, 0:3] * G, rtol=1e-15)
    np.testing.assert_allclose(imu.gyr, vals[:, 3:6] * DEG, rtol=1e-15)
    np.testing.assert_allclose(imu.mag, vals[:, 6:9] * 100.0, rtol=1e-15)  # 1 gauss = 100 uT
    meta = rec.metadata["imulog.device.wrist"]
    assert (meta["model"], meta["serial"], meta["rate_hz"], meta["acc_range_g"], meta["gyr_range_dps"]) == (
        "BlueBuddy",
        "BB-7",
        115.0,
        16,
        2000,
    )
    assert len(rec.sources) == 2 and rec.sources[1].endswith((".mapping.json", ".mapping.toml"))


def test_mapping_option_overrides_and_names_missing_columns(tmp_path):
    csv, _, _ = _write_bluebuddy(tmp_path)
    other = tmp_path / "other.json"
    doc = json.loads((tmp_path / "s01_t01_imu.mapping.json").read_text())
    doc["columns"]["qx"] = {"quantity": "acc", "axis": "x", "unit": "g"}
    other.write_text(json.dumps(doc))
    with pytest.raises(ConversionError, match=r"other\.json names column 'qx'"):
        convert_file(csv, options=ConvertOptions(mapping=other))


def test_gaitmap_two_row_header_gives_one_imu_per_sensor(shared_data):
    path = shared_data / "gaitmap_foot/imu_sample.csv"
    rec = convert_file(path)
    df = pd.read_csv(path, header=[0, 1], index_col=0)
    assert [i.name for i in rec.imus] == ["left_sensor", "right_sensor"]
    for imu in rec.imus:
        acc = df[imu.name][["acc_x", "acc_y", "acc_z"]].to_numpy()
        gyr = df[imu.name][["gyr_x", "gyr_y", "gyr_z"]].to_numpy() * DEG
        np.testing.assert_allclose(imu.acc, acc, rtol=1e-15)
        np.testing.assert_allclose(imu.gyr, gyr, rtol=1e-15)
        np.testing.assert_array_equal(imu.t_ns, np.round(df.index.to_numpy() / 204.8 * 1e9).astype(np.int64))
        assert abs((imu.t_ns[-1] - imu.t_ns[0]) / 1e9 - 38.7) < 0.05
        assert rec.metadata[f"imulog.device.{imu.name}"]["rate_hz"] == 204.8


def test_gaitmap_mocap_and_strides(shared_data):
    path = shared_data / "gaitmap_foot/mocap_sample.csv"
    rec = convert_file(path)
    df = pd.read_csv(path, header=[0, 1], index_col=0)
    (m,) = rec.markers
    assert m.labels == ["L_TOE", "R_TOE", "L_FCC", "R_FCC", "R_FM5", "L_FM5"]
    for j, label in enumerate(m.labels):
        np.testing.assert_allclose(m.pos[:, j, :], df[label][["x", "y", "z"]].to_numpy() / 1000.0, rtol=1e-15)
    np.testing.assert_array_equal(m.t_ns, np.round(df.index.to_numpy() / 100.0 * 1e9).astype(np.int64))
    strides = convert_file(shared_data / "gaitmap_foot/stride_borders_sample.csv").events[0]
    sdf = pd.read_csv(shared_data / "gaitmap_foot/stride_borders_sample.csv")
    assert len(strides) == len(sdf) == 58
    np.testing.assert_array_equal(strides.start_ns, np.round(sdf["start"].to_numpy() / 204.8 * 1e9).astype(np.int64))
    assert strides.labels == [f"{f}_sensor" for f in sdf["foot"]]


# ------------------------------------------------------------------------------------------ Vicon, C3D
def _nexus_frame(path: Path) -> pd.DataFrame:
    return pd.read_csv(path, skiprows=5, header=None)


def test_vicon_markers_match_the_csv_with_gaps_as_invalid(shared_data):
    path = shared_data / "vicon_nexus/markers.csv"
    rec = convert_file(path)
    (m,) = rec.markers
    df = _nexus_frame(path)
    names = pd.read_csv(path, skiprows=2, nrows=0).columns
    assert m.labels[:2] == ["boite:gauche_ext", "boite:gauche_int"] and m.labels[-1] == names[-3] == "Daphnee:LATH"
    raw = df.iloc[:, 2:].to_numpy().reshape(len(df), -1, 3) / 1000.0
    assert m.pos.shape == (580, 51, 3)
    gaps = np.isnan(raw).any(axis=2)
    assert gaps.any()  # the real export has gaps
    np.testing.assert_array_equal(m.valid, ~gaps)
    np.testing.assert_allclose(m.pos[~gaps], raw[~gaps], rtol=1e-15)
    assert np.isnan(m.pos[gaps]).all()  # gaps are NaN, never zeros
    np.testing.assert_array_equal(m.t_ns, ((df[0].to_numpy() - 1) * 10_000_000).astype(np.int64))


def test_vicon_devices_section_sub_frames(shared_data):
    path = shared_data / "vicon_nexus/analogs.csv"
    (a,) = convert_file(path).analogs
    df = _nexus_frame(path)
    assert a.values.shape == (11600, 38)
    assert set(a.units) == {"V"}
    assert a.channel_names[0] == "Imported Analog EMG - Voltage/1"
    assert a.channel_names[6] == "Imported Delsys Trigno EMG 2.0 - Sensor 1/EMG1"
    np.testing.assert_allclose(a.values, df.iloc[:, 2:].to_numpy(), rtol=1e-15)
    # frame f, sub frame s of 20 at 2000 Hz: (f - 1 + s / 20) / 100 Hz
    expected = np.round((df[0].to_numpy() - 1 + df[1].to_numpy() / 20) / 100 * 1e9).astype(np.int64)
    np.testing.assert_array_equal(a.t_ns, expected)


def test_vicon_csv_and_c3d_of_the_same_trial_agree(shared_data):
    csv = convert_files([shared_data / "vicon_nexus/markers.csv", shared_data / "vicon_nexus/analogs.csv"])
    c3d = convert_file(shared_data / "vicon_nexus/markers_analogs.c3d")
    mc, m3 = csv.markers[0], c3d.markers[0]
    assert mc.labels == m3.labels
    np.testing.assert_array_equal(mc.t_ns, m3.t_ns)
    np.testing.assert_array_equal(mc.valid, m3.valid)
    ok = mc.valid
    diff = np.abs(mc.pos - m3.pos)[ok]
    printed = np.abs(mc.pos[ok]) * 1000.0  # mm as in the CSV
    # the CSV prints 6 significant digits: 3 decimals (5e-7 m rounding) below 1000 mm, 2 decimals above
    assert diff[printed < 1000.0].max() < 1e-6
    assert diff[printed >= 1000.0].max() <= 5e-6 + 1e-9
    ac, a3 = csv.analogs[0], c3d.analogs[0]
    np.testing.assert_array_equal(ac.t_ns, a3.t_ns)
    # the analog channels in the same order: the Voltage.1..6 block. The CSV prints few digits ('-0.0220516',
    # '-3.27E-05'), the C3D holds float32: they agree within half a unit of each cell's last printed digit
    text = (
        pd.read_csv(shared_data / "vicon_nexus/analogs.csv", skiprows=5, header=None, dtype=str).iloc[:, 2:8].to_numpy()
    )
    resolution = np.vectorize(_printed_resolution)(text)
    x, y = ac.values[:, :6], a3.values[:, :6]
    assert np.all(np.abs(x - y) <= 0.5 * resolution + 1e-7 * np.abs(x) + 1e-12)


def _printed_resolution(cell: str) -> float:
    """Value of one unit in the last printed digit: '0.0123' -> 1e-4, '-3.27E-05' -> 1e-7, '0' -> 1."""
    mantissa, _, exponent = cell.upper().partition("E")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (int(exponent or 0) - decimals)


def test_c3d_in_metres_with_a_non_integer_rate(shared_data):
    import ezc3d

    path = shared_data / "c3d/ktk_sample_propulsion_upperlimb.c3d"
    c = ezc3d.c3d(str(path))
    rate = float(c["parameters"]["POINT"]["RATE"]["value"][0])
    assert c["parameters"]["POINT"]["UNITS"]["value"][0] == "m" and rate != round(rate)
    rec = convert_file(path)
    (m,) = rec.markers
    pts = np.transpose(c["data"]["points"][:3], (2, 1, 0))
    assert m.pos.shape == pts.shape == (700, 41, 3)
    ok = np.isfinite(pts).all(axis=2)
    np.testing.assert_array_equal(m.valid, ok)
    np.testing.assert_array_equal(m.pos[ok], pts[ok])  # metres stay metres
    np.testing.assert_array_equal(m.t_ns, np.round(np.arange(700) / rate * 1e9).astype(np.int64))
    assert rec.metadata["imulog.device.vicon"]["rate_hz"] == pytest.approx(69.9926, abs=1e-4)


def test_c3d_events_are_read(tmp_path):
    import ezc3d

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [50.0]
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c["parameters"]["POINT"]["LABELS"]["value"] = ["A"]
    pts = np.ones((4, 1, 20))
    pts[0, 0, :] = np.arange(20) * 10.0
    c["data"]["points"] = pts
    c.add_event(time=[0, 0.2], label="Foot Strike", context="Left")
    c.add_event(time=[0, 0.1], label="Foot Off", context="Right")
    path = tmp_path / "ev.c3d"
    c.write(str(path))
    rec = convert_file(path)
    (ev,) = rec.events
    assert ev.labels == ["Right Foot Off", "Left Foot Strike"]  # sorted by time
    np.testing.assert_allclose(ev.start_ns, [100_000_000, 200_000_000], rtol=2**-23)  # C3D stores float32 seconds
    np.testing.assert_allclose(rec.markers[0].pos[:, 0, 0], np.arange(20) * 0.01, rtol=1e-6)


# -------------------------------------------------------------------------------------------- BROAD
def test_broad_hdf5_matches_h5py(shared_data):
    path = shared_data / "broad/05_undisturbed_slow_rotation_with_breaks_B.hdf5"
    rec = convert_file(path)
    with h5py.File(path) as f:
        rate = float(f.attrs["sampling_rate"])
        acc, gyr, mag = f["imu_acc"][()], f["imu_gyr"][()], f["imu_mag"][()]
        pos, quat, movement = f["opt_pos"][()], f["opt_quat"][()], f["movement"][()]
    (imu,) = rec.imus
    np.testing.assert_array_equal(imu.acc, acc)
    np.testing.assert_array_equal(imu.gyr, gyr)
    np.testing.assert_array_equal(imu.mag, mag)
    np.testing.assert_array_equal(imu.t_ns, np.round(np.arange(len(acc)) / rate * 1e9).astype(np.int64))
    assert rec.metadata["imulog.device.imu"]["rate_hz"] == pytest.approx(285.714, abs=1e-3)
    (pose,) = rec.poses
    np.testing.assert_array_equal(pose.position, pos)
    np.testing.assert_array_equal(pose.orientation, quat)
    (ev,) = rec.events
    # movement runs: rebuild the mask from the intervals
    rebuilt = np.zeros(len(acc), bool)
    for s, e in zip(ev.start_ns, ev.end_ns, strict=True):
        rebuilt[np.searchsorted(imu.t_ns, s) : np.searchsorted(imu.t_ns, e) + 1] = True
    np.testing.assert_array_equal(rebuilt, movement)
    assert len(ev) == 4  # "with breaks"


# ------------------------------------------------------------------------------------------ Xsens
XSENS_HEADER = [
    "// General information:",
    "//  MT Manager version: 2022.0.0",
    "// Device information:",
    "//  DeviceId: {serial}",
    "//  ProductCode: MTW2-3A7G6",
    "//  Firmware Version: 4.6.0",
    "// Device settings:",
    "//  Filter Profile: human (46.1)",
    "// Update Rate: 100.0Hz",
]
XSENS_COLUMNS = [
    "PacketCounter",
    "SampleTimeFine",
    "Acc_X",
    "Acc_Y",
    "Acc_Z",
    "Gyr_X",
    "Gyr_Y",
    "Gyr_Z",
    "Mag_X",
    "Mag_Y",
    "Mag_Z",
    "Quat_q0",
    "Quat_q1",
    "Quat_q2",
    "Quat_q3",
]


def write_xsens(
    path: Path, serial: str, counters: np.ndarray, stf: np.ndarray | None, data: np.ndarray, sep: str = "\t"
) -> Path:
    """An MT Manager export in the documented layout; ``stf`` None leaves SampleTimeFine empty."""
    lines = [h.format(serial=serial) for h in XSENS_HEADER] + [sep.join(XSENS_COLUMNS)]
    for i, c in enumerate(counters):
        t = "" if stf is None else str(int(stf[i]))
        lines.append(sep.join([f"{int(c):05d}", t, *(f"{v:.6f}" for v in data[i])]))
    path.write_text("\n".join(lines) + "\n")
    return path


def _xsens_data(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.normal(0, 1, (n, 13))
    d[:, 9:13] = d[:, 9:13] / np.linalg.norm(d[:, 9:13], axis=1, keepdims=True)
    return np.round(d, 6)


def test_xsens_packet_counter_wraps_and_empty_sample_time_fine(tmp_path):
    n = 300
    counters = (65400 + np.arange(n)) % 65536  # wraps from 65535 to 0 after 136 samples
    counters = np.delete(counters, [200, 201])  # two lost packets
    data = _xsens_data(len(counters), 1)
    path = write_xsens(tmp_path / "MT_00B41234_000-000.txt", "00B41234", counters, None, data)
    rec = convert_file(path)
    assert detect(path).name == "xsens"
    (imu,) = rec.imus
    assert imu.name == "mt_00b41234"
    unwrapped = np.concatenate([np.arange(65400, 65536), np.arange(65536, 65536 + n - 136)])
    unwrapped = np.delete(unwrapped, [200, 201])
    np.testing.assert_array_equal(imu.t_ns, np.round(unwrapped / 100.0 * 1e9).astype(np.int64))
    np.testing.assert_allclose(imu.acc, data[:, 0:3], rtol=1e-15)  # m/s^2 already
    np.testing.assert_allclose(imu.gyr, data[:, 3:6], rtol=1e-15)  # rad/s already
    assert imu.mag is None  # arbitrary units, kept as a signal
    sig, orient = rec.signals  # columns as found, and the device's quaternion as /orientation/<name>
    assert sig.columns[:3] == ["Mag_X", "Mag_Y", "Mag_Z"] and sig.units[0] == "a.u."
    assert orient.topic == "/orientation/mt_00b41234" and orient.columns == ["qw", "qx", "qy", "qz"]
    np.testing.assert_allclose(orient.values, data[:, 9:13], rtol=1e-15)
    np.testing.assert_allclose(sig.values[:, 3:7], data[:, 9:13], rtol=1e-15)
    meta = rec.metadata["imulog.device.mt_00b41234"]
    assert (meta["serial"], meta["rate_hz"], meta["model"]) == ("00B41234", 100.0, "MTW2-3A7G6")
    assert meta["filter_profile"] == "human (46.1)"


def test_xsens_sample_time_fine_and_several_sensors_by_serial(tmp_path):
    n = 50
    stf_a = (2**32 - 1000 + np.arange(n) * 100) % 2**32  # 10 kHz ticks, wraps at 2^32
    files = [
        write_xsens(tmp_path / "MT_00B41234.txt", "00B41234", np.arange(n), stf_a, _xsens_data(n, 2)),
        write_xsens(
            tmp_path / "MT_00B45678.txt", "00B45678", np.arange(n), np.arange(n) * 100 + 7, _xsens_data(n, 3), sep=","
        ),
    ]
    rec = convert_files(files, options=ConvertOptions(extra={"names": {"00B45678": "wrist"}}))
    assert [i.name for i in rec.imus] == ["mt_00b41234", "wrist"]
    ticks = (2**32 - 1000) + np.arange(n) * 100
    np.testing.assert_array_equal(rec.imus[0].t_ns, ticks * 100_000)
    assert set(rec.metadata) >= {"imulog.device.mt_00b41234", "imulog.device.wrist"}
    assert rec.metadata["imulog.device.wrist"]["serial"] == "00B45678"


# -------------------------------------------------------------------------------------------- ADC
def test_adc_counts_to_m_s2(tmp_path):
    rng = np.random.default_rng(5)
    counts = rng.integers(0, 1024, (400, 3))
    path = tmp_path / "witilt.txt"
    seps = ["\t", " "]
    path.write_text("".join(f"X={x}{seps[i % 2]}Y={y}\tZ={z}\n" for i, (x, y, z) in enumerate(counts)))
    assert detect(path).name == "adc"
    with pytest.raises(ConversionError, match="--rate"):
        convert_file(path)
    rec = convert_file(path, options=ConvertOptions(rate_hz=50.0))
    (imu,) = rec.imus
    np.testing.assert_allclose(imu.acc, (counts - 512) / 256 * G, rtol=1e-15)
    np.testing.assert_array_equal(imu.t_ns, np.arange(400) * 20_000_000)
    assert imu.gyr is None
    rec2 = convert_file(
        path, options=ConvertOptions(rate_hz=50.0, extra={"zero_counts": [510, 500, 520], "counts_per_g": 128})
    )
    np.testing.assert_allclose(rec2.imus[0].acc, (counts - [510, 500, 520]) / 128 * G, rtol=1e-15)
    meta = rec.metadata["imulog.device.acc"]
    assert (meta["rate_hz"], meta["acc_range_g"], meta["counts_per_g"]) == (50.0, 2.0, 256.0)


# ------------------------------------------------------------------------------ simulator round trip
def test_simulated_raw_files_convert_to_the_simulators_recording(tmp_path):
    sim_mod = pytest.importorskip("imulog.simulate")
    sim = sim_mod.simulate("r2g", repetitions=1, opening_static_s=1.0)
    paths = sim_mod.write_trial_files(sim, tmp_path)
    rec = convert_files([paths["imu"], paths["vicon"]])
    a, b = sim.recording.imus[0], rec.imus[0]
    assert b.name == a.name == "wrist"
    np.testing.assert_array_equal(b.t_ns, a.t_ns)
    np.testing.assert_allclose(b.acc, a.acc, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b.gyr, a.gyr, rtol=1e-12, atol=1e-12)
    ma, mb = sim.recording.markers[0], rec.markers[0]
    assert mb.labels == ma.labels
    np.testing.assert_array_equal(mb.valid, ma.valid)
    np.testing.assert_allclose(mb.pos[mb.valid], ma.pos[ma.valid], rtol=1e-12, atol=1e-12)


# ------------------------------------------------------------------------------- plug-in converters
class LabConverter:
    """A lab's own device: 'LAB1' magic line, then 't_ms ax ay az' rows in g (what a plug-in looks like)."""

    name = "lab-device"
    description = "example plug-in"
    extensions = (".lab",)

    def sniff(self, path, head):
        return 0.9 if head.startswith(b"LAB1\n") else 0.0

    def convert(self, path, options=None):
        from imulog.model import ImuStream, Recording

        rows = np.loadtxt(path, skiprows=1, ndmin=2)
        imu = ImuStream(name="lab", t_ns=(rows[:, 0] * 1e6).astype(np.int64), acc=rows[:, 1:4] * G)
        return Recording(imus=[imu], metadata={"imulog.device.lab": {"model": "LAB1"}}, sources=[str(path)])


def test_a_lab_registers_its_own_converter_through_entry_points(tmp_path, monkeypatch):
    from importlib.metadata import EntryPoint

    import imulog.converters.registry as registry

    ep = EntryPoint(name="lab-device", value="test_convert_formats:LabConverter", group=ENTRY_POINT_GROUP)
    real = registry.entry_points
    monkeypatch.setattr(registry, "entry_points", lambda group: [*real(group=group), ep])
    path = tmp_path / "walk.lab"
    path.write_text("LAB1\n0 0 0 1\n10 0 0 1\n20 0 1 0\n")
    assert "lab-device" in available() and detect(path).name == "lab-device"
    rec = convert_file(path)
    np.testing.assert_array_equal(rec.imus[0].t_ns, [0, 10_000_000, 20_000_000])
    np.testing.assert_allclose(rec.imus[0].acc[2], [0, G, 0])


def test_nexus_csv_with_all_sections(tmp_path):
    """Devices, Model Outputs, Segments and Trajectories in one export, blank lines between sections."""
    text = (
        "Devices\n1000\n,,Force Plate 1,,\nFrame,Sub Frame,Fx,Fy,Mz\n,,N,N,N.mm\n"
        + "".join(f"{f},{s},{f + s / 10:.1f},2,{1000 * s}\n" for f in (1, 2) for s in range(10))
        + "\nModel Outputs\n100\n,,S:LKneeAngles,,\nFrame,Sub Frame,X,Y,Z\n,,deg,deg,deg\n1,0,10,20,30\n2,0,11,21,31\n"
        + "\nSegments\n100\n,,S:Forearm,,,,,\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,deg,deg,deg,mm,mm,mm\n"
        + "1,0,1,2,3,100,200,300\n2,0,1,2,3,110,210,310\n"
        + "\nTrajectories\n100\n,,S:A,,,S:B,,\nFrame,Sub Frame,X,Y,Z,X,Y,Z\n,,mm,mm,mm,m,m,m\n"
        + "1,0,1,2,3,,,\n2,0,4,5,6,0.5,0.25,1\n"
    )
    path = tmp_path / "all.csv"
    path.write_text(text.replace("\n", "\r\n"))
    rec = convert_file(path)
    (m,) = rec.markers
    assert m.labels == ["S:A", "S:B"]
    np.testing.assert_allclose(m.pos[1], [[0.004, 0.005, 0.006], [0.5, 0.25, 1.0]])  # mm and m columns
    np.testing.assert_array_equal(m.valid, [[True, False], [True, True]])
    (a,) = rec.analogs
    assert a.channel_names == ["Force Plate 1/Fx", "Force Plate 1/Fy", "Force Plate 1/Mz"]
    assert a.units == ["N", "N", "N.m"]
    np.testing.assert_allclose(a.values[:10, 2], np.arange(10))  # N.mm -> N.m
    np.testing.assert_array_equal(a.t_ns[:3], [0, 1_000_000, 2_000_000])  # 10 sub frames of the 100 Hz frame
    sig = {s.topic: s for s in rec.signals}
    mo, seg = sig["/vicon/model_outputs"], sig["/vicon/segments"]
    assert mo.columns == ["S:LKneeAngles.X", "S:LKneeAngles.Y", "S:LKneeAngles.Z"] and mo.units == ["deg"] * 3
    np.testing.assert_allclose(mo.values[1], [11, 21, 31])
    assert seg.units == ["deg", "deg", "deg", "m", "m", "m"]
    np.testing.assert_allclose(seg.values[1, 3:], [0.11, 0.21, 0.31])
    np.testing.assert_array_equal(seg.t_ns, [0, 10_000_000])
