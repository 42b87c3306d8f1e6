"""Wearable text exports: ActiLife epoch counts, Axivity CSV, Movella DOT CSV, Empatica E4 folders, Shimmer CSVs.

Real samples from ../shared/data/devices where they exist, files written in the documented layouts where not.
Expected values are computed here from the files themselves (pandas, unit factors written out), never copied
from the converters' output.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from imulog.converters import ConversionError, ConvertOptions, convert_file, convert_files, detect
from imulog.converters.movella_dot import unwrap_sample_time_fine
from imulog.converters.registry import group_directory

G = 9.80665
DEG = math.pi / 180.0


@pytest.fixture(scope="module")
def devices(shared_data: Path) -> Path:
    return shared_data / "devices"


# ------------------------------------------------------------------------------------ ActiLife epoch counts
def test_actilife_epoch_csv_without_names_row(devices):
    path = devices / "actigraph_count_csv/ActiGraph13.csv"
    assert detect(path).name == "actilife-csv"
    rec = convert_file(path)
    (sig,) = rec.signals
    expected = pd.read_csv(path, skiprows=10, header=None).to_numpy(dtype=float)
    assert sig.topic == "/signals/cle2a2123456_counts"
    assert sig.columns == ["axis1", "axis2", "axis3", "steps"]
    assert sig.units == ["counts", "counts", "counts", "steps"]
    np.testing.assert_array_equal(sig.values, expected)
    np.testing.assert_array_equal(sig.t_ns, np.arange(len(expected)) * 15_000_000_000)  # Epoch Period 00:00:15
    meta = rec.metadata["imulog.device.cle2a2123456_counts"]
    assert meta["epoch_s"] == 15.0 and meta["serial"] == "CLE2A2123456"
    assert rec.metadata["imulog.trial"]["start_time"] == "2013-08-26T09:00:00.000"  # Start Date 8/26/2013 09:00:00
    assert any("no names row" in w for w in rec.warnings)


def _epoch_file(tmp: Path, body: list[str], epoch: str = "00:01:00", date_format: str = "M/d/yyyy") -> Path:
    banner = [
        f"------------ Data File Created By ActiGraph GT3X+ ActiLife v6.13.3 Firmware v3.2.1 date format {date_format}"
        " Filter Normal -----------",
        "Serial Number: MOS2E12345678",
        "Start Time 10:00:00",
        "Start Date 3/1/2020" if date_format == "M/d/yyyy" else "Start Date 01.03.2020",
        f"Epoch Period (hh:mm:ss) {epoch}",
        "Download Time 12:00:00",
        "Download Date 3/2/2020",
        "Current Memory Address: 0",
        "Current Battery Voltage: 4.1     Mode = 61",
        "--------------------------------------------------",
    ]
    path = tmp / "counts.csv"
    path.write_text("\n".join(banner + body) + "\n")
    return path


def test_actilife_epoch_csv_with_names_and_date_time(tmp_path):
    names = "Date,Time,Axis1,Axis2,Axis3,Steps,Lux,Inclinometer Off,Inclinometer Standing,Inclinometer Sitting,"
    names += "Inclinometer Lying,Vector Magnitude"
    rows = [
        "3/1/2020,10:00:00,120,33,41,3,12,0,60,0,0,131.3",
        "3/1/2020,10:01:00,0,0,0,0,10,0,0,60,0,0",
        "3/1/2020,10:03:00,15,2,8,1,9,0,10,50,0,17.1",  # a missing epoch: the time says so
    ]
    path = _epoch_file(tmp_path, [names, *rows])
    rec = convert_file(path)
    (sig,) = rec.signals
    assert sig.columns[:3] == ["axis1", "axis2", "axis3"] and sig.columns[-1] == "vector_magnitude"
    assert sig.units[sig.columns.index("lux")] == "lx" and sig.units[sig.columns.index("inclinometer_sitting")] == "s"
    np.testing.assert_array_equal(sig.t_ns, np.array([0, 60, 180]) * 1_000_000_000)
    np.testing.assert_allclose(sig.values[:, 0], [120, 0, 15])
    np.testing.assert_allclose(sig.values[:, -1], [131.3, 0, 17.1])
    assert any("not 60 s apart" in w for w in rec.warnings)


def test_actilife_epoch_csv_errors(tmp_path):
    path = _epoch_file(tmp_path, ["1,2,3,4,5,6,7,8,9,10"])
    with pytest.raises(ConversionError, match=r"counts\.csv: line 11: 10 columns without a names row"):
        convert_file(path)
    path = _epoch_file(tmp_path, ["Date,Time,Axis1", "3/1/2020,10:00:00,5", "13/45/2020,10:01:00,6"])
    with pytest.raises(ConversionError, match=r"line 13, column 'Date': '13/45/2020 10:01:00' is not a date"):
        convert_file(path)
    path = _epoch_file(tmp_path, ["Axis1,Axis2", "5,6", "7,x"])
    with pytest.raises(ConversionError, match=r"line 13.*'x'"):
        convert_file(path)


# ------------------------------------------------------------------------------------------- Axivity CSV
def test_axivity_csv_unix_timestamps(devices):
    path = devices / "axivity_csv/ax3_testfile_unix_timestamps.csv"
    assert detect(path).name == "axivity-csv"
    rec = convert_file(path)
    (imu,) = rec.imus
    df = pd.read_csv(path, header=None)
    np.testing.assert_allclose(imu.acc, df[[1, 2, 3]].to_numpy() * G, rtol=1e-15)
    assert imu.gyr is None
    expected_ns = np.round((df[0].to_numpy() - df[0].iloc[0]) * 1e6).astype(np.int64) * 1000
    assert np.abs(imu.t_ns - expected_ns).max() <= 1000  # within 1 us of the printed stamps
    start = datetime.fromtimestamp(float(df[0].iloc[0]), tz=UTC).replace(tzinfo=None)
    assert rec.metadata["imulog.trial"]["start_time"] == start.isoformat(timespec="milliseconds")
    assert rec.metadata["imulog.device.axivity"]["model"] == "AX3"


def test_axivity_csv_formatted_ax6(tmp_path):
    rng = np.random.default_rng(1)
    n = 100
    t0 = pd.Timestamp("2021-05-04 13:14:15.000")
    times = [t0 + pd.Timedelta(milliseconds=10 * i) for i in range(n)]
    acc = np.round(rng.normal(0, 0.5, (n, 3)), 6)
    gyr = np.round(rng.normal(0, 50, (n, 3)), 6)
    path = tmp_path / "ax6.csv"
    path.write_text(
        "".join(
            f"{t.strftime('%Y-%m-%d %H:%M:%S.%f')[:-3]},{','.join(map(str, a))},{','.join(map(str, g))}\n"
            for t, a, g in zip(times, acc, gyr, strict=True)
        )
    )
    assert detect(path).name == "axivity-csv"
    rec = convert_file(path)
    (imu,) = rec.imus
    np.testing.assert_allclose(imu.acc, acc * G, rtol=1e-15)
    np.testing.assert_allclose(imu.gyr, gyr * DEG, rtol=1e-15)
    np.testing.assert_array_equal(imu.t_ns, np.arange(n) * 10_000_000)
    assert rec.metadata["imulog.trial"]["start_time"] == "2021-05-04T13:14:15.000"
    assert rec.metadata["imulog.device.axivity"]["model"] == "AX6"


# ----------------------------------------------------------------------------------------- Movella DOT
def test_movella_dot_app_export(devices):
    path = devices / "movella_dot_csv/bei_D4CA6EF17860_20210830_170505.csv"
    assert detect(path).name == "movella-dot"
    rec = convert_file(path)
    (imu,) = rec.imus
    df = pd.read_csv(path, skiprows=7)
    assert imu.name == "bei" and len(imu) == len(df)
    np.testing.assert_allclose(imu.acc, df[["Acc_X", "Acc_Y", "Acc_Z"]].to_numpy(), rtol=1e-15)
    np.testing.assert_allclose(imu.gyr, df[["Gyr_X", "Gyr_Y", "Gyr_Z"]].to_numpy() * DEG, rtol=1e-15)
    stf = df["SampleTimeFine"].to_numpy(dtype=np.int64)
    np.testing.assert_array_equal(imu.t_ns, (stf - stf[0]) * 1000)  # microseconds
    assert 119 < rec.metadata["imulog.device.bei"]["rate_hz"] < 121  # the DOT's 120 Hz
    trial = rec.metadata["imulog.trial"]
    assert trial["start_time"] == "2021-08-30T17:05:05+08:00" and trial["time_zone"] == "+08:00"
    orient = next(s for s in rec.signals if s.topic == "/orientation/bei")
    # Euler (roll, pitch, yaw) -> quaternion: rotating x by q equals the ZYX rotation matrix's first column
    r, p, y = np.radians(df[["Euler_X", "Euler_Y", "Euler_Z"]].to_numpy()).T
    col0 = np.column_stack([np.cos(y) * np.cos(p), np.sin(y) * np.cos(p), -np.sin(p)])
    w, x, yy, z = orient.values.T
    qcol0 = np.column_stack([1 - 2 * (yy**2 + z**2), 2 * (x * yy + w * z), 2 * (x * z - w * yy)])
    np.testing.assert_allclose(qcol0, col0, atol=1e-9)


def test_movella_dot_rate_is_the_time_stamps(devices):
    """The shared DOT file is described as 60 Hz in the shared data's notes; its stamps say 120 Hz and imulog reads
    120 Hz: PacketCounter steps by 1 (no packet lost) and every SampleTimeFine step is 8333 us. docs/converters.md
    says so, with the figures this file gives."""
    path = devices / "movella_dot_csv/bei_D4CA6EF17860_20210830_170505.csv"
    df = pd.read_csv(path, skiprows=7)
    assert set(np.diff(df["PacketCounter"].to_numpy())) == {1}
    assert set(np.diff(df["SampleTimeFine"].to_numpy(dtype=np.int64))) == {8333}
    rec = convert_file(path)
    (imu,) = rec.imus
    span_s = (imu.t_ns[-1] - imu.t_ns[0]) / 1e9
    rate = rec.metadata["imulog.device.bei"]["rate_hz"]
    assert abs(rate - (len(imu) - 1) / span_s) < 1e-3 and round(rate, 3) == 120.005
    docs = (Path(__file__).resolve().parents[1] / "docs" / "converters.md").read_text()
    section = docs.split("### Movella DOT CSV", 1)[1].split("\n### ", 1)[0]
    for figure in (f"{rate:.3f} Hz", f"{len(imu)} samples", f"{span_s:.3f} s", "exactly 8333 us", "60 Hz"):
        assert figure in section, figure


def _dot_log(tmp: Path, stf: np.ndarray, name: str = "log.csv") -> tuple[Path, np.ndarray]:
    n = len(stf)
    rng = np.random.default_rng(2)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    fa = rng.normal(size=(n, 3))
    path = tmp / name
    lines = ["PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z,FreeAcc_X,FreeAcc_Y,FreeAcc_Z"]
    for i in range(n):
        lines.append(",".join([str(i), str(int(stf[i])), *(f"{v:.8f}" for v in q[i]), *(f"{v:.6f}" for v in fa[i])]))
    path.write_text("\n".join(lines) + "\n")
    return path, q


def test_movella_dot_realtime_log_wraps_sample_time_fine(tmp_path):
    stf = (2**32 - 3 * 16_667 + np.arange(10) * 16_667) % 2**32  # 60 Hz, wraps after the third sample
    path, q = _dot_log(tmp_path, stf)
    assert detect(path).name == "movella-dot"
    rec = convert_file(path)
    assert not rec.imus  # orientation and free acceleration only
    orient = next(s for s in rec.signals if s.topic.startswith("/orientation/"))
    np.testing.assert_array_equal(orient.t_ns, np.arange(10) * 16_667_000)
    np.testing.assert_allclose(orient.values, np.round(q, 8), atol=1e-12)
    sig = next(s for s in rec.signals if s.topic.startswith("/signals/"))
    assert sig.units[sig.columns.index("freeacc_x")] == "m/s^2"
    assert "imulog.trial" not in rec.metadata  # the log carries no start time


def test_unwrap_sample_time_fine_and_backwards_step(tmp_path):
    raw = np.array([2**32 - 10, 2**32 - 5, 3, 8])
    np.testing.assert_array_equal(unwrap_sample_time_fine(raw), np.array([0, 5, 13, 18]) * 1000)
    path, _ = _dot_log(tmp_path, np.array([1000, 2000, 1500, 3000]), "back.csv")
    with pytest.raises(ConversionError, match=r"back\.csv: line 4, column 'SampleTimeFine': SampleTimeFine does not"):
        convert_file(path)


def test_xsens_mt_file_is_not_taken_for_a_dot_log(tmp_path):
    path = tmp_path / "MT_00B41234.txt"
    path.write_text("PacketCounter,SampleTimeFine,Acc_X,Acc_Y,Acc_Z\n0,100,0,0,9.8\n1,200,0,0,9.8\n")
    assert detect(path).name == "xsens"


# ------------------------------------------------------------------------------------------- Empatica E4
def test_empatica_e4_folder_is_one_recording(devices, tmp_path):
    folder = devices / "empatica_e4"
    groups = group_directory(folder)
    assert len(groups) == 1
    files = groups[0][1]
    assert {f.name for f in files} == {"ACC.csv", "BVP.csv", "EDA.csv", "HR.csv", "IBI.csv", "TEMP.csv"}
    rec = convert_files(files)
    acc = pd.read_csv(folder / "ACC.csv", header=None)
    start = float(acc.iloc[0, 0])
    (imu,) = rec.imus
    np.testing.assert_allclose(imu.acc, acc.iloc[2:].to_numpy(dtype=float) / 64.0 * G, rtol=1e-15)
    np.testing.assert_array_equal(imu.t_ns[:3], [0, 31_250_000, 62_500_000])  # 32 Hz
    hr = pd.read_csv(folder / "HR.csv", header=None)
    hr_sig = next(s for s in rec.signals if s.topic == "/signals/e4_hr")
    assert hr_sig.t_ns[0] == round((float(hr.iloc[0, 0]) - start) * 1e9)  # HR starts later: same origin kept
    np.testing.assert_allclose(hr_sig.values[:, 0], hr.iloc[2:, 0].to_numpy(dtype=float))
    ibi = pd.read_csv(folder / "IBI.csv", header=None, skiprows=1)
    ibi_sig = next(s for s in rec.signals if s.topic == "/signals/e4_ibi")
    np.testing.assert_array_equal(ibi_sig.t_ns, np.round(ibi[0].to_numpy() * 1e9).astype(np.int64))
    np.testing.assert_allclose(ibi_sig.values[:, 0], ibi[1].to_numpy())
    trial = rec.metadata["imulog.trial"]
    assert trial["time_zone"] == "UTC"
    assert trial["start_time"].startswith(datetime.fromtimestamp(start, tz=UTC).isoformat()[:19])
    assert not rec.warnings  # one start time for every file


def test_empatica_e4_tags_and_bad_rate(tmp_path):
    (tmp_path / "ACC.csv").write_text("1600000000.0, 1600000000.0, 1600000000.0\n32.0, 32.0, 32.0\n1,2,64\n3,4,63\n")
    (tmp_path / "tags.csv").write_text("1600000001.5\n1600000003.0\n")
    (tmp_path / "TEMP.csv").write_text("1600000000.0\n-4.0\n30.1\n")
    rec = convert_file(tmp_path / "tags.csv")
    np.testing.assert_array_equal(rec.events[0].start_ns, [1_500_000_000, 3_000_000_000])
    with pytest.raises(ConversionError, match=r"TEMP\.csv: line 2: sample rate -4 Hz is not plausible"):
        convert_file(tmp_path / "TEMP.csv")


# ------------------------------------------------------------------------------------------------ Shimmer
SHIMMER_NAMES = [
    "Timestamp",
    "System Timestamp",
    "Low Noise Accelerometer X",
    "Low Noise Accelerometer Y",
    "Low Noise Accelerometer Z",
    "Wide Range Accelerometer X",
    "Wide Range Accelerometer Y",
    "Wide Range Accelerometer Z",
    "Gyroscope X",
    "Gyroscope Y",
    "Gyroscope Z",
    "Magnetometer X",
    "Magnetometer Y",
    "Magnetometer Z",
]
SHIMMER_UNITS = ["mSecs", "mSecs"] + ["m/(sec^2)"] * 6 + ["deg/sec"] * 3 + ["local"] * 3


def _shimmer(
    tmp: Path, *, flags: list[str] | None = None, sep: str = ",", sep_line: bool = False, trailing: bool = True
):
    rng = np.random.default_rng(5)
    n = 256
    t_ms = np.arange(n) * 1000 / 51.2
    unix_ms = 1_600_000_000_000 + t_ms
    data = np.round(rng.normal(0, 2, (n, 12)), 5)
    data[:, 2] += 9.81
    flags = flags or ["CAL"] * 14
    end = sep if trailing else ""
    rows = [
        sep.join(["Shimmer_5E3B"] * 14) + end,
        sep.join(SHIMMER_NAMES) + end,
        sep.join(flags) + end,
        sep.join(u if f == "CAL" else "no units" for u, f in zip(SHIMMER_UNITS, flags, strict=True)) + end,
    ]
    for i in range(n):
        rows.append(sep.join(f"{v:.5f}" for v in [t_ms[i], unix_ms[i], *data[i]]) + end)
    path = tmp / "shimmer.csv"
    path.write_text((f'"sep={sep}"\n' if sep_line else "") + "\n".join(rows) + "\n")
    return path, t_ms, unix_ms, data


@pytest.mark.parametrize(("sep", "sep_line", "trailing"), [(",", False, True), ("\t", True, False), (";", True, True)])
def test_shimmer_four_row_header(tmp_path, sep, sep_line, trailing):
    path, t_ms, unix_ms, data = _shimmer(tmp_path, sep=sep, sep_line=sep_line, trailing=trailing)
    assert detect(path).name == "shimmer-csv"
    rec = convert_file(path)
    (imu,) = rec.imus
    assert imu.name == "shimmer_5e3b"
    np.testing.assert_allclose(imu.acc, data[:, 0:3], rtol=1e-15)  # low-noise accelerometer: the first variant
    np.testing.assert_allclose(imu.gyr, data[:, 6:9] * DEG, rtol=1e-15)
    assert imu.mag is None  # 'local' = normalised field, kept as a signal
    np.testing.assert_array_equal(imu.t_ns, np.round(np.round(t_ms, 5) * 1e6).astype(np.int64))
    (sig,) = rec.signals
    wr = [c for c in sig.columns if "Accel_WR" in c]
    assert len(wr) == 3
    np.testing.assert_allclose(sig.values[:, sig.columns.index(wr[0])], data[:, 3], rtol=1e-15)
    trial = rec.metadata["imulog.trial"]
    assert trial["time_zone"] == "UTC"
    assert trial["start_time"] == datetime.fromtimestamp(unix_ms[0] / 1000, tz=UTC).isoformat(timespec="milliseconds")
    assert "System_Timestamp" in trial["start_time_source"]


def test_shimmer_uncalibrated_export(tmp_path):
    path, *_ = _shimmer(tmp_path, flags=["CAL", "CAL"] + ["RAW"] * 12)
    rec = convert_file(path)
    assert not rec.imus  # ADC counts: never taken for SI units
    assert any("uncalibrated (RAW)" in w for w in rec.warnings)
    path, *_ = _shimmer(tmp_path, flags=["RAW"] * 14)
    with pytest.raises(ConversionError, match=r"shimmer\.csv: uncalibrated \(RAW\) Shimmer export: its Timestamp"):
        convert_file(path)
    assert convert_file(path, options=ConvertOptions(rate_hz=51.2)).signals  # a rate stands in


def test_shimmer_consensys_unix_column_dates_the_trial(shared_data: Path):
    path = shared_data / "imu_text" / "shimmer_consensys_export.csv"
    rec = convert_file(path)
    first_ms = float(pd.read_csv(path, sep=";", skiprows=[0, 2], nrows=1).iloc[0, 0])
    start = datetime.fromisoformat(rec.metadata["imulog.trial"]["start_time"])
    assert abs(start.timestamp() * 1000 - first_ms) < 40  # the fitted first stamp, within the host jitter
    assert rec.metadata["imulog.trial"]["time_zone"] == "UTC"


def test_actilife_epoch_csv_day_first_date_format(tmp_path):
    from imulog.converters.actilife_csv import strptime_format

    assert strptime_format("dd.MM.yyyy") == "%d.%m.%Y" and strptime_format("M/d/yyyy") == "%m/%d/%Y"
    rows = ["Date,Time,Axis1", "01.03.2020,10:00:00,5", "01.03.2020,10:01:00,6", "01.03.2020,10:02:00,7"]
    rec = convert_file(_epoch_file(tmp_path, rows, date_format="dd.MM.yyyy"))
    assert rec.metadata["imulog.trial"]["start_time"] == "2020-03-01T10:00:00.000"
    np.testing.assert_array_equal(rec.signals[0].t_ns, np.array([0, 60, 120]) * 1_000_000_000)


def test_actilife_epoch_csv_without_banner(tmp_path):
    path = tmp_path / "nobanner.csv"
    path.write_text(
        "Date,Time,Axis1,Axis2,Axis3,Steps\n"
        "26/08/2013,09:00:00,10,0,3,1\n26/08/2013,09:00:15,0,5,0,0\n26/08/2013,09:00:30,7,7,7,2\n"
    )
    assert detect(path).name == "actilife-csv"
    rec = convert_file(path)
    (sig,) = rec.signals
    np.testing.assert_array_equal(sig.t_ns, np.array([0, 15, 30]) * 1_000_000_000)
    np.testing.assert_array_equal(sig.values, [[10, 0, 3, 1], [0, 5, 0, 0], [7, 7, 7, 2]])
    assert rec.metadata["imulog.trial"]["start_time"] == "2013-08-26T09:00:00.000"  # 26 > 12: day first
    assert any("no ActiLife banner" in w and "d/M/yyyy" in w for w in rec.warnings)
    path.write_text("Axis1,Axis2,Axis3\n1,2,3\n4,5,6\n")
    with pytest.raises(ConversionError, match=r"without its banner and without Date/Time columns"):
        convert_file(path)


def test_e4_file_alone_starts_at_its_first_sample_and_files_merge_to_the_earliest(devices: Path):
    """HR.csv starts 10 s after ACC.csv: alone, its start_time is its own first sample; given first with ACC.csv
    (one time base), the merged trial starts at ACC's first sample, without a 'start time differs' warning."""
    folder = devices / "empatica_e4"
    acc_start = float((folder / "ACC.csv").read_text().split(",")[0])
    hr_start = float((folder / "HR.csv").read_text().splitlines()[0])
    assert hr_start - acc_start == 10.0
    alone = convert_file(folder / "HR.csv")
    assert alone.metadata["imulog.trial"]["start_time"] == datetime.fromtimestamp(hr_start, tz=UTC).isoformat()
    assert alone.signals[0].t_ns[0] == 10 * 10**9  # t_ns stay on the session origin
    both = convert_files([folder / "HR.csv", folder / "ACC.csv"])
    assert both.metadata["imulog.trial"]["start_time"] == datetime.fromtimestamp(acc_start, tz=UTC).isoformat()
    assert not any("differs" in w for w in both.warnings)
