"""Whole setups (issue 27): a session folder is one trial, and the per-IMU steps run on every IMU by default.

Real files: the OpenSense Xsens trial (two MTw sensors, MT_012005D6_031) beside the kineticstoolkit C3D, and the
APDM Opal CSV with four sensors (Static, Upper, Middle, Lower)."""

from __future__ import annotations

import shutil

import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli

XSENS = ("MT_012005D6_031-000_00B421AF.txt", "MT_012005D6_031-000_00B4227B.txt")
OPALS = ["static", "upper", "middle", "lower"]


def run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


@pytest.fixture
def session(shared_data, tmp_path):
    """A session folder as a lab saves it: per-sensor IMU files, the optical export, a file of something else."""
    folder = tmp_path / "session"
    folder.mkdir()
    for name in XSENS:
        shutil.copy(shared_data / "devices" / "xsens_mtmanager" / name, folder)
    shutil.copy(shared_data / "c3d" / "ktk_sample_propulsion_upperlimb.c3d", folder)
    (folder / "notes.csv").write_text("who,what\nme,walked\n")
    return folder


def test_session_folder_is_one_trial_and_says_what_it_skipped(session, tmp_path):
    out = tmp_path / "trial.mcap"
    code, stdout, stderr = run("convert", session, "-o", out)
    assert code == 0, stderr
    assert "from 3 files" in stdout
    assert "skipped" in stderr and "notes.csv: unknown format" in stderr
    with TrialReader(out) as trial:
        topics = trial.topics()
        inputs = trial.metadata["imulog.conversion"]["inputs"]
    assert {"/imu/mt_00b421af", "/imu/mt_00b4227b", "/markers/vicon"} <= set(topics)
    assert sorted(inputs) == sorted([*XSENS, "ktk_sample_propulsion_upperlimb.c3d"])
    # an output folder: the same session is still one trial, named after the IMU recording
    code, _, stderr = run("convert", session, "-o", tmp_path / "trials")
    assert code == 0, stderr
    assert [p.name for p in (tmp_path / "trials").glob("*.mcap")] == ["MT_012005D6_031.mcap"]


def test_folder_of_unrelated_recordings_is_not_one_trial(shared_data, tmp_path):
    """The shared Xsens folder holds 10 separate recordings: one trial is refused, one per recording is made."""
    code, _, stderr = run("convert", shared_data / "devices" / "xsens_mtmanager", "-o", tmp_path / "x.mcap")
    assert code == 2 and "10 recordings" in stderr and not (tmp_path / "x.mcap").exists()


@pytest.fixture
def opals(shared_data, tmp_path):
    path = tmp_path / "opals.mcap"
    code, _, stderr = run("convert", shared_data / "devices" / "apdm_csv" / "imuData01.csv", "-o", path)
    assert code == 0, stderr
    return path


def test_orientation_runs_on_every_imu_one_run_each(opals):
    code, stdout, stderr = run("process", "orientation", opals)
    assert code == 0, stderr
    rows = [line.split() for line in stdout.splitlines() if line.strip().split(" ")[0] in OPALS]
    assert [r[0] for r in rows] == OPALS and {r[1] for r in rows} == {"wrote"}
    # 6D orientations each have their own heading; the Opals' own orientations (one recording) relate them
    assert "heading: one frame for static, upper, middle, lower: device" in stdout
    with TrialReader(opals) as trial:
        steps = sorted(r["step"] for r in trial.runs().values())
        assert all(f"/derived/orientation/{n}" in trial.topics() for n in OPALS)
    assert steps == sorted([*(f"orientation:{n}" for n in OPALS), "heading"])  # one heading run relates them
    code, stdout, _ = run("process", "orientation", opals)  # the same again: nothing written
    assert code == 0 and stdout.count("unchanged") == 4
    code, stdout, _ = run("process", "orientation", opals, "--imu", "upper", "--backend", "madgwick")
    assert code == 0 and stdout.startswith("wrote /derived/") and "/derived/orientation/upper" in stdout
    code, _, stderr = run("process", "orientation", opals, "--imu", "upper", "--imu", "nope")
    assert code == 1 and "no channel /imu/nope" in stderr and "static, upper, middle, lower" in stderr


def test_phases_and_metrics_keep_one_record_per_imu(opals):
    code, stdout, stderr = run("process", "phases", opals)
    assert code == 0, stderr
    assert stdout.startswith("phases: 4 IMUs")
    with TrialReader(opals) as trial:
        md = trial.metadata
        runs = {r["step"] for r in trial.runs().values()}
    # the primary IMU (no alignment, no 'wrist': the first) keeps imulog.timing; the others get their own
    assert md["imulog.timing"]["imu"] == "/imu/static"
    for name in OPALS[1:]:
        assert md[f"imulog.timing.{name}"]["imu"] == f"/imu/{name}"
    assert {f"phases:{n}" for n in OPALS} <= runs
    code, stdout, _ = run("process", "phases", opals)
    assert code == 0 and stdout.count("unchanged") == 4  # each IMU's run is found again
    code, stdout, stderr = run("process", "metrics", opals, "--imu", "lower", "--imu", "upper", "--json")
    assert code == 0, stderr
    import json

    records = json.loads(stdout)
    assert sorted(records) == ["lower", "upper"] and records["upper"]["imu"] == "/imu/upper"


def _sto(path):
    """(column names, time (N,), quaternions {column: (N, 4)}) of a quaternion .sto file."""
    import numpy as np

    lines = path.read_text().splitlines()
    k = lines.index("endheader")
    names = lines[k + 1].split("\t")[1:]
    rows = [line.split("\t") for line in lines[k + 2 :]]
    time = np.array([float(r[0]) for r in rows])
    quats = {n: np.array([[float(v) for v in r[j + 1].split(",")] for r in rows]) for j, n in enumerate(names)}
    return names, time, quats


def test_device_orientations_export_to_sto_with_names_checked(opals, tmp_path):
    """The APDM Opals' own orientations go to .sto without `process orientation`; --name takes an IMU's name or
    its label, and a name that matches no IMU is refused (it used to be ignored)."""
    import numpy as np

    out = tmp_path / "opals.sto"
    code, stdout, stderr = run("export", opals, "-o", out, "--name", "Upper=humerus_r_imu", "--name", "lower=radius_r")
    assert code == 0, stderr
    assert "upper: /orientation/upper" not in stderr and "humerus_r_imu: /orientation/upper (the device's" in stderr
    names, _, quats = _sto(out)
    assert names == ["static_imu", "humerus_r_imu", "middle_imu", "radius_r"]
    with TrialReader(opals) as trial:
        for column, imu in zip(names, OPALS, strict=True):
            q = trial.read(f"/orientation/{imu}").values
            assert np.allclose(quats[column], q / np.linalg.norm(q, axis=1, keepdims=True), atol=1e-12)
    code, _, stderr = run("export", opals, "-o", tmp_path / "bad.sto", "--name", "nope=foo")
    assert code == 1 and "--name nope=foo: no IMU 'nope'" in stderr and not (tmp_path / "bad.sto").exists()
    # imulog's 6D orientations: each has its own heading, related by the Opals' own orientations
    assert run("process", "orientation", opals)[0] == 0
    code, _, stderr = run("export", opals, "-o", tmp_path / "6d.sto")
    assert code == 0 and "/derived/orientation/upper (imulog's" in stderr
    assert "every IMU in the trial's common heading frame (device" in stderr
    code, _, stderr = run("export", opals, "-o", tmp_path / "dev.sto", "--source", "device")
    assert code == 0 and "do not share" not in stderr  # one device export: one global frame


def test_opensense_sto_round_trips_through_a_trial(shared_data, tmp_path):
    """An OpenSense orientation file (8 IMUs) converted and exported again holds the same quaternions."""
    import numpy as np

    src = shared_data / "devices" / "opensense_sto" / "MT_012005D6_009-quaternions_calibration_trial_Facing_negX.sto"
    trial = tmp_path / "os.mcap"
    assert run("convert", src, "-o", trial)[0] == 0
    code, _, stderr = run("export", trial, "-o", tmp_path / "os.sto")
    assert code == 0, stderr
    names, time, quats = _sto(tmp_path / "os.sto")
    their_names, their_time, theirs = _sto(src)
    assert names == their_names and len(names) == 8
    assert np.allclose(np.diff(time), np.diff(their_time), atol=1e-9)
    for n in names:
        q = theirs[n] / np.linalg.norm(theirs[n], axis=1, keepdims=True)
        assert np.allclose(quats[n], q, atol=1e-9)


def test_arm_imus_from_names_and_placements():
    from imulog.steps.placements import arm_imus, partner, words

    assert words("RightUpperArm") == ["right", "upper", "arm"] and words("upper_arm_r") == ["upper", "arm", "r"]
    assert arm_imus(["trunk", "upper_arm", "forearm"], {}) == ("upper_arm", "forearm")
    assert arm_imus(["humerus_r_imu", "radius_r_imu", "pelvis_imu"], {}) == ("humerus_r_imu", "radius_r_imu")
    assert arm_imus(["rightforearm", "rightupperarm"], {}) == ("rightupperarm", "rightforearm")  # lower-cased
    # two arms: paired by side; a wrist sensor stands for the forearm when nothing else names it
    names = ["upper_arm_l", "upper_arm_r", "forearm_l", "forearm_r"]
    with pytest.raises(ValueError, match="more than one arm"):
        arm_imus(names, {})
    assert partner("forearm", "upper_arm_r", names, {}) == "forearm_r"
    assert arm_imus(["left_wrist", "left_upper_arm"], {}) == ("left_upper_arm", "left_wrist")
    # placements from the device records (an APDM label, or --meta device.NAME.placement=...)
    md = {"imulog.device.a": {"label": "Upper Arm"}, "imulog.device.b": {"placement": "lower arm"}}
    assert arm_imus(["a", "b", "c"], md) == ("a", "b")
    with pytest.raises(ValueError, match="no upper-arm and forearm IMU .*static: Static"):
        arm_imus(["static", "upper"], {"imulog.device.static": {"label": "Static"}})


def test_kinematics_takes_the_arm_imus_named_at_conversion(session, tmp_path):
    """The two real Xsens sensors named by --device-name are the DH model's IMUs, without --upper-arm/--forearm."""
    trial = tmp_path / "arm.mcap"
    code, _, stderr = run(
        "convert",
        session,
        "-o",
        trial,
        "--device-name",
        "00B421AF=right_upper_arm",
        "--device-name",
        "00B4227B=RightForearm",
    )
    assert code == 0, stderr
    code, stdout, stderr = run("process", "kinematics", trial, "--no-markers")
    assert code == 0, stderr
    with TrialReader(trial) as reader:
        run_record = next(r for r in reader.runs().values() if r["step"] == "kinematics")
    assert {t for t in run_record["inputs"] if t.startswith("/imu/")} == {"/imu/right_upper_arm", "/imu/rightforearm"}
    assert run_record["params"]["upper_arm"] == "right_upper_arm" and run_record["params"]["forearm"] == "rightforearm"


def test_device_orientations_are_drawn_in_3d_for_every_imu(opals, tmp_path):
    """The Opals' own orientations (no processing) are moving frames in the Rerun recording, equal to the file's."""
    import numpy as np

    from imulog.view import layout as L
    from imulog.view.rrd import read_column

    rrd = tmp_path / "opals.rrd"
    code, _, stderr = run("view", opals, "--save", rrd)
    assert code == 0, stderr
    with TrialReader(opals) as trial:
        for name in OPALS:
            q = trial.read(f"/orientation/{name}").values
            _, xyzw = read_column(rrd, L.imu_frame_entity(f"/orientation/{name}"), "Transform3D:quaternion")
            drawn = np.array([r[0] for r in xyzw])[:, [3, 0, 1, 2]]
            q = q / np.linalg.norm(q, axis=1, keepdims=True)
            assert drawn.shape == q.shape and np.allclose(np.abs(np.sum(drawn * q, axis=1)), 1.0, atol=1e-6)


def test_imus_that_lack_what_the_step_reads_are_left_out_by_default(shared_data, tmp_path):
    """An ActiGraph GT9X has an accelerometer-only stream beside its IMU: orienting every IMU leaves it out with
    a note instead of failing; named with --imu, the step's own error stands."""
    trial = tmp_path / "ag.mcap"
    assert run("convert", shared_data / "devices" / "actigraph_gt3x" / "example.gt3x", "-o", trial)[0] == 0
    code, stdout, stderr = run("process", "orientation", trial)
    assert code == 0, stderr
    assert "left out /imu/tas1e31150129: no gyr" in stderr and "/derived/orientation/tas1e31150129_imu" in stdout
    code, _, stderr = run("process", "orientation", trial, "--imu", "tas1e31150129")
    assert code == 1 and "needs accelerometer and gyroscope" in stderr
    # the one line says what is missing and what works without it
    assert "/imu/tas1e31150129 has no gyroscope" in stderr and "`imulog process epochs`" in stderr
    assert len(stderr.strip().splitlines()) == 1
    # the phases step says the same (it said only "has no gyroscope columns")
    code, _, stderr = run("process", "phases", trial, "--imu", "tas1e31150129")
    assert code == 1 and "/imu/tas1e31150129 has no gyroscope" in stderr and "angular velocity" in stderr
    assert "`imulog process epochs`" in stderr and len(stderr.strip().splitlines()) == 1
    # the first IMU a step runs on keeps imulog.timing when the trial names no primary IMU
    assert run("process", "phases", trial)[0] == 0
    with TrialReader(trial) as reader:
        assert reader.metadata["imulog.timing"]["imu"] == "/imu/tas1e31150129_imu"


@pytest.mark.parametrize(
    ("optical", "topics"),
    [
        (("vicon_nexus/markers.csv", "vicon_nexus/analogs.csv"), {"/markers/vicon", "/analog/vicon"}),
        (("devices/opensim_trc/markers.trc", "devices/optitrack_motive/sample_optitrack_take.csv"), {"/markers/trc"}),
    ],
)
def test_other_optical_exports_join_the_session(shared_data, tmp_path, optical, topics):
    """Nexus CSV (markers + devices), TRC and Motive exports beside the per-sensor IMU files: one trial."""
    folder = tmp_path / "session"
    folder.mkdir()
    for name in XSENS:
        shutil.copy(shared_data / "devices" / "xsens_mtmanager" / name, folder)
    for rel in optical:
        shutil.copy(shared_data / rel, folder)
    code, stdout, stderr = run("convert", folder, "-o", tmp_path / "t.mcap")
    assert code == 0, stderr
    assert f"from {len(XSENS) + len(optical)} files" in stdout
    with TrialReader(tmp_path / "t.mcap") as trial:
        assert {"/imu/mt_00b421af", "/imu/mt_00b4227b", *topics} <= set(trial.topics())


def test_calibrate_every_imu_or_each_with_its_own_file(opals, tmp_path):
    """One calibration file for the IMUs chosen (default all), or IMU=FILE pairs; unknown IMUs are refused."""
    import json

    import numpy as np

    from imulog.process.calibration import AxisCalibration, Calibration

    offset = np.array([0.1, -0.2, 0.3])
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(Calibration(acc=AxisCalibration(bias=offset)).to_dict()))
    code, stdout, stderr = run("process", "calibrate", opals, "--calibration", cal)
    assert code == 0, stderr
    assert stdout.startswith("calibrate: 4 IMUs") and stdout.count("wrote") == 4
    code, stdout, stderr = run(
        "process", "calibrate", opals, "--calibration", f"upper={cal}", "--calibration", f"lower={cal}"
    )
    assert code == 0 and stdout.count("unchanged") == 2, stderr  # the same file again for these two
    with TrialReader(opals) as trial:
        raw = trial.read("/imu/middle").acc
        calibrated = trial.read("/derived/calibrated/middle").values[:, :3]
        steps = {r["step"] for r in trial.runs().values()}
    assert np.allclose(calibrated, raw - offset)
    assert {f"calibrate:{n}" for n in OPALS} <= steps
    code, _, stderr = run("process", "calibrate", opals, "--calibration", f"nope={cal}")
    assert code == 1 and "no channel /imu/nope" in stderr


def test_kinematics_takes_the_arm_imus_from_placements_declared_at_conversion(session, tmp_path):
    """Placements (`--meta device.NAME.placement=...`), not names: the streams keep their Xsens names and the DH
    model still finds its upper arm and forearm; without placements or names it refuses, listing the IMUs."""
    trial = tmp_path / "placed.mcap"
    code, _, stderr = run(
        "convert",
        session,
        "-o",
        trial,
        "--meta",
        "device.mt_00b421af.placement=right upper arm",
        "--meta",
        "device.mt_00b4227b.placement=right lower arm",
    )
    assert code == 0, stderr
    code, _, stderr = run("process", "kinematics", trial, "--no-markers")
    assert code == 0, stderr
    with TrialReader(trial) as reader:
        run_record = next(r for r in reader.runs().values() if r["step"] == "kinematics")
    assert run_record["params"]["upper_arm"] == "mt_00b421af" and run_record["params"]["forearm"] == "mt_00b4227b"
    bare = tmp_path / "bare.mcap"
    assert run("convert", session, "-o", bare)[0] == 0
    code, _, stderr = run("process", "kinematics", bare, "--no-markers")
    assert code != 0 and "mt_00b421af" in stderr and "mt_00b4227b" in stderr
