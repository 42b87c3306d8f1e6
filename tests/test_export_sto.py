"""OpenSense .sto export, read back with the opensim package and compared with OpenSim's own files."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, append_derived, write_trial
from imulog.cli import cli
from imulog.export.sto import export_sto, format_sto, resample_orientation
from imulog.model import ImuStream, Recording, SignalStream
from imulog.process import quaternion as quat

osim = pytest.importorskip("opensim")


def _read_sto(path):
    """(time s, labels, {label: (N, 4) w,x,y,z}) through OpenSim's own reader."""
    table = osim.TimeSeriesTableQuaternion(str(path))
    labels = list(table.getColumnLabels())
    n = table.getNumRows()
    out = {label: np.empty((n, 4)) for label in labels}
    for i in range(n):
        row = table.getRowAtIndex(i)
        for j, label in enumerate(labels):
            q = row.getElt(0, j)
            out[label][i] = [q.get(k) for k in range(4)]
    return np.array(table.getIndependentColumn()), labels, out, table


def _two_imu_trial(path):
    rate, n = 100.0, 500
    t = np.arange(n, dtype=np.int64) * 10_000_000 + 2_000_000_000
    rng = np.random.default_rng(3)
    imus, streams = [], []
    for k, name in enumerate(("radius_r", "humerus_r")):
        rv = np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0)
        q = quat.from_rotation_vector(rv)
        imus.append(
            ImuStream(name, t + k * 3_000_000, acc=np.zeros((n, 3)), gyr=np.zeros((n, 3)), meta={"rate_hz": rate})
        )
        streams.append(
            SignalStream(f"/derived/orientation/{name}", t + k * 3_000_000, ["qw", "qx", "qy", "qz"], ["1"] * 4, q)
        )
    write_trial(path, Recording(imus=imus), overwrite=True)
    append_derived(path, streams, run={"step": "orientation", "algorithm": "test", "params": {}, "inputs": []})
    return t, [s.values for s in streams]


def test_sto_reads_back_in_opensim_equal_to_the_source(tmp_path):
    path = tmp_path / "arm.mcap"
    t, quats = _two_imu_trial(path)
    out = tmp_path / "arm.sto"
    with TrialReader(path) as trial:
        res = export_sto(trial, out, names={"humerus_r": "humerus_r_imu"})
    times, labels, data, table = _read_sto(out)
    assert labels == ["radius_r_imu", "humerus_r_imu"] and res.rows == len(t)
    assert float(table.getTableMetaDataAsString("DataRate")) == pytest.approx(100.0)
    np.testing.assert_allclose(times, (t - t[0]) / 1e9, atol=1e-12)  # the first sample is the trial's start
    # the first IMU's samples are the grid: its quaternions come back bit for bit (up to sign)
    got = data["radius_r_imu"] * np.sign(np.sum(data["radius_r_imu"] * quats[0], axis=1))[:, None]
    np.testing.assert_array_equal(got, quat.normalize(quats[0]))
    # the second IMU is 3 ms late: grid point i lies 70 % of the way from its sample i-1 to sample i
    q2 = quat.normalize(quats[1])
    expected = quat.slerp(q2[:-1], q2[1:], 0.7)
    err = quat.angle_between(data["humerus_r_imu"][1:], expected)
    assert np.max(err) < 1e-7 and np.isnan(data["humerus_r_imu"][0]).all()


def test_processed_trial_sto_has_gaps_as_nan_and_opensims_layout(processed_r2g, shared_data, tmp_path):
    out = tmp_path / "r2g.sto"
    result = CliRunner().invoke(cli, ["export", str(processed_r2g), "-o", str(out), "--name", "wrist=hand_r_imu"])
    assert result.exit_code == 0, result.output
    times, labels, data, _ = _read_sto(out)
    assert labels == ["hand_r_imu"]
    q = data["hand_r_imu"]
    gaps = np.isnan(q).any(axis=1)
    assert 0 < gaps.sum() < 0.05 * len(q)  # the simulated trial has 17 dropped-sample gaps
    np.testing.assert_allclose(np.linalg.norm(q[~gaps], axis=1), 1.0, atol=1e-12)
    with TrialReader(processed_r2g) as trial:
        ori = trial.read("/derived/orientation/wrist")
    assert len(q) >= len(ori)
    # header lines and cell layout as in OpenSim's own files (../shared/data/devices/opensense_sto)
    ours = out.read_text().splitlines()
    theirs = (shared_data / "devices/opensense_sto/myComplexTasksTrial_orientations.sto").read_text().splitlines()
    assert [line.split("=")[0] for line in ours[:5]] == [line.split("=")[0] for line in theirs[:5]]
    assert ours[5].split("\t")[0] == theirs[5].split("\t")[0] == "time"
    assert len(ours[6].split("\t")[1].split(",")) == len(theirs[6].split("\t")[1].split(",")) == 4


def test_opensims_own_file_reads_with_the_same_reader(shared_data):
    """Control: the helper reads OpenSim's file, so a failure above is ours, not the reader's."""
    times, labels, data, _ = _read_sto(shared_data / "devices/opensense_sto/myComplexTasksTrial_orientations.sto")
    assert len(labels) == 7 and len(times) == 6
    np.testing.assert_allclose(np.linalg.norm(data["pelvis_imu"], axis=1), 1.0, atol=1e-9)


def test_format_and_resample_are_pure():
    text = format_sto(np.array([0.0, 0.5]), ["a_imu"], [np.array([[1.0, 0, 0, 0], [0.0, 1, 0, 0]])], 2.0)
    assert text.splitlines()[0] == "DataRate=2.000000" and text.splitlines()[-1] == "0.5\t0,1,0,0"
    t = np.array([0, 10, 20, 60], dtype=np.int64)
    q = np.tile([1.0, 0, 0, 0], (4, 1))
    out = resample_orientation(t, q, np.array([5, 15, 40, 60, 70]), period_ns=10)
    assert (
        np.isfinite(out[:2]).all() and np.isnan(out[2]).all() and np.isfinite(out[3]).all() and np.isnan(out[4]).all()
    )


def test_no_orientation_is_a_one_line_error(tmp_path):
    path = tmp_path / "raw.mcap"
    t = np.arange(10, dtype=np.int64) * 10_000_000
    write_trial(path, Recording(imus=[ImuStream("wrist", t, acc=np.zeros((10, 3)), gyr=np.zeros((10, 3)))]))
    result = CliRunner().invoke(cli, ["export", str(path), "-o", str(tmp_path / "x.sto")])
    assert result.exit_code == 1 and "imulog process orientation" in result.output
    assert not (tmp_path / "x.sto").exists()
