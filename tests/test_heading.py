"""One heading frame per trial (issue 27): magnetometer, optical clusters, a declared static pose, or none."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from read_spy import record_reads

from imulog.archive import TrialReader, write_trial
from imulog.process import heading as hd
from imulog.process import quaternion as Q
from imulog.simulate.setup import simulate_setup
from imulog.steps.align_setup import run_align_setup
from imulog.steps.heading import common_heading, run_heading
from imulog.steps.orientation import run_orientation


def _heading_of(q):
    return np.degrees(np.arctan2(*Q.rotate(q, np.array([1.0, 0, 0]))[..., [1, 0]].T))


def test_magnetic_correction_turns_a_known_heading_onto_north():
    rng = np.random.default_rng(0)
    q = Q.from_rotation_vector(rng.normal(scale=0.5, size=(400, 3)))  # sensor to its global frame
    field_global = np.array([0.0, 20.0, -40.0])  # north and down, in a frame whose north is at 30 deg
    turn = hd.yaw_quaternion(np.radians(-30.0))  # the IMU's global frame is turned by -30 deg from ENU
    mag = Q.rotate_inverse(q, np.tile(Q.rotate(turn, field_global), (len(q), 1)))
    f = hd.field_in_global(q, mag)
    corr, why = hd.magnetic_corrections(
        {"a": f, "b": hd.field_in_global(q, Q.rotate_inverse(q, np.tile(field_global, (400, 1))))}
    )
    assert not why
    np.testing.assert_allclose(Q.rotate(corr["a"], Q.rotate(turn, field_global)), field_global, atol=1e-9)
    np.testing.assert_allclose(corr["b"], [1, 0, 0, 0], atol=1e-9)
    disturbed = dict(f, norm_cv=0.3)
    assert hd.magnetic_corrections({"a": disturbed})[0] is None


def test_static_pose_makes_the_headings_equal():
    qa = np.tile(hd.yaw_quaternion(np.radians(40.0)), (50, 1))
    qb = np.tile(hd.yaw_quaternion(np.radians(-75.0)), (50, 1))
    corr = hd.static_pose_corrections({"a": qa, "b": qb})
    ha = hd.heading_deg(hd.apply_correction(corr["a"], qa))
    hb = hd.heading_deg(hd.apply_correction(corr["b"], qb))
    np.testing.assert_allclose(ha, hb, atol=1e-9)


@pytest.fixture(scope="module")
def oriented_setup(tmp_path_factory):
    sim = simulate_setup(seed=0, duration_s=40.0)
    path = write_trial(tmp_path_factory.mktemp("heading") / "setup.mcap", sim.recording)
    for imu in ("upper_arm", "forearm", "trunk"):
        run_orientation(path, imu=imu)  # 6D: arbitrary headings
    return sim, path


def test_six_d_imus_without_anything_to_relate_them_say_so(oriented_setup, tmp_path):
    """6D orientations, magnetometers with the simulator's device errors (bias, scale: the field's norm and dip
    change with the orientation), no alignment yet: no common frame, and every reason is given."""
    _, src = oriented_setup
    path = shutil.copy(src, tmp_path / "t.mcap")
    _, rec = run_heading(path, imus=["upper_arm", "forearm"])
    assert rec["source"] == "none"
    assert [r.split(":")[0] for r in rec["rejected"]] == ["magnetometer", "optical", "static pose", "device"]
    assert all("correction" not in v for v in rec["imus"].values())
    corr, warn = common_heading({"imulog.heading": rec}, ["upper_arm", "forearm"])
    assert corr is None and "not related" in warn and "magnetometer" in warn
    assert "not related" in common_heading({}, ["upper_arm"])[1]
    # a declared static pose relates them: the still neutral posture of the first 3 s
    _, pose = run_heading(path, imus=["upper_arm", "forearm"], static_s=(0.5, 2.5))
    assert pose["source"] == "static pose" and common_heading({"imulog.heading": pose}, ["forearm"])[0]


def test_without_a_field_a_pose_or_device_orientations_no_samples_are_read(oriented_setup, tmp_path, monkeypatch):
    """6D IMUs without magnetometers, not aligned, no pose declared: the record ("none", every reason) needs no
    samples, so neither the orientations nor the IMU channels are read (two IMUs' quaternions of a week are 4 GB;
    issue 24); a declared pose still reads the orientations and relates them."""
    import dataclasses

    sim, _ = oriented_setup
    imus = [dataclasses.replace(i, mag=None) for i in sim.recording.imus]
    path = write_trial(tmp_path / "nomag.mcap", dataclasses.replace(sim.recording, imus=imus))
    for imu in ("upper_arm", "forearm"):
        run_orientation(path, imu=imu)
    spans = record_reads(monkeypatch)
    _, rec = run_heading(path, imus=["upper_arm", "forearm"])
    reads = [topic for topic, _, _ in spans]
    assert rec["source"] == "none"
    assert [r.split(":")[0] for r in rec["rejected"]] == ["magnetometer", "optical", "static pose", "device"]
    assert rec["rejected"][0] == "magnetometer: not every IMU has one"
    assert not [t for t in reads if t.startswith(("/imu/", "/derived/orientation/"))], reads
    _, pose = run_heading(path, imus=["upper_arm", "forearm"], static_s=(0.5, 2.5))
    assert pose["source"] == "static pose" and "/derived/orientation/forearm" in [topic for topic, _, _ in spans]


def test_corrected_headings_agree_with_the_truth(oriented_setup, tmp_path):
    """Optical (align after orientation): each IMU in the common frame has the true heading up to one
    rotation shared by all IMUs (the markers' world is the truth's world here: offsets near 0)."""
    sim, src = oriented_setup
    path = shutil.copy(src, tmp_path / "t.mcap")
    names = ["upper_arm", "forearm"]
    run_align_setup(path, imus=names)
    with TrialReader(path) as t:
        meta = t.metadata
        q = {n: t.read(f"/derived/orientation/{n}") for n in names}
    _, opt_rec = run_heading(path, imus=names, force=True)
    with TrialReader(path) as t:
        meta = t.metadata
    assert opt_rec["source"] == "optical"
    for rec in (opt_rec,):
        diffs = []
        for n in names:
            qc = hd.apply_correction(np.asarray(rec["imus"][n]["correction"]), q[n].values)
            k = np.searchsorted(sim.arm.truth.t_ns, q[n].t_ns + meta[f"imulog.alignment.{n}"]["offset_ns"])
            k = np.clip(k, 0, len(sim.arm.truth.t_ns) - 1)
            d = _heading_of(qc) - _heading_of(sim.arm.truth.q_world_sensor[n][k])
            diffs.append(np.degrees(np.angle(np.mean(np.exp(1j * np.radians(d))))))
        print(f"\n{rec['source']}: heading offsets from the truth {', '.join(f'{x:.1f}' for x in diffs)} deg")
        assert all(abs(d) < 5.0 for d in diffs)  # both in the one (optical) world frame


def test_info_says_whether_the_headings_relate(oriented_setup, tmp_path):
    from click.testing import CliRunner

    from imulog.cli import cli

    _, src = oriented_setup
    path = shutil.copy(src, tmp_path / "t.mcap")
    res = CliRunner().invoke(cli, ["process", "heading", str(path), "--imu", "upper_arm", "--imu", "forearm"])
    assert res.exit_code == 0 and "no common heading" in res.output and "not used: magnetometer" in res.output
    info = CliRunner().invoke(cli, ["info", str(path)])
    assert "heading: not related between" in info.output
    bad = CliRunner().invoke(cli, ["process", "heading", str(path), "--static-pose", "3,1"])
    assert bad.exit_code != 0 and "END must be after START" in bad.output


def test_sto_export_writes_the_imus_in_the_common_heading_frame(oriented_setup, tmp_path):
    """Issue 27 point 4: with a heading record, `export --to sto` writes every IMU in the common frame (so the
    segments' headings relate) and says so; without one it writes them as estimated and says they do not."""
    from imulog.export.sto import export_sto

    def read_sto(path):
        lines = Path(path).read_text().split("endheader\n", 1)[1].splitlines()
        names = lines[0].split("\t")[1:]
        rows = [line.split("\t")[1:] for line in lines[1:]]
        return {n: np.array([[float(v) for v in r[i].split(",")] for r in rows]) for i, n in enumerate(names)}

    _, src = oriented_setup
    path = shutil.copy(src, tmp_path / "t.mcap")
    names = ["upper_arm", "forearm"]
    with TrialReader(path) as t:
        plain = export_sto(t, tmp_path / "plain.sto", imus=names)
    assert any("do not share one heading frame" in n and "process heading" in n for n in plain.notes), plain.notes
    _, rec = run_heading(path, imus=names, static_s=(0.5, 2.5))
    with TrialReader(path) as t:
        common = export_sto(t, tmp_path / "common.sto", imus=names)
    assert any("common heading frame (static pose" in n for n in common.notes), common.notes
    assert not any("do not share" in n for n in common.notes)
    before, after = read_sto(tmp_path / "plain.sto"), read_sto(tmp_path / "common.sto")
    for n in names:
        col = f"{n}_imu"
        expect = hd.apply_correction(np.asarray(rec["imus"][n]["correction"]), before[col])
        dots = np.abs(np.sum(expect * after[col], axis=1))
        assert np.all(dots > 1 - 1e-6)  # the same rotation (q and -q alike)


def test_aligned_before_oriented_reads_the_orientation_only_around_the_poses(tmp_path, monkeypatch):
    """Aligned before its orientation existed, the optical heading comes from the cluster's poses: the
    orientation is read over the poses' span and a margin (a lab hour of a week's recording, not the week:
    issue 24), and the rotation is the one the whole orientation gives."""
    import dataclasses

    from imulog.simulate import simulate
    from imulog.steps.align import run_align
    from imulog.steps.common import cluster_pose_topic
    from imulog.steps.heading import global_to_world_from_pose

    sim = simulate("r2g", seed=4, repetitions=4)
    imus = [dataclasses.replace(i, mag=None) for i in sim.recording.imus]
    path = write_trial(tmp_path / "t.mcap", dataclasses.replace(sim.recording, imus=imus))
    run_align(path)
    run_orientation(path)
    with TrialReader(path) as t:
        name = next(x.split("/")[3] for x in t.topics() if x.startswith("/derived/orientation/"))
        whole = t.read(f"/derived/orientation/{name}")
        align = t.metadata["imulog.alignment"]
        pose = t.read(cluster_pose_topic(name, t.topics(), t.metadata))
    assert align.get("rotation_global_to_world") is None  # the late case
    want = np.asarray(global_to_world_from_pose(whole.t_ns, whole.values, align, pose.t_ns, pose.orientation))
    spans = record_reads(monkeypatch)
    _, rec = run_heading(path, force=True)
    reads = [(lo, hi) for topic, lo, hi in spans if topic == f"/derived/orientation/{name}"]
    assert reads and all(lo is not None and hi is not None for lo, hi in reads), reads
    assert rec["source"] == "optical"
    got = np.asarray(rec["imus"][name]["correction"])
    assert np.allclose(got, want, atol=1e-9) or np.allclose(got, -want, atol=1e-9), (got, want)
