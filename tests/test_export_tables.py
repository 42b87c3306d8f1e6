"""Parquet/CSV exports: one clock for every channel, units in names and field metadata, typed time."""

from __future__ import annotations

import json
import shutil
from datetime import datetime, timedelta, timezone

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.export import ClockError, channel_table, export_table
from imulog.model import ImuStream, Intervals, Recording
from imulog.process.alignment import device_to_reference, reference_to_device
from imulog.simulate import load_truth


def _small_trial(path, start_time: str | None, time_zone: str | None = None):
    t = np.arange(200, dtype=np.int64) * 10_000_000 + 5_000_000_000  # 2 s at 100 Hz, device clock from 5 s
    rng = np.random.default_rng(1)
    imu = ImuStream("wrist", t, acc=rng.normal(0, 1, (200, 3)), gyr=rng.normal(0, 1, (200, 3)))
    trial = {"subject": "S01", "trial": 1, "task": "r2g"}
    if start_time is not None:
        trial["start_time"] = start_time
        trial["time_zone"] = time_zone or "unknown (device local time)"
    phases = Intervals("/derived/phases/wrist", [5_500_000_000], [6_000_000_000], ["reach"], [1])
    write_trial(path, Recording(imus=[imu], metadata={"imulog.trial": trial}), overwrite=True)
    from imulog.archive import append_derived

    append_derived(path, [phases], run={"step": "manual", "algorithm": "test", "params": {}, "inputs": []})
    return t


def test_imu_table_has_units_in_names_and_field_metadata(processed_r2g, tmp_path):
    out = tmp_path / "wrist.parquet"
    with TrialReader(processed_r2g) as trial:
        res = export_table(trial, "/imu/wrist", out)
        imu = trial.read("/imu/wrist")
    table = pq.read_table(out)
    assert res.rows == table.num_rows == len(imu)
    assert table.column_names[:2] == ["t[s]", "t_ns"]  # no start_time recorded: no wall-clock column
    assert "acc_x[m/s^2]" in table.column_names and "gyr_z[rad/s]" in table.column_names
    assert "mag_y[uT]" in table.column_names
    field = table.schema.field("gyr_z[rad/s]")
    assert field.metadata[b"unit"] == b"rad/s" and field.metadata[b"name"] == b"gyr_z"
    np.testing.assert_array_equal(table["gyr_z[rad/s]"].to_numpy(), imu.gyr[:, 2])
    np.testing.assert_array_equal(table["t_ns"].to_numpy(), imu.t_ns)  # device clock = as recorded
    assert table.schema.metadata[b"clock"] == b"device"
    # seconds from the trial's first raw sample (the Vicon's, mapped onto the IMU clock)
    origin = int(table.schema.metadata[b"origin_ns"])
    np.testing.assert_allclose(table["t[s]"].to_numpy(), (imu.t_ns - origin) / 1e9)


def test_reference_clock_puts_imu_and_phases_on_the_vicon_clock(processed_r2g, tmp_path):
    """The IMU exported on the reference clock lies where the simulator's true clock map puts it."""
    truth = load_truth("recordings/sim/r2g_s00_t00_truth.json").alignment
    with TrialReader(processed_r2g) as trial:
        alignment = trial.metadata["imulog.alignment"]
        imu = trial.read("/imu/wrist")
        phases = trial.read("/derived/phases/wrist")
        ref = channel_table(trial, "/imu/wrist", clock="reference")
        ph_dev = channel_table(trial, "/derived/phases/wrist", clock="device")
        ph_ref = channel_table(trial, "/derived/phases/wrist", clock="reference")
        mk_dev = channel_table(trial, "/markers/vicon", clock="device")
        mk = trial.read("/markers/vicon")
    t_ref = ref["t_ns"].to_numpy()
    np.testing.assert_array_equal(t_ref, device_to_reference(imu.t_ns, alignment))
    true_ref = device_to_reference(imu.t_ns, truth)
    assert np.max(np.abs(t_ref - true_ref)) < 10_000_000  # within 10 ms of the true clock map
    # phases are stored on the reference clock (imulog.timing clock=reference): device export maps them back
    np.testing.assert_array_equal(ph_ref["start_ns"].to_numpy(), phases.start_ns)
    np.testing.assert_array_equal(ph_dev["start_ns"].to_numpy(), reference_to_device(phases.start_ns, alignment))
    np.testing.assert_array_equal(mk_dev["t_ns"].to_numpy(), reference_to_device(mk.t_ns, alignment))
    # seconds from start agree on both clocks (one origin) up to the clock drift, so the two CSVs line up
    drift_s = abs(float(alignment.get("drift_ppm") or 0.0)) * 1e-6 * 100.0  # at most 100 s into the trial
    np.testing.assert_allclose(ph_dev["start[s]"].to_numpy(), ph_ref["start[s]"].to_numpy(), atol=drift_s + 2e-9)
    assert ph_ref.column_names[:2] == ["start[s]", "start_ns"]
    assert ph_ref["label"].to_pylist()[:4] == ["reach", "lift", "return_bottle", "return_hand"]


def test_reference_clock_without_alignment_is_refused(tmp_path):
    path = tmp_path / "t.mcap"
    _small_trial(path, None)
    with TrialReader(path) as trial, pytest.raises(ClockError, match=r"no /markers/\* or /poses/\* channel"):
        channel_table(trial, "/imu/wrist", clock="reference")  # IMU only: no reference clock to align on
    from imulog.model import MarkerStream

    with TrialReader(path) as trial:
        imu = trial.read("/imu/wrist")
    markers = MarkerStream("vicon", imu.t_ns[::2].copy(), ["m1"], np.zeros((100, 1, 3)))
    write_trial(path, Recording(imus=[imu], markers=[markers]), overwrite=True)  # optical, not aligned yet
    out = tmp_path / "w.csv"
    result = CliRunner().invoke(cli, ["export", str(path), "-t", "/imu/wrist", "-o", str(out), "--clock", "reference"])
    assert result.exit_code == 1
    assert "imulog process align" in result.output and len(result.output.strip().splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob(".w.csv*"))  # nothing half-written


@pytest.mark.parametrize(
    ("start", "tz"),
    [
        ("2026-03-04T10:20:30.250+01:00", "+01:00"),
        ("2026-03-04T10:20:30.250Z", "UTC"),
        ("2026-03-04T10:20:30.250", None),
    ],
)
def test_time_column_is_a_typed_timestamp_from_the_start_time(tmp_path, start, tz):
    path = tmp_path / "t.mcap"
    t = _small_trial(path, start, tz)
    with TrialReader(path) as trial:
        table = channel_table(trial, "/imu/wrist")
        phases = channel_table(trial, "/derived/phases/wrist")
    assert table.column_names[:3] == ["time", "t[s]", "t_ns"]
    assert table.schema.field("time").type == pa.timestamp("ns", tz=tz)
    times = table["time"].to_pandas()
    first = pd.Timestamp(datetime.fromisoformat(start.replace("Z", "+00:00")))
    assert times.iloc[0] == first
    assert times.iloc[-1] - times.iloc[0] == pd.Timedelta(nanoseconds=int(t[-1] - t[0]))
    assert phases["start_time"].to_pandas().iloc[0] == first + pd.Timedelta(milliseconds=500)
    if tz is not None:
        expected = datetime(2026, 3, 4, 10, 20, 30, 250_000, tzinfo=timezone(timedelta(hours=1 if tz != "UTC" else 0)))
        assert times.iloc[0].to_pydatetime() == expected


def test_csv_export_reads_back_in_pandas(processed_r2g, tmp_path):
    out = tmp_path / "phases.csv"
    result = CliRunner().invoke(
        cli,
        ["export", str(processed_r2g), "-t", "/derived/phases/wrist", "-o", str(out), "--clock", "reference", "--json"],
    )
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["rows"] == 20 and report["clock"] == "reference" and report["format"] == "csv"
    df = pd.read_csv(out)
    assert list(df.columns[:3]) == ["start[s]", "start_ns", "end[s]"]
    np.testing.assert_allclose(df["duration[s]"], df["end[s]"] - df["start[s]"], atol=1e-6)


def test_real_gaitmap_export_equals_the_source_file(shared_data, tmp_path):
    """gaitmap's real foot IMU CSV -> archive -> CSV export: the same numbers, units in the names."""
    result = CliRunner().invoke(cli, ["convert", str(shared_data / "gaitmap_foot"), "-o", str(tmp_path / "gm")])
    assert result.exit_code == 0, result.output
    out = tmp_path / "left.csv"
    mcap = next((tmp_path / "gm").glob("*.mcap"))
    result = CliRunner().invoke(cli, ["export", str(mcap), "-t", "/imu/left_sensor", "-o", str(out)])
    assert result.exit_code == 0, result.output
    df = pd.read_csv(out)
    src = pd.read_csv(shared_data / "gaitmap_foot" / "imu_sample.csv", header=[0, 1], index_col=0)["left_sensor"]
    np.testing.assert_allclose(df["acc_x[m/s^2]"], src["acc_x"], rtol=1e-12)
    np.testing.assert_allclose(np.degrees(df["gyr_z[rad/s]"]), src["gyr_z"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.diff(df["t[s]"]), 1 / 204.8, rtol=1e-6)


def test_export_streams_blocks_and_equals_a_whole_read(processed_r2g, tmp_path):
    """The block-by-block Parquet writer gives the same table as one read, also for a time range."""
    with TrialReader(processed_r2g) as trial:
        info = trial.channel("/imu/wrist")
        lo, hi = info.start_ns + 10**10, info.start_ns + 3 * 10**10
        export_table(trial, "/imu/wrist", tmp_path / "w.parquet", start_ns=lo, end_ns=hi)
        whole = channel_table(trial, "/imu/wrist", start_ns=lo, end_ns=hi)
    assert pq.read_table(tmp_path / "w.parquet").equals(whole)
    assert whole["t_ns"].to_numpy().min() >= lo and whole["t_ns"].to_numpy().max() < hi


def test_bad_output_suffix_is_one_line(processed_r2g, tmp_path):
    copy = tmp_path / "t.mcap"
    shutil.copy(processed_r2g, copy)
    result = CliRunner().invoke(cli, ["export", str(copy), "-o", str(tmp_path / "x.txt")])
    assert result.exit_code == 2 and "give --to" in result.output
    result = CliRunner().invoke(cli, ["export", str(copy), "-o", str(tmp_path / "x.csv")])
    assert result.exit_code == 2 and "--topic" in result.output


def test_real_actigraph_time_column_matches_actilifes_own_export(shared_data, tmp_path):
    """A real .gt3x (start time with its UTC offset) -> archive -> Parquet: the wall clock ActiLife prints."""
    folder = shared_data / "devices" / "actigraph_gt3x"
    mcap = tmp_path / "ag.mcap"
    result = CliRunner().invoke(cli, ["convert", str(folder / "example.gt3x"), "-o", str(mcap)])
    assert result.exit_code == 0, result.output
    with TrialReader(mcap) as trial:
        topic = next(t for t in trial.topics() if t.startswith("/imu/") and not t.endswith("_imu"))
    out = tmp_path / "ag.parquet"
    assert CliRunner().invoke(cli, ["export", str(mcap), "-t", topic, "-o", str(out)]).exit_code == 0
    table = pq.read_table(out)
    assert table.schema.field("time").type == pa.timestamp("ns", tz="-05:00")
    times = table["time"].to_pandas()
    # ActiLife's CSV of the same recording: "Start Time 08:58:00", "Start Date 2/14/2019" (local time, -05:00)
    assert times.iloc[0] == pd.Timestamp("2019-02-14T08:58:00-05:00")
    np.testing.assert_allclose(np.diff(table["t[s]"].to_numpy()), 1 / 90, rtol=1e-6)  # 90 Hz
    raw = pd.read_csv(folder / "exampleRAW.csv", skiprows=10)  # g, 3 decimals
    acc_g = np.column_stack([table[f"acc_{a}[m/s^2]"].to_numpy() for a in "xyz"])[: len(raw)] / 9.80665
    np.testing.assert_allclose(acc_g, raw.to_numpy(), atol=5.01e-4)


def test_export_refuses_several_topics_for_one_table_and_a_topic_for_sto(tmp_path, processed_r2g):
    """Two -t used to export only the last one silently; --topic with sto was ignored."""
    out = tmp_path / "two.parquet"
    result = CliRunner().invoke(
        cli, ["export", str(processed_r2g), "-t", "/imu/wrist", "-t", "/vicon/markers", "-o", str(out)]
    )
    assert result.exit_code == 2
    assert "one channel per file, got 2 (/imu/wrist, /vicon/markers)" in result.output
    assert not out.exists()
    sto = tmp_path / "trial.sto"
    result = CliRunner().invoke(cli, ["export", str(processed_r2g), "-t", "/imu/wrist", "-o", str(sto)])
    assert result.exit_code == 2 and "takes no --topic" in result.output and not sto.exists()
