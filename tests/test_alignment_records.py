"""One rule for every alignment path: in a trial with several IMUs each IMU's alignment is its own record
(``imulog.alignment.{imu}``, cluster channels ``/derived/vicon/cluster_pose/{imu}``), whether it was aligned on a
rigid body's poses or on markers, one IMU at a time or as a whole setup; ``imulog.alignment`` stays the first IMU
aligned. Before, aligning IMUs one at a time on poses (or ``--imu`` on markers) replaced ``imulog.alignment`` each
time, so only the last IMU kept an alignment, and a second IMU's orientation evaluation named (and hashed)
``imulog.alignment`` instead of its own record. Trials: :func:`imulog.simulate.setup.simulate_setup` (upper arm,
forearm and trunk IMUs on one station clock, 0.3217 s and 40 ppm off the optical clock), with one rigid body per
IMU (``rigid_bodies``) or with the markers."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.archive.metadata import record_hash
from imulog.cli import cli
from imulog.process import quaternion as quat
from imulog.process.alignment_clock import device_to_reference
from imulog.simulate.setup import simulate_setup
from imulog.steps.common import alignment_for, alignment_writes

MS = 1_000_000


def lag_error_ns(record: dict, sim, name: str) -> float:
    """The largest error of ``record``'s clock over the IMU's samples against the simulated station clock."""
    t = next(s.t_ns for s in sim.recording.imus if s.name == name)
    return float(np.max(np.abs(device_to_reference(t, record) - device_to_reference(t, sim.alignment))))


def run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


@pytest.fixture(scope="module")
def bodies(tmp_path_factory):
    sim = simulate_setup(seed=0, duration_s=30.0, rigid_bodies=True)
    path = tmp_path_factory.mktemp("bodies") / "bodies.mcap"
    write_trial(path, sim.recording, attach_sources=False)
    return path, sim


def test_the_simulated_rigid_bodies_carry_each_imu(bodies):
    _, sim = bodies
    rec = sim.recording
    assert not rec.markers and [p.topic for p in rec.poses] == [f"/poses/{s.name}_body" for s in rec.imus]
    for s, p in zip(rec.imus, rec.poses, strict=True):
        q_s2w = sim.arm.truth.q_world_sensor[s.name]
        back = quat.multiply(p.orientation, np.broadcast_to(sim.imu_to_body[s.name], q_s2w.shape))
        assert np.max(np.abs(np.abs(np.sum(back * q_s2w, axis=1)) - 1)) < 1e-9  # body-to-world * IMU-to-body


def test_imus_aligned_one_at_a_time_on_poses_keep_their_own_records(bodies):
    path, sim = bodies
    out = run("process", "align", path, "--imu", "upper_arm", "--poses", "upper_arm_body")
    assert out.startswith(f"{path}: upper_arm offset")  # among several IMUs, the line names the IMU
    with TrialReader(path) as t:
        first = dict(t.metadata["imulog.alignment.upper_arm"])
        main = dict(t.metadata["imulog.alignment"])
    out = run("process", "align", path, "--imu", "forearm", "--poses", "forearm_body")
    assert out.startswith(f"{path}: forearm offset") and "rigid body /poses/forearm_body" in out
    with TrialReader(path) as t:
        meta, topics = t.metadata, t.topics()
    # the first IMU's alignment is still there, unchanged, and still the trial's main record
    assert record_hash(meta["imulog.alignment.upper_arm"]) == record_hash(first)
    assert record_hash(meta["imulog.alignment"]) == record_hash(main) and main["imu"] == "/imu/upper_arm"
    for name in ("upper_arm", "forearm"):
        rec = alignment_for(meta, f"/imu/{name}")
        assert rec["imu"] == f"/imu/{name}" and rec["reference"] == f"/poses/{name}_body"
        assert lag_error_ns(rec, sim, name) < 1 * MS
        truth = np.asarray(sim.imu_to_body[name])
        angle = np.degrees(2 * np.arccos(min(1.0, abs(float(np.dot(rec["rotation_imu_to_cluster"], truth))))))
        assert angle < 1.0, (name, angle)  # each IMU got its own body's rotation
        assert f"/derived/vicon/cluster_pose/{name}" in topics
    assert "/derived/vicon/cluster_pose" not in topics  # no single cluster channel for the last IMU aligned
    info = run("info", path)
    assert "alignment (2 IMUs on /poses/forearm_body, /poses/upper_arm_body):" in info
    assert "  forearm: offset" in info and "  upper_arm: offset" in info


def test_a_second_imus_orientation_evaluation_reads_and_hashes_its_own_record(bodies):
    path, sim = bodies
    run("process", "align", path, "--imu", "upper_arm", "--poses", "upper_arm_body")
    run("process", "align", path, "--imu", "forearm", "--poses", "forearm_body")
    run("process", "orientation", path, "--imu", "upper_arm")
    run("process", "orientation", path, "--imu", "forearm")
    run("evaluate", path, "--imu", "upper_arm")
    run("evaluate", path, "--imu", "forearm")
    with TrialReader(path) as t:
        meta = t.metadata
        runs = {r["step"]: r for r in t.runs().values()}
    own = meta["imulog.alignment.forearm"]
    assert set(runs["evaluate_orientation:forearm"]["inputs"]) >= {"metadata:imulog.alignment.forearm"}
    assert "metadata:imulog.alignment" not in runs["evaluate_orientation:forearm"]["inputs"]
    assert meta["imulog.orientation_evaluation.forearm"]["alignment"]["offset_ns"] == own["offset_ns"]
    assert meta["imulog.orientation_evaluation.forearm"]["reference"] == "/poses/forearm_body"
    assert meta["imulog.orientation_evaluation.forearm"]["heading_free_rmse_deg"] < 5.0
    # both bodies relate the two IMUs' headings (the trunk, which barely turns, has no body alignment): each
    # corrected heading within 2 deg of the truth (median over the trial), on each IMU's own clock
    out = run("process", "heading", path, "--imu", "upper_arm", "--imu", "forearm")
    assert "one heading frame for upper_arm, forearm: optical" in out, out
    with TrialReader(path) as t:
        for name in ("upper_arm", "forearm"):
            o = t.read(f"/derived/orientation/{name}")
            corr = np.asarray(t.metadata["imulog.heading"]["imus"][name]["correction"], dtype=np.float64)
            q = quat.multiply(np.broadcast_to(corr, o.values.shape), o.values)
            t_ref = device_to_reference(o.t_ns, t.metadata[f"imulog.alignment.{name}"])
            k = np.clip(np.searchsorted(sim.arm.truth.t_ns, t_ref), 0, len(sim.arm.truth.t_ns) - 1)
            yaw = [
                np.degrees(np.arctan2(x[:, 1], x[:, 0]))
                for x in (
                    quat.rotate(qq, np.array([1.0, 0.0, 0.0])) for qq in (q, sim.arm.truth.q_world_sensor[name][k])
                )
            ]
            assert abs(np.median((yaw[0] - yaw[1] + 180) % 360 - 180)) < 2.0, name
    # re-aligning the forearm (offset only) puts its evaluation out of date, not the upper arm's
    run("process", "align", path, "--imu", "forearm", "--poses", "forearm_body", "--no-drift")
    assert new_runs(path, "evaluate", "--imu", "upper_arm") == []  # up to date: nothing written
    assert new_runs(path, "evaluate", "--imu", "forearm") == ["evaluate_orientation:forearm"]


def new_runs(path, *args) -> list[str]:
    """The steps of the runs the command ``args`` (on ``path``) added to the trial."""
    with TrialReader(path) as t:
        last = max(t.runs())
    run(args[0], path, *args[1:])
    with TrialReader(path) as t:
        return [r["step"] for n, r in t.runs().items() if n > last]


def test_imus_aligned_one_at_a_time_on_markers_keep_their_own_records(tmp_path):
    sim = simulate_setup(seed=1, duration_s=25.0)
    path = write_trial(tmp_path / "markers.mcap", sim.recording, attach_sources=False)
    run("process", "align", path, "--imu", "forearm")
    run("process", "align", path, "--imu", "upper_arm")
    with TrialReader(path) as t:
        meta, topics = t.metadata, t.topics()
    assert meta["imulog.alignment"]["imu"] == "/imu/forearm"  # the first aligned stays the main record
    for name in ("forearm", "upper_arm"):
        rec = meta[f"imulog.alignment.{name}"]
        assert all(m.startswith(f"{name}_") for m in rec["cluster"]["markers"]), rec["cluster"]["markers"]
        assert rec["imu"] == f"/imu/{name}"  # (alone on 25 s the upper arm's drift is poorly known: flagged poor)
        assert f"/derived/vicon/cluster_pose/{name}" in topics


def test_the_rule_for_one_imu_several_and_older_archives():
    one, three = ["/imu/wrist"], ["/imu/a", "/imu/b", "/imu/c"]
    rec_a, rec_b = {"imu": "/imu/a", "offset_ns": 1}, {"imu": "/imu/b", "offset_ns": 2}
    assert alignment_writes(one, {}, "wrist", {"imu": "/imu/wrist"}) == (
        {"imulog.alignment": {"imu": "/imu/wrist"}},
        "",
    )
    assert alignment_writes(three, {}, "a", rec_a) == ({"imulog.alignment.a": rec_a, "imulog.alignment": rec_a}, "/a")
    # an older archive whose only record is a's (aligned alone before per-IMU records): b never replaces it
    older = {"imulog.alignment": rec_a}
    assert alignment_writes(three, older, "b", rec_b) == ({"imulog.alignment.b": rec_b}, "/b")
    assert alignment_for({**older, "imulog.alignment.b": rec_b}, "/imu/a") == rec_a
    assert alignment_for({**older, "imulog.alignment.b": rec_b}, "/imu/b") == rec_b
    # re-aligning the main IMU updates both of its records
    assert set(alignment_writes(three, older, "a", rec_a)[0]) == {"imulog.alignment.a", "imulog.alignment"}


def _t_ns(path) -> np.ndarray:
    import csv

    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return np.array([int(r[rows[0].index("t_ns")]) for r in rows[1:]], dtype=np.int64)


def test_exports_put_each_imu_on_its_own_clock_and_name_the_command_for_the_others(bodies, tmp_path):
    path, _ = bodies
    run("process", "align", path, "--imu", "upper_arm", "--poses", "upper_arm_body")
    run("process", "align", path, "--imu", "forearm", "--poses", "forearm_body")
    run("export", path, "-t", "/imu/forearm", "-o", tmp_path / "ref.csv", "--clock", "reference")
    run("export", path, "-t", "/imu/forearm", "-o", tmp_path / "dev.csv", "--clock", "device", "--imu", "forearm")
    with TrialReader(path) as t:
        t_dev = t.read("/imu/forearm").t_ns
        own, other = t.metadata["imulog.alignment.forearm"], t.metadata["imulog.alignment"]
    shift = _t_ns(tmp_path / "ref.csv") - _t_ns(tmp_path / "dev.csv")
    assert np.max(np.abs(shift - (device_to_reference(t_dev, own) - t_dev))) <= 1  # the forearm's own clock
    assert np.max(np.abs(shift - (device_to_reference(t_dev, other) - t_dev))) > 10_000  # not the upper arm's
    # the trunk has no alignment: the error names the command that aligns it on a rigid body (one IMU at a time)
    result = CliRunner().invoke(
        cli, ["export", str(path), "-t", "/imu/trunk", "-o", str(tmp_path / "t.csv"), "--clock", "reference"]
    )
    assert result.exit_code == 1 and not (tmp_path / "t.csv").exists()
    assert f"run `imulog process align {path} --imu trunk --poses BODY (one of " in result.output, result.output


def test_several_imus_are_paired_with_their_bodies_by_the_data(tmp_path):
    """``imulog process align`` on IMUs and rigid bodies whose names say nothing (body_1..3, shuffled): each IMU
    with its own body, one to one; the trunk, which barely turns, with none, and the step says why."""
    sim = simulate_setup(seed=0, duration_s=30.0, rigid_bodies=True)
    names = {"upper_arm": "body_3", "forearm": "body_1", "trunk": "body_2"}
    for pose, imu in zip(sim.recording.poses, ("upper_arm", "forearm", "trunk"), strict=True):
        assert pose.topic == f"/poses/{imu}_body"
        pose.topic = f"/poses/{names[imu]}"
    path = write_trial(tmp_path / "bodies.mcap", sim.recording, attach_sources=False)
    out = run("process", "align", path)
    assert "3 IMUs aligned" in out and "trunk: offset" in out and "(shared clock of upper_arm, forearm)" in out, out
    with TrialReader(path) as t:
        meta, topics = t.metadata, t.topics()
        t_trunk = t.read("/imu/trunk").t_ns
    for imu in ("upper_arm", "forearm"):
        rec = meta[f"imulog.alignment.{imu}"]
        assert rec["reference"] == f"/poses/{names[imu]}" and lag_error_ns(rec, sim, imu) < 1 * MS
        assert f"/derived/vicon/cluster_pose/{imu}" in topics
    # the trunk, which no body turns like, shares the station clock with the two (one source file, one set of time
    # stamps: imulog.process.alignment_setup.recording_groups): their clock, named as such, no frame, graded poor
    trunk = meta["imulog.alignment.trunk"]
    assert trunk["clock"] == "shared" and trunk["clock_of"] == ["upper_arm", "forearm"] and trunk["reference"] is None
    assert trunk["signal"] == "clock of the recording" and trunk["rotation_imu_to_cluster"] is None
    assert (
        trunk["quality"] == "poor"
        and "no rigid body turns like this IMU (no body aligns" in trunk["quality_reasons"][0]
    )
    assert lag_error_ns(trunk, sim, "trunk") < 1 * MS
    assert "/derived/vicon/cluster_pose/trunk" not in topics
    assert set(meta["imulog.alignment"]["unpaired"]) == {"trunk"}
    exported = CliRunner().invoke(
        cli, ["export", str(path), "-t", "/imu/trunk", "-o", str(tmp_path / "t.csv"), "--clock", "reference"]
    )
    assert exported.exit_code == 0, exported.output
    assert "IMU 'trunk' has no alignment of its own; mapped with the clock of its recording (upper_arm, forearm)" in (
        exported.stderr
    )
    assert np.array_equal(_t_ns(tmp_path / "t.csv"), device_to_reference(t_trunk, trunk))
    assert meta["imulog.alignment"]["imu"] == "/imu/upper_arm"  # the first IMU paired is the main record
    assert "unchanged" in run("process", "align", path)  # the same inputs: nothing recomputed
    # evaluate, no --imu: every IMU aligned on a body has its orientation evaluated, each against its own body;
    # the trunk, with no body, is named and skipped
    run("process", "orientation", path)
    out = run("evaluate", path)
    assert f"{path}: /imu/upper_arm orientation against /poses/body_3" in out
    assert f"{path}: /imu/forearm orientation against /poses/body_1" in out
    assert f"{path}: trunk: not evaluated: no alignment on a rigid body's poses" in out
    with TrialReader(path) as t:
        evaluated = {k: v["reference"] for k, v in t.metadata.items() if k.startswith("imulog.orientation_evaluation")}
    assert evaluated == {
        "imulog.orientation_evaluation": "/poses/body_3",
        "imulog.orientation_evaluation.forearm": "/poses/body_1",
    }
    info = run("info", path)
    assert "alignment (3 IMUs on /poses/body_1, /poses/body_3):" in info
    assert "trunk: offset" in info and "(shared clock of upper_arm, forearm), no rigid body, no frame alignment" in info


def test_an_imu_of_another_recording_takes_no_other_clock(tmp_path):
    """The same setup with the trunk IMU from a file and clock of its own (another source, other time stamps): no
    body aligns it and no clock is guessed for it (a record without a clock, the export refused)."""
    sim = simulate_setup(seed=0, duration_s=30.0, rigid_bodies=True)
    trunk = next(s for s in sim.recording.imus if s.name == "trunk")
    sim.recording.metadata["imulog.device.trunk"]["source"] = trunk.meta["source"] = "trunk_imu.csv"
    trunk.t_ns = trunk.t_ns + 3_000_000  # another device's clock: its samples 3 ms later than the station's
    path = write_trial(tmp_path / "bodies.mcap", sim.recording, attach_sources=False)
    out = run("process", "align", path)
    assert "2 of 3 IMUs aligned" in out and "trunk: not aligned (no body aligns with it, 3 tried" in out, out
    with TrialReader(path) as t:
        rec = t.metadata["imulog.alignment.trunk"]  # no clock: a record that says why (replacing any older one)
    assert rec["quality"] == "failed" and "offset_ns" not in rec and "no body aligns" in rec["quality_reasons"][0]
    refused = CliRunner().invoke(
        cli, ["export", str(path), "-t", "/imu/trunk", "-o", str(tmp_path / "t.csv"), "--clock", "reference"]
    )
    assert refused.exit_code == 1 and "which could not be aligned (no body aligns with it" in refused.output
    assert not (tmp_path / "t.csv").exists()
    info = run("info", path)
    assert "alignment (2 of 3 IMUs on /poses/forearm_body, /poses/upper_arm_body):" in info
    assert "trunk: not aligned" in info


def test_a_record_without_a_clock_puts_no_imu_on_the_reference_clock():
    """A setup writes a record without ``offset_ns`` for an IMU it could not align (``quality: failed``); before,
    the exports' clock map took it as an offset of 0 and put that IMU on the reference clock unaligned."""
    from imulog.archive.alignment_records import alignments_from_metadata

    meta = {
        "imulog.alignment": {"imu": "/imu/a", "offset_ns": 5},
        "imulog.alignment.a": {"imu": "/imu/a", "offset_ns": 5},
        "imulog.alignment.b": {"imu": "/imu/b", "quality": "failed", "quality_reasons": ["no cluster"]},
    }
    assert set(alignments_from_metadata(meta)) == {"a"}
    assert set(alignments_from_metadata(meta, failed=True)) == {"a", "b"}  # imulog info lists it, with why


def test_the_export_provenance_names_a_recording_clock():
    """A BIDS sidecar's clock description (``TrialClock.record``) names an IMU on its recording's clock."""
    from imulog.archive.trial_clock import TrialClock

    shared = {"offset_ns": 5, "clock": "shared", "clock_of": ["upper_arm", "forearm"]}
    tc = TrialClock("t.mcap", "reference", None, {"upper_arm": {"offset_ns": 5}, "trunk": shared}, {}, set(), {})
    assert tc.record()["recording_clock"] == "trunk: clock of upper_arm, forearm"
    assert (
        "recording_clock"
        not in TrialClock("t.mcap", "reference", None, {"a": {"offset_ns": 5}}, {}, set(), {}).record()
    )
