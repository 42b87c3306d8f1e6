"""Issue 27's done-when lines, end to end on the command line with default options: a simulated gait-lab session
(11 Xsens MT Manager files and a Vicon C3D, :mod:`imulog.simulate.gait`) and the shared four-Opal APDM file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.process import quaternion as quat

pytest.importorskip("ezc3d")


def run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


def sto_quaternions(path):
    lines = Path(path).read_text().splitlines()
    header = lines.index("endheader") + 1
    names = lines[header].split("\t")[1:]
    rows = [row.split("\t") for row in lines[header + 1 :]]
    q = {n: np.array([[float(v) for v in r[i + 1].split(",")] for r in rows]) for i, n in enumerate(names)}
    return np.array([float(r[0]) for r in rows]), q


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    """The session written as a lab has it, converted from its folder, then aligned and oriented by default."""
    from imulog.simulate.gait_files import write_gait_session

    root = tmp_path_factory.mktemp("gait")
    files = write_gait_session(root / "session", seed=0)
    trial = root / "walk.mcap"
    out = {}
    out["convert"] = run("convert", root / "session", "-o", trial)
    out["align"] = run("process", "align", trial)
    out["orientation"] = run("process", "orientation", trial)
    out["export"] = run("export", trial, "-o", root / "walk.sto")
    out["evaluate"] = run("evaluate", trial, "--json")
    truth = json.loads(files["truth_json"].read_text())
    return trial, root, truth, out


def test_the_session_folder_converts_to_one_trial_of_11_imus(walk):
    trial, _, truth, out = walk
    code, stdout, stderr = out["convert"]
    assert code == 0, stderr
    assert "from 12 files" in stdout
    with TrialReader(trial) as reader:
        topics = reader.topics()
    assert sorted(t for t in topics if t.startswith("/imu/")) == sorted(
        f"/imu/{s['stream']}" for s in truth["sensors"].values()
    )
    assert "/markers/vicon" in topics


def test_align_pairs_each_imu_with_its_segment_and_one_offset(walk):
    """Each foot IMU takes markers of its foot only (the malleolus beside it is the shank's), every IMU its own
    segment's markers, and the 11 share one clock within 2 ms of the truth."""
    trial, _, truth, out = walk
    code, stdout, stderr = out["align"]
    assert code == 0, stderr
    assert "11 IMUs aligned" in stdout
    clock = truth["clock"]
    with TrialReader(trial) as reader:
        records = {seg: reader.metadata[f"imulog.alignment.{s['stream']}"] for seg, s in truth["sensors"].items()}
    for seg, rec in records.items():  # every IMU found its own segment's markers, and only those
        chosen = set(rec["cluster"]["markers"])
        assert chosen <= set(truth["sensors"][seg]["markers"]) and len(chosen) >= 3, (seg, rec["cluster"])
        assert rec["frame_alignment"] is not False
    for foot in ("foot_l", "foot_r"):  # a foot's cluster: its own markers only, not the malleolus beside them
        chosen = set(records[foot]["cluster"]["markers"])
        assert chosen <= set(truth["sensors"][foot]["markers"]) and len(chosen) == 3, (foot, chosen)
    offsets = []
    for rec in records.values():
        t0 = rec["t0_ns"]
        true_ns = clock["offset_ns"] + clock["drift_ppm"] * 1e-6 * (t0 - clock["t0_ns"])
        offsets.append(rec["offset_ns"] - true_ns)
    assert len({rec["offset_ns"] for rec in records.values()}) == 1  # one clock for the recording
    assert max(abs(o) for o in offsets) < 2e6, [o / 1e6 for o in offsets]


def test_orientation_orients_all_11_in_one_heading_frame(walk):
    trial, _, truth, out = walk
    code, stdout, stderr = out["orientation"]
    assert code == 0, stderr
    names = [s["stream"] for s in truth["sensors"].values()]
    rows = [line.split() for line in stdout.splitlines() if line.strip().split(" ")[0] in names]
    assert sorted(r[0] for r in rows) == sorted(names) and {r[1] for r in rows} == {"wrote"}
    assert "heading: one frame for" in stdout and "optical" in stdout  # related without `process heading`


def test_sto_export_writes_11_imus_in_the_optical_world(walk):
    """The exported orientations, taken to the markers' clock, are the true IMU-to-world orientations: one
    heading frame (the optical world) for all 11, within a few degrees."""
    trial, root, truth, out = walk
    code, _, stderr = out["export"]
    assert code == 0, stderr
    assert "every IMU in the trial's common heading frame (optical" in stderr
    t_s, q = sto_quaternions(root / "walk.sto")
    assert len(q) == 11
    npz = np.load(root / "session" / "walk03_truth.npz")
    with TrialReader(trial) as reader:
        t0_dev = reader.read(f"/imu/{truth['sensors']['pelvis']['stream']}").t_ns[0]
        rec = reader.metadata[f"imulog.alignment.{truth['sensors']['pelvis']['stream']}"]
    from imulog.process.alignment import device_to_reference

    t_ref = device_to_reference(t0_dev + np.round(t_s * 1e9).astype(np.int64), rec) / 1e9
    heading_err = {}
    for seg, s in truth["sensors"].items():
        inside = (t_ref > npz["marker_t_s"][0]) & (t_ref < npz["marker_t_s"][-1])
        q_true = quat.normalize(
            np.column_stack([np.interp(t_ref[inside], npz["marker_t_s"], npz[f"{seg}_quat"][:, j]) for j in range(4)])
        )
        err = np.degrees(quat.angle_between(q[s["stream"] + "_imu"][inside], q_true))
        heading_err[seg] = float(np.median(err))
    assert max(heading_err.values()) < 4.0, heading_err


def test_zupt_per_stride_on_both_feet(walk):
    trial, _, truth, out = walk
    code, stdout, stderr = out["evaluate"]
    assert code == 0, stderr
    record = json.loads(stdout)
    assert record["kind"] == "strides"
    feet = {truth["sensors"][f]["stream"] for f in ("foot_l", "foot_r")}
    assert set(record["feet"]) == feet  # the other nine are not feet (their markers move in their rests)
    for name in feet:
        r = record["feet"][name]
        assert r["count"] >= 5
        assert max(r["mean_abs_cm"].values()) <= 3.0, r["mean_abs_cm"]
    assert all("not a foot" in why or "strides" in why for why in record["skipped"].values())


def test_apdm_opals_one_heading_frame_by_default_and_device_sto(shared_data, tmp_path):
    trial = tmp_path / "opals.mcap"
    code, _, stderr = run("convert", shared_data / "devices" / "apdm_csv" / "imuData01.csv", "-o", trial)
    assert code == 0, stderr
    # the device's own orientations, before any processing
    code, _, stderr = run("export", trial, "-o", tmp_path / "device.sto")
    assert code == 0, stderr
    _, q_dev = sto_quaternions(tmp_path / "device.sto")
    assert len(q_dev) == 4
    code, stdout, stderr = run("process", "orientation", trial)
    assert code == 0, stderr
    assert "heading: one frame for static, upper, middle, lower: device" in stdout
    with TrialReader(trial) as reader:
        rec = reader.metadata["imulog.heading"]
    assert rec["source"] == "device" and max(rec["yaw_sd_deg"].values()) < 5.0
    code, _, stderr = run("export", trial, "-o", tmp_path / "derived.sto", "--source", "derived")
    assert code == 0, stderr
    assert "every IMU in the trial's common heading frame (device" in stderr
    _, q_der = sto_quaternions(tmp_path / "derived.sto")
    # imulog's orientations in the common frame agree with the device's within a few degrees
    for name in q_dev:
        err = np.degrees(quat.angle_between(q_der[name], q_dev[name]))
        assert np.median(err) < 5.0, (name, np.median(err))
