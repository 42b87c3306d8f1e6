"""The orientation and align steps end to end: simulated trial -> MCAP archive -> CLI -> derived channels."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from read_spy import record_reads

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.process import alignment as al
from imulog.process import quaternion as Q
from imulog.simulate import simulate


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    sim = simulate("r2g", seed=4, repetitions=8)
    path = tmp_path_factory.mktemp("align") / "trial.mcap"
    write_trial(path, sim.recording)
    return path, sim


def _ok(result):
    assert result.exit_code == 0, result.output + repr(result.exception)
    return result.output


def test_orientation_then_align_cli(trial):
    path, sim = trial
    runner = CliRunner()
    _ok(runner.invoke(cli, ["process", "orientation", str(path)]))
    out = _ok(runner.invoke(cli, ["process", "align", str(path), "--window", "60", "--drift"]))
    assert "offset" in out
    with TrialReader(path) as t:
        topics = set(t.topics())
        rec = t.metadata["imulog.alignment"]
        ori = t.read("/derived/orientation/wrist")
        lin = t.read("/derived/acc_global/wrist")
        pose = t.read("/derived/vicon/cluster_pose")
        omega = t.read("/derived/vicon/angular_velocity")
        q_ref = t.read("/derived/reference/orientation/wrist")
        imu = t.read("/imu/wrist")
    assert {
        "/derived/orientation_static/wrist",
        "/derived/reference/gyr/wrist",
        "/derived/reference/acc_global/wrist",
    } <= topics
    assert "/derived/static/wrist" not in topics  # owned by the segmentation step
    assert np.array_equal(ori.t_ns, imu.t_ns) and ori.columns == ["qw", "qx", "qy", "qz"]
    assert lin.units == ["m/s^2"] * 3
    assert omega.columns == ["wx", "wy", "wz"] and len(pose) > 0.9 * len(omega)
    truth = sim.truth
    assert rec["reference"] == "/markers/vicon" and rec["imu"] == "/imu/wrist"
    est = al.device_to_reference(imu.t_ns, rec)
    assert np.abs(est - truth.imu_t_ref_ns).max() < 10_000_000
    assert abs(rec["drift_ppm"] - truth.alignment["drift_ppm"]) < 10.0
    assert np.rad2deg(Q.angle_between(rec["rotation_imu_to_cluster"], truth.alignment["rotation_imu_to_cluster"])) < 1.0
    # the resampled orientation is on the Vicon clock (100 Hz) and, rotated to world, matches truth
    assert set(np.diff(q_ref.t_ns)) <= {10_000_000}
    q_world = Q.multiply(rec["rotation_global_to_world"], q_ref.values)
    true_q = np.array([np.interp(q_ref.t_ns, truth.t_ns, truth.orientation[:, k]) for k in range(4)]).T
    err = np.rad2deg(Q.angle_between(q_world, Q.normalize(true_q)))
    assert np.sqrt(np.mean(err**2)) < 3.0
    # a second identical run writes nothing
    out2 = _ok(runner.invoke(cli, ["process", "orientation", str(path)]))
    assert "unchanged" in out2


def test_madgwick_backend_and_errors(trial):
    path, _ = trial
    runner = CliRunner()
    _ok(runner.invoke(cli, ["process", "orientation", str(path), "--backend", "madgwick", "--beta", "0.03"]))
    with TrialReader(path) as t:
        runs = [r for r in t.runs().values() if str(r.get("step", "")).startswith("orientation")]
    assert runs[-1]["algorithm"] == "imulog.orientation.madgwick" and runs[-1]["params"]["beta"] == 0.03
    bad = runner.invoke(cli, ["process", "orientation", str(path), "--imu", "ankle"])
    assert bad.exit_code != 0 and "no channel /imu/ankle" in bad.output
    bad = runner.invoke(cli, ["process", "align", str(path), "--markers", "nope"])
    assert bad.exit_code != 0 and "/markers/nope" in bad.output


def test_align_short_real_recording_with_foot_markers(shared_data, tmp_path):
    """gaitmap (38.7 s, IMU and mocap already synchronised, foot markers L_/R_TOE, FCC, FM5, no O/X/Y): the
    default align finds each IMU's own foot by itself (the other foot is the runner-up), the lag is ~0, and
    the one window is no reason to grade it poor (its unknown drift moves its ends by < 1 ms at 50 ppm; a
    foot whose markers reproduce the gyroscope at 0.89 is still poor for that); explicit markers still override
    and name missing ones."""
    from imulog.converters import convert_files

    path = tmp_path / "gaitmap.mcap"
    write_trial(path, convert_files(sorted((shared_data / "gaitmap_foot").glob("*_sample.csv"))))
    runner = CliRunner()
    for imu, side, other in (("left_sensor", "L_", "R_"), ("right_sensor", "R_", "L_")):
        out = _ok(runner.invoke(cli, ["process", "align", str(path), "--imu", imu]))
        with TrialReader(path) as t:
            rec = t.metadata[f"imulog.alignment.{imu}"]  # each foot's own record (two IMUs in the trial)
        chosen = rec["cluster"]["markers"]
        assert len(chosen) >= 3 and all(m.startswith(side) for m in chosen), out
        assert all(m.startswith(other) for m in rec["cluster"]["runner_up"]["markers"])
        assert abs(rec["offset_ns"]) < 20_000_000 and rec["score"] > 0.8  # the data set is synchronised
        # 38.7 s, not three 30-s windows: the drift comes from 5-s windows over the whole trial with its
        # uncertainty, applied or said to be not estimable (issue 27); graded from the residuals (issue 32)
        assert len(rec["windows"]) >= 3 and rec["drift_uncertainty_ppm"] is not None and "runner-up" in out
        assert rec["drift_estimated"] or "not estimable" in rec["drift_note"]
        assert not any("window" in r for r in rec["quality_reasons"]), rec["quality_reasons"]
    bad = runner.invoke(cli, ["process", "align", str(path), "--imu", "left_sensor", "--cluster-markers", "A,B,C"])
    assert bad.exit_code == 1 and "/markers/mocap" in bad.output and "A, B, C" in bad.output
    assert "Traceback" not in bad.output
    svd = ["--cluster-markers", "L_FCC,L_TOE,L_FM5"]
    _ok(runner.invoke(cli, ["process", "align", str(path), "--imu", "left_sensor", *svd]))
    with TrialReader(path) as t:
        rec = t.metadata["imulog.alignment.left_sensor"]
        assert t.metadata["imulog.alignment"] == rec  # the first IMU aligned: the trial's main record too
    assert rec["cluster"]["selection"] == "given" and abs(rec["offset_ns"]) < 20_000_000


def test_align_reads_the_imu_only_around_the_markers(tmp_path, monkeypatch):
    """An IMU that records long after the markers stop (a lab session, then a week at home) is read only around
    the markers' span (issue 24: a day's wrist took 3.2 GB to align on an hour of markers), with the alignment it
    gave reading every sample."""
    import dataclasses

    from imulog.steps.align import MARGIN_S, run_align

    sim = simulate("r2g", seed=4, repetitions=4)
    imu = sim.recording.imus[0]
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) * 1e-9)
    extra = int((2 * MARGIN_S + 120.0) * rate)  # still on a table after the session, beyond the margin
    t_more = imu.t_ns[-1] + np.round(np.arange(1, extra + 1) * 1e9 / rate).astype(np.int64)
    longer = dataclasses.replace(
        imu,
        t_ns=np.concatenate([imu.t_ns, t_more]),
        acc=np.vstack([imu.acc, np.tile([0.0, 0.0, 9.81], (extra, 1))]),
        gyr=np.vstack([imu.gyr, np.zeros((extra, 3))]),
        mag=None if imu.mag is None else np.vstack([imu.mag, np.tile(imu.mag[-1], (extra, 1))]),
    )
    whole = write_trial(tmp_path / "whole.mcap", dataclasses.replace(sim.recording, imus=[longer]))
    long_ = write_trial(tmp_path / "long.mcap", dataclasses.replace(sim.recording, imus=[longer]))
    with monkeypatch.context() as patch:  # the previous reading: every IMU sample
        patch.setattr("imulog.steps.align.imu_span", lambda *a: (None, None))
        run_align(whole)
    reads = record_reads(monkeypatch)
    run_align(long_)
    imu_reads = [r for r in reads if r[0] == "/imu/wrist"]
    assert imu_reads and all(r[2] is not None and r[2] < t_more[-1] for r in imu_reads), imu_reads
    with TrialReader(whole) as a, TrialReader(long_) as b:
        ra, rb = a.metadata["imulog.alignment"], b.metadata["imulog.alignment"]
        ga, gb = a.read("/derived/reference/gyr/wrist"), b.read("/derived/reference/gyr/wrist")
    for key in ("offset_ns", "drift_ppm", "quality"):
        assert ra[key] == rb[key], key
    for key in ("rotation_imu_to_cluster", "rotation_global_to_world"):  # less of the still tail is seen: 3e-6
        assert (ra[key] is None) == (rb[key] is None), key
        if ra[key] is not None:
            np.testing.assert_allclose(ra[key], rb[key], atol=1e-5, err_msg=key)  # 1e-5: 0.002 deg
    assert np.array_equal(ga.t_ns, gb.t_ns) and np.allclose(ga.values, gb.values, atol=1e-6, equal_nan=True)
