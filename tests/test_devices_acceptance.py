"""Issue 25's acceptance test: every file (or session folder) in ../shared/data/devices converts through the command
line, passes ``imulog doctor``, and matches its reference decode where one exists: a reference library (pygt3x's
kept decode, scikit-digital-health, OpenMovement's parser, nilspodlib, MNE, ezc3d, OpenSim's readers, pyxdf) or,
for text exports without one, the file's own numbers read with pandas. Values, sample counts and start times.

``CASES`` names every file of the folder: a file added there without a case here fails
``test_every_shared_file_has_a_case``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from imulog.converters._common import G0

from imulog.archive import TrialReader
from imulog.cli import cli

DATA = Path(__file__).parent / "data"
COMPANIONS = ("LICENSE_", "NOTICE_", "README", "HEADERS.md", "SOURCES.tsv")
DEG = np.pi / 180.0


# ----------------------------------------------------------------------------------------------------- helpers
def convert(src: Path, tmp_path: Path) -> TrialReader:
    """``imulog convert SRC -o OUT`` then ``imulog doctor OUT``, both with exit code 0; the trial opened."""
    out = tmp_path / "trial.mcap"
    r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    d = CliRunner().invoke(cli, ["doctor", str(out)])
    assert d.exit_code == 0, d.output
    return TrialReader(out)


def first_ns(trial: TrialReader) -> int:
    """The trial's first raw sample: ``start_time`` is its wall time (imulog.archive.timeline)."""
    return min(c.start_ns for c in trial.channels if not c.derived and c.start_ns is not None)


def wall_s(trial: TrialReader, t_ns: np.ndarray) -> np.ndarray:
    """Sample times as seconds since 1970 of the clock's own wall time (what the reference readers give)."""
    start = datetime.fromisoformat(trial.metadata["imulog.trial"]["start_time"]).replace(tzinfo=None)
    us = round((start - datetime(1970, 1, 1)).total_seconds() * 1e6)
    return (us * 1000 + (np.asarray(t_ns, dtype=np.int64) - first_ns(trial))) / 1e9


def utc_s(trial: TrialReader, t_ns: np.ndarray) -> np.ndarray:
    """Sample times as Unix seconds (the trial's start_time carries its zone)."""
    start = datetime.fromisoformat(trial.metadata["imulog.trial"]["start_time"])
    us = round(start.timestamp() * 1e6)
    return (us * 1000 + (np.asarray(t_ns, dtype=np.int64) - first_ns(trial))) / 1e9


def one(trial: TrialReader, prefix: str):
    topics = [t for t in trial.topics() if t.startswith(prefix)]
    assert len(topics) == 1, topics
    return trial.read(topics[0])


def actilife_banner(path: Path) -> datetime:
    lines = path.read_text().splitlines()[:10]
    time = next(x for x in lines if x.startswith("Start Time")).split()[2].strip(",")
    date = next(x for x in lines if x.startswith("Start Date")).split()[2].strip(",")
    return datetime.strptime(f"{date} {time}", "%m/%d/%Y %H:%M:%S")


def epoch_s(dt: datetime) -> float:
    return (dt - datetime(1970, 1, 1)).total_seconds()


# ------------------------------------------------------------------------------------------ reference checks
def ref_actilife_epochs(trial: TrialReader, src: Path) -> None:
    ref = pd.read_csv(src, skiprows=10, header=None).to_numpy(dtype=float)
    s = one(trial, "/signals/")
    np.testing.assert_array_equal(s.values, ref)
    np.testing.assert_allclose(wall_s(trial, s.t_ns), epoch_s(actilife_banner(src)) + 15.0 * np.arange(len(ref)))


def ref_gt3x(trial: TrialReader, src: Path) -> None:
    ref = np.load(DATA / "pygt3x_example.npz")  # ActiGraph's pygt3x decode (GPL: kept, not installed)
    acc = trial.read("/imu/tas1e31150129")
    np.testing.assert_allclose(acc.acc / G0, ref["counts"] / 256.0, atol=1e-6, rtol=0)
    np.testing.assert_allclose(wall_s(trial, acc.t_ns), ref["time_s"], atol=1e-6, rtol=0)


def ref_actilife_imu(trial: TrialReader, src: Path) -> None:
    ref = pd.read_csv(src, skiprows=10)
    imu = one(trial, "/imu/")
    assert len(imu.t_ns) == len(ref) == 2300
    np.testing.assert_allclose(imu.acc / G0, ref.filter(like="Accelerometer").to_numpy(), atol=1e-6)
    np.testing.assert_allclose(imu.gyr / DEG, ref.filter(like="Gyroscope").to_numpy(), atol=1e-5)
    t = pd.to_datetime(ref["Timestamp"]).to_numpy().astype("datetime64[ns]").astype(np.int64) / 1e9
    np.testing.assert_allclose(wall_s(trial, imu.t_ns), t, atol=1e-6)


def ref_actilife_raw(trial: TrialReader, src: Path) -> None:
    ref = pd.read_csv(src, skiprows=10).to_numpy(dtype=float)
    imu = one(trial, "/imu/")
    np.testing.assert_allclose(imu.acc / G0, ref, atol=1e-6)
    np.testing.assert_allclose(wall_s(trial, imu.t_ns), epoch_s(actilife_banner(src)) + np.arange(len(ref)) / 90.0)


def ref_apdm_format7(trial: TrialReader, src: Path) -> None:
    raw = pd.read_csv(src, skiprows=3, header=None).to_numpy(dtype=float)
    imu = trial.read("/imu/lumbar")
    np.testing.assert_allclose(imu.acc, raw[:, 1:4], atol=1e-9)
    np.testing.assert_allclose(imu.gyr, raw[:, 4:7], atol=1e-9)
    np.testing.assert_allclose(utc_s(trial, imu.t_ns), raw[:, 0] / 1e6, atol=1e-6)  # us since 1970


def ref_apdm_opensim(trial: TrialReader, src: Path) -> None:
    osim = pytest.importorskip("opensim")
    settings = osim.APDMDataReaderSettings()
    for label in ("Static", "Upper", "Middle", "Lower"):
        settings.append_ExperimentalSensors(osim.ExperimentalSensor(label, label.lower()))
    reader = osim.APDMDataReader(settings)
    tables = reader.read(str(src))
    acc, gyr = reader.getLinearAccelerationsTable(tables), reader.getAngularVelocityTable(tables)
    for k, label in enumerate(("static", "upper", "middle", "lower")):
        imu = trial.read(f"/imu/{label}")
        assert len(imu.t_ns) == acc.getNumRows() == 1024
        for i in (0, 511, 1023):
            np.testing.assert_allclose(imu.acc[i], acc.getRowAtIndex(i)[k].to_numpy(), atol=1e-6)
            np.testing.assert_allclose(imu.gyr[i], gyr.getRowAtIndex(i)[k].to_numpy(), atol=1e-6)
    # OpenSim counts from 0 at 128 Hz; the file's time column (first 0.0074576 s) is the sample grid
    np.testing.assert_allclose(np.diff(trial.read("/imu/static").t_ns) / 1e9, 1 / 128.0, atol=2e-6)


def ref_axivity_csv(trial: TrialReader, src: Path) -> None:
    ref = pd.read_csv(src, header=None).to_numpy(dtype=float)
    imu = one(trial, "/imu/")
    np.testing.assert_allclose(imu.acc / G0, ref[:, 1:4], atol=1e-9)
    np.testing.assert_allclose(wall_s(trial, imu.t_ns), ref[:, 0], atol=1e-6)


def ref_cwa(trial: TrialReader, src: Path) -> None:
    """Values and times: scikit-digital-health's shipped decode (times to 0.1 ms, the .npz's precision; imulog's
    default .cwa time rule is skdh's: tests/test_convert_axivity_time.py)."""
    ref = np.load(src.with_name(src.name.replace("_sample.cwa", "_data.npz")))
    imu = one(trial, "/imu/")
    assert len(imu.t_ns) == len(ref["time"])
    np.testing.assert_allclose(imu.acc / G0, ref["accel"], atol=5e-5, rtol=0)
    if "gyro" in ref:
        np.testing.assert_allclose(imu.gyr / DEG, ref["gyro"], atol=1e-4, rtol=0)
    np.testing.assert_allclose(wall_s(trial, imu.t_ns), ref["time"], atol=1e-4, rtol=0)


def ref_c3d(trial: TrialReader, src: Path) -> None:
    """The ``c3d`` package (pure Python, independent of ezc3d, which crashes on MACsample.c3d). MIPS is given to it
    as imulog's exact Intel rewrite, its header scale set to POINT:SCALE (imulog trusts the parameter, the header
    says 0.0551 against 0.0215; c3d refuses a file where they differ)."""
    import io
    import struct

    c3d = pytest.importorskip("c3d")
    from imulog.converters.c3d_format import parameters, to_intel

    data = bytearray(to_intel(src.read_bytes()))
    struct.pack_into("<f", data, 12, parameters(bytes(data))["POINT:SCALE"][0])
    reader = c3d.Reader(io.BytesIO(bytes(data)))
    frames = [(p.copy(), a.copy()) for _, p, a in reader.read_frames()]
    pts = np.stack([p[:, :3] for p, _ in frames])
    valid = np.stack([p[:, 3] >= 0 for p, _ in frames])
    scale = 1e-3 if reader.get("POINT:UNITS").string_value.strip(" \x00").lower() == "mm" else 1.0
    markers = one(trial, "/markers/")
    assert markers.pos.shape == pts.shape
    np.testing.assert_array_equal(np.isfinite(markers.pos).all(axis=2), valid)
    np.testing.assert_allclose(markers.pos[valid], pts[valid] * scale, atol=1e-6)
    np.testing.assert_allclose(np.diff(markers.t_ns) / 1e9, 1 / reader.point_rate, atol=1e-6)
    analog = np.concatenate([a.T for _, a in frames])  # (frames * per_frame, channels)
    an = one(trial, "/analog/")
    assert an.values.shape == analog.shape


def ref_delsys(trial: TrialReader, src: Path) -> None:
    lines = src.read_text(encoding="utf-8").splitlines()
    head = next(i for i, x in enumerate(lines) if x.startswith("X[s]"))
    df = pd.read_csv(src, skiprows=head, header=0)
    acc_x = df["Mini sensor 10: ACC.X 10"].dropna().to_numpy(dtype=float)
    imu = trial.read("/imu/mini_sensor_10")
    assert len(imu.t_ns) == len(acc_x)
    np.testing.assert_allclose(imu.acc[:, 0] / G0, acc_x, atol=1e-9)
    emg = df["Mini sensor 10: EMG 10"].dropna().to_numpy(dtype=float)
    assert trial.read("/analog/mini_sensor_10").values.shape[0] == len(emg)


def ref_edf(trial: TrialReader, src: Path) -> None:
    mne = pytest.importorskip("mne")
    raw = mne.io.read_raw_edf(src, preload=True, verbose="error")
    emg = raw.get_data(picks=[0])[0]  # V
    an = trial.read("/analog/edf")
    assert an.values.shape[0] == len(emg)
    np.testing.assert_allclose(an.values[:, 0], emg, atol=1e-12)
    meas = raw.info["meas_date"].replace(tzinfo=None)
    assert datetime.fromisoformat(trial.metadata["imulog.trial"]["start_time"]).replace(tzinfo=None) == meas


def _e4_ref(path: Path) -> tuple[float, float, np.ndarray]:
    head = pd.read_csv(path, header=None, nrows=2).to_numpy(dtype=float)
    values = pd.read_csv(path, header=None, skiprows=2).to_numpy(dtype=float)
    return head[0, 0], head[1, 0], values


def ref_e4_file(trial: TrialReader, src: Path) -> None:
    kind = src.stem.lower()
    if kind == "ibi":
        ref = pd.read_csv(src, header=None, skiprows=1).to_numpy(dtype=float)
        start = float(pd.read_csv(src, header=None, nrows=1).iloc[0, 0])
        s = one(trial, "/signals/")
        np.testing.assert_allclose(s.values[:, 0], ref[:, 1])
        np.testing.assert_allclose(utc_s(trial, s.t_ns), start + ref[:, 0], atol=1e-6)
        return
    start, rate, values = _e4_ref(src)
    if kind == "acc":
        s = one(trial, "/imu/")
        np.testing.assert_allclose(s.acc / G0, values / 64.0, atol=1e-12)  # 1/64 g per count
    else:
        s = one(trial, "/signals/")
        np.testing.assert_allclose(s.values[:, 0], values[:, 0])
    n = len(s.t_ns)
    assert n == len(values)
    np.testing.assert_allclose(utc_s(trial, s.t_ns), start + np.arange(n) / rate, atol=1e-6)


def ref_e4_folder(trial: TrialReader, src: Path) -> None:
    start, rate, values = _e4_ref(src / "ACC.csv")
    imu = one(trial, "/imu/")
    np.testing.assert_allclose(imu.acc / G0, values / 64.0, atol=1e-12)
    np.testing.assert_allclose(utc_s(trial, imu.t_ns), start + np.arange(len(values)) / rate, atol=1e-6)
    for name in ("BVP", "EDA", "HR", "TEMP"):
        s0, r, v = _e4_ref(src / f"{name}.csv")
        s = trial.read(f"/signals/e4_{name.lower()}")
        np.testing.assert_allclose(s.values[:, 0], v[:, 0])
        np.testing.assert_allclose(utc_s(trial, s.t_ns), s0 + np.arange(len(v)) / r, atol=1e-6)
    assert len(trial.read("/signals/e4_ibi").t_ns) == len(pd.read_csv(src / "IBI.csv", skiprows=1, header=None))


def ref_geneactiv(trial: TrialReader, src: Path) -> None:
    """scikit-digital-health's ReadBin on the pages before the cut last one (it refuses a cut page)."""
    skdh_io = pytest.importorskip("skdh.io")
    from imulog.converters.geneactiv import PAGE_MARK

    data = src.read_bytes()
    cut = data.rfind(PAGE_MARK)
    whole = _tmp_copy(data[:cut].replace(b"Number of Pages:222048", f"Number of Pages:{16:<6d}".encode()))
    ref = skdh_io.ReadBin().predict(file=str(whole))
    imu = one(trial, "/imu/")
    assert len(imu.t_ns) == len(ref["time"]) == 4800
    np.testing.assert_allclose(imu.acc / G0, ref["accel"], atol=1e-12, rtol=0)
    np.testing.assert_allclose(wall_s(trial, imu.t_ns), ref["time"], atol=1e-6, rtol=0)


_TMP: list[Path] = []


def _tmp_copy(data: bytes, suffix: str = ".bin") -> Path:
    import tempfile

    f = tempfile.NamedTemporaryFile(suffix=suffix, delete=False)  # noqa: SIM115 - removed by the fixture below
    f.write(data)
    f.close()
    _TMP.append(Path(f.name))
    return Path(f.name)


def every_unit_given(trial: TrialReader) -> None:
    """Every column of every channel names its unit: a rotation matrix's entries and a packet counter are "1",
    never blank (``imulog info`` showed the Xsens matrix as " x9" and BIDS channels.tsv needs a unit)."""
    for c in trial.channels:
        text = c.metadata.get("units") or "[]"
        units = json.loads(text) if text.startswith("[") else [text]  # events store one plain unit ("ns")
        assert all(str(u).strip() for u in units), (c.topic, units)


def ref_movella_dot(trial: TrialReader, src: Path) -> None:
    every_unit_given(trial)
    df = pd.read_csv(src, skiprows=7)
    imu = one(trial, "/imu/")
    assert len(imu.t_ns) == len(df) == 1953
    np.testing.assert_allclose(imu.acc, df[["Acc_X", "Acc_Y", "Acc_Z"]].to_numpy(), atol=1e-9)
    np.testing.assert_allclose(imu.gyr / DEG, df[["Gyr_X", "Gyr_Y", "Gyr_Z"]].to_numpy(), atol=1e-9)
    fine = df["SampleTimeFine"].to_numpy(dtype=np.int64)  # us, this file does not wrap
    np.testing.assert_array_equal(imu.t_ns, (fine - fine[0]) * 1000)
    # StartTime: ,2021-08-30_17:05:05_000 GMT+8
    assert trial.metadata["imulog.trial"]["start_time"] == "2021-08-30T17:05:05+08:00"


def ref_nilspod_bin(trial: TrialReader, src: Path) -> None:
    nilspodlib = pytest.importorskip("nilspodlib")
    ds = nilspodlib.Dataset.from_bin_file(src)
    imu = one(trial, "/imu/")
    assert len(imu.t_ns) == len(ds.counter) == 635
    np.testing.assert_allclose(imu.acc, ds.acc.data, atol=1e-12)
    np.testing.assert_allclose(imu.gyr / DEG, ds.gyro.data, atol=1e-9)
    ref_t = np.asarray(ds.utc_counter, dtype=float)  # Unix s of each sample
    np.testing.assert_allclose(utc_s(trial, imu.t_ns), ref_t, atol=1e-6)


def ref_nilspod_csv(trial: TrialReader, src: Path) -> None:
    df = pd.read_csv(src)
    header = json.loads(src.with_name(src.name.replace("_data.csv", "_header.json")).read_text())
    imu = one(trial, "/imu/")
    assert len(imu.t_ns) == len(df) == header["n_samples"]
    np.testing.assert_allclose(imu.acc, df[["acc_x", "acc_y", "acc_z"]].to_numpy(), atol=1e-12)
    np.testing.assert_allclose(utc_s(trial, imu.t_ns), header["utc_start"] + df["t"].to_numpy(), atol=1e-6)


def refused_companion(src: Path, tmp_path: Path) -> None:
    """A NilsPod _header.json describes the _data.csv beside it: refused in one line that says what to convert."""
    out = tmp_path / "t.mcap"
    r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
    assert r.exit_code != 0 and not out.exists()
    line = r.output.strip()
    assert "\n" not in line and "Traceback" not in line
    assert "NilsPod" in line and "_data.csv" in line
    assert "holds the session's settings, not its samples" in line  # two apostrophes are not a quoted value


def ref_opensense_sto(trial: TrialReader, src: Path) -> None:
    osim = pytest.importorskip("opensim")
    table = osim.TimeSeriesTableQuaternion(str(src))
    labels = list(table.getColumnLabels())
    times = np.array(table.getIndependentColumn())
    for k, label in enumerate(labels):
        q = trial.read(f"/orientation/{label}")
        assert len(q.t_ns) == table.getNumRows()
        for i in (0, table.getNumRows() - 1):
            e = table.getRowAtIndex(i).getElt(0, k)
            np.testing.assert_allclose(q.values[i], [e.get(0), e.get(1), e.get(2), e.get(3)], atol=1e-9)
        np.testing.assert_allclose(q.t_ns / 1e9, times, atol=1e-9)


def _lab_table(src: Path, header_line: str) -> pd.DataFrame:
    lines = src.read_text().splitlines()
    head = next(i for i, x in enumerate(lines) if x.split(",")[0].strip().lower() == header_line)
    return pd.read_csv(src, skiprows=head, header=0)


def ref_mot(trial: TrialReader, src: Path) -> None:
    df = _lab_table(src, "time").dropna(axis=1, how="all")
    s = one(trial, "/signals/")
    assert len(s.t_ns) == len(df) == 88
    np.testing.assert_allclose(s.t_ns / 1e9, df["time"].to_numpy(), atol=1e-9)
    for col in ("thorax_tilt", "thorax_tx"):
        np.testing.assert_allclose(s.values[:, s.columns.index(col)], df[col].to_numpy(), atol=1e-9)


def ref_trc(trial: TrialReader, src: Path) -> None:
    raw = pd.read_csv(src, skiprows=6, header=None).dropna(axis=1, how="all").to_numpy(dtype=float)
    m = one(trial, "/markers/")
    assert m.pos.shape[0] == len(raw) == 93
    np.testing.assert_allclose(m.pos.reshape(len(raw), -1), raw[:, 2:] * 1e-3, atol=1e-9)  # mm -> m
    np.testing.assert_allclose(m.t_ns / 1e9, raw[:, 1], atol=1e-9)


def ref_motive(trial: TrialReader, src: Path) -> None:
    raw = pd.read_csv(src, skiprows=7, header=None).to_numpy(dtype=float)
    pose = one(trial, "/poses/")
    assert len(pose.t_ns) == len(raw) == 250
    np.testing.assert_allclose(pose.t_ns / 1e9, raw[:, 1] - raw[0, 1], atol=1e-6)
    np.testing.assert_allclose(pose.position, raw[:, 6:9], atol=1e-9)  # Rotation X,Y,Z,W then Position X,Y,Z
    assert trial.metadata["imulog.trial"]["start_time"].startswith("2016-01-05T15:49:50.755")


def ref_xdf(trial: TrialReader, src: Path) -> None:
    pyxdf = pytest.importorskip("pyxdf")
    streams, _ = pyxdf.load_xdf(str(src), synchronize_clocks=False, dejitter_timestamps=False)
    for st in streams:
        n = len(st["time_stamps"])
        fmt = st["info"]["channel_format"][0]
        name = st["info"]["name"][0]
        if not n:
            continue
        key = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        topics = [t for t in trial.topics() if t.rsplit("/", 1)[-1] == key or t.rsplit("/", 1)[-1].startswith(key)]
        assert topics, (name, trial.topics())
        if fmt != "string":
            s = trial.read(topics[0])
            assert len(s.t_ns) == n
            np.testing.assert_allclose(s.values, np.asarray(st["time_series"], dtype=float), atol=1e-6)


def ref_xsens(trial: TrialReader, src: Path) -> None:
    every_unit_given(trial)
    osim = pytest.importorskip("opensim")
    stem = src.stem
    settings = osim.XsensDataReaderSettings()
    settings.set_trial_prefix(stem[:-8])
    settings.append_ExperimentalSensors(osim.ExperimentalSensor(stem[-8:], "imu"))
    reader = osim.XsensDataReader(settings)
    tables = reader.read(str(src.parent) + "/")
    acc = reader.getLinearAccelerationsTable(tables)
    imu = one(trial, "/imu/")
    assert len(imu.t_ns) == acc.getNumRows()
    ref = np.array([acc.getRowAtIndex(i)[0].to_numpy() for i in range(acc.getNumRows())])
    both = np.isfinite(ref) & np.isfinite(imu.acc)
    np.testing.assert_allclose(imu.acc[both], ref[both], atol=1e-5)
    text = src.read_text(errors="replace")
    if "Update Rate" in text:  # files without it state no rate (OpenSim assumes 40 Hz, imulog 100 Hz, with a warning)
        rate = float(acc.getTableMetaDataAsString("DataRate"))
        np.testing.assert_allclose(np.diff(imu.t_ns) / 1e9, 1 / rate, atol=1e-6)


# ------------------------------------------------------------------------------------------------ the cases
X = "xsens_mtmanager/"
CASES: dict[str, Callable[[TrialReader, Path], None] | None] = {
    "actigraph_count_csv/ActiGraph13.csv": ref_actilife_epochs,
    "actigraph_gt3x/example.gt3x": ref_gt3x,
    "actigraph_gt3x/example-IMU.csv": ref_actilife_imu,
    "actigraph_gt3x/exampleRAW.csv": ref_actilife_raw,
    "apdm_csv/apdm_format7.csv": ref_apdm_format7,
    "apdm_csv/imuData01.csv": ref_apdm_opensim,
    "axivity_csv/ax3_testfile_unix_timestamps.csv": ref_axivity_csv,
    "axivity_cwa/ax3_sample.cwa": ref_cwa,
    "axivity_cwa/ax6_sample.cwa": ref_cwa,
    "axivity_cwa/ax3_data.npz": None,  # skdh's reference decode (used by ref_cwa)
    "axivity_cwa/ax6_data.npz": None,
    "c3d_samples/MACsample.c3d": ref_c3d,
    "c3d_samples/pc_int.c3d": ref_c3d,
    "delsys_trigno/trigno_sample_header.csv": ref_delsys,
    "delsys_trigno/truncated_trigno_sample.csv": ref_delsys,
    "edf/trigno_emg.edf": ref_edf,
    "empatica_e4": ref_e4_folder,
    **{f"empatica_e4/{n}.csv": ref_e4_file for n in ("ACC", "BVP", "EDA", "HR", "IBI", "TEMP")},
    "geneactiv_bin/GENEActiv_testfile.bin": ref_geneactiv,
    "movella_dot_csv/bei_D4CA6EF17860_20210830_170505.csv": ref_movella_dot,
    "nilspod/NilsPodX-6F13_20210109_162824.bin": ref_nilspod_bin,
    "nilspod/NilsPodX-6F13_20210109_162824_data.csv": ref_nilspod_csv,
    "nilspod/NilsPodX-6F13_20210109_162824_header.json": refused_companion,
    "opensense_sto/MT_012005D6_009-quaternions_calibration_trial_Facing_negX.sto": ref_opensense_sto,
    "opensense_sto/myComplexTasksTrial_orientations.sto": ref_opensense_sto,
    "opensim_mot/inverse_kin.mot": ref_mot,
    "opensim_trc/markers.trc": ref_trc,
    "optitrack_motive/sample_optitrack_take.csv": ref_motive,
    "xdf/clock_resets.xdf": ref_xdf,
    "xdf/empty_streams.xdf": ref_xdf,
    "xdf/minimal.xdf": ref_xdf,
    **{
        X + n: ref_xsens
        for n in (
            "MT2022_ACC_00B42D4B.txt",
            "MT2022_ACC_GYRO_ROT_ALL_TAB_NAN_00B42D4B.txt",
            "MT2022_ACC_GYRO_ROT_EULER_TAB_00B42D4F.txt",
            "MT2022_ACC_GYRO_ROT_MAT_COMMA_00B42D4B.txt",
            "MT2022_ACC_GYRO_ROT_MAT_SEMICOLON_00B42D4B.txt",
            "MT2022_ACC_GYRO_ROT_MAT_SPACE_00B42D4B.txt",
            "MT46_01-000_00B42D4D.txt",
            "MT46_01-000_00B42D4E.txt",
            "MT_01200312-002-000_00B474BA.txt",
            "MT_01200454_000-000_00B40DE4.txt",
            "MT_012005D6_031-000_00B421AF.txt",
            "MT_012005D6_031-000_00B4227B.txt",
        )
    },
}


@pytest.fixture(scope="module")
def devices(shared_data: Path):
    yield shared_data / "devices"
    for p in _TMP:
        p.unlink(missing_ok=True)


def test_every_shared_file_has_a_case(devices: Path):
    files = {
        p.relative_to(devices).as_posix()
        for p in devices.rglob("*")
        if p.is_file() and not p.name.startswith(COMPANIONS)
    }
    assert files - set(CASES) == set(), "files in shared/data/devices without an acceptance case"
    assert {c for c in CASES if "." in Path(c).name} - files == set(), "cases without their file"


@pytest.mark.parametrize("name", [c for c, ref in CASES.items() if ref is not None])
def test_converts_passes_doctor_and_matches_reference(devices: Path, tmp_path: Path, name: str):
    src = devices / name
    check = CASES[name]
    if check is refused_companion:
        refused_companion(src, tmp_path)
        return
    with convert(src, tmp_path) as trial:
        check(trial, src)
