"""Several sensors of one recording are one trial: folders and lists of per-sensor exports (real files in
../shared/data/devices), one /imu/<name> per sensor, --device-name SERIAL=NAME, and doctor on every trial."""

from __future__ import annotations

import shutil

import numpy as np
from click.testing import CliRunner
from imulog.converters import ConvertOptions, convert_files
from imulog.converters.registry import group_directory

from imulog.archive import TrialReader, check_file
from imulog.cli import cli

XSENS = "devices/xsens_mtmanager"


def run(*args) -> tuple[int, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.output


def test_xsens_folder_is_one_trial_per_recording(shared_data, tmp_path):
    groups = dict(group_directory(shared_data / XSENS))
    assert sorted(p.name for p in groups["MT_012005D6_031"]) == [
        "MT_012005D6_031-000_00B421AF.txt",
        "MT_012005D6_031-000_00B4227B.txt",
    ]
    assert sorted(p.name for p in groups["MT46_01"]) == ["MT46_01-000_00B42D4D.txt", "MT46_01-000_00B42D4E.txt"]
    assert len(groups) == 10  # the six MT2022 exports are different files of their own, never merged

    out = tmp_path / "trials"
    code, output = run("convert", shared_data / XSENS, "-o", out)
    assert code == 0, output
    trials = sorted(p.name for p in out.glob("*.mcap"))
    assert len(trials) == 10 and "MT_012005D6_031.mcap" in trials
    for path in out.glob("*.mcap"):
        report = check_file(path)
        assert report.ok, (path.name, report.problems)
    with TrialReader(out / "MT_012005D6_031.mcap") as trial:
        imus = [t for t in trial.topics() if t.startswith("/imu/")]
        assert sorted(imus) == ["/imu/mt_00b421af", "/imu/mt_00b4227b"]
        a = trial.read("/imu/mt_00b421af")
        b = trial.read("/imu/mt_00b4227b")
        np.testing.assert_array_equal(a.t_ns, b.t_ns)  # PacketCounter 03583..06951 in both: sample aligned
        assert a.acc[0].tolist() == [3.030769, 5.254238, -7.714005]
        assert b.acc[0].tolist() == [0.015173, 9.109743, -3.736056]
        assert len(trial.attachments()) == 2


def test_files_given_together_with_device_names(shared_data, tmp_path):
    files = sorted((shared_data / XSENS).glob("MT46_01-000_*.txt"))
    out = tmp_path / "mt46.mcap"
    code, output = run(
        "convert",
        *files,
        "-o",
        out,
        "--device-name",
        "00B42D4D=left_forearm",
        "--device-name",
        "00b42d4e=left_upper_arm",
    )
    assert code == 0, output
    with TrialReader(out) as trial:
        assert {t for t in trial.topics() if t.startswith("/imu/")} == {"/imu/left_forearm", "/imu/left_upper_arm"}
        assert trial.metadata["imulog.device.left_forearm"]["serial"] == "00B42D4D"
        assert {"/orientation/left_forearm", "/orientation/left_upper_arm"} <= set(trial.topics())


def test_same_sensor_twice_is_refused(shared_data, tmp_path):
    d = shared_data / XSENS
    files = [d / "MT2022_ACC_00B42D4B.txt", d / "MT2022_ACC_GYRO_ROT_MAT_COMMA_00B42D4B.txt"]
    out = tmp_path / "twice.mcap"
    code, output = run("convert", *files, "-o", out)
    assert code == 1 and "same channel(s): /imu/mt_00b42d4b" in output and not out.exists()


def test_one_file_many_sensors_apdm_and_delsys_with_names(shared_data):
    rec = convert_files(
        [shared_data / "devices/apdm_csv/apdm_format7.csv"],
        options=ConvertOptions(extra={"names": {"5718": "pelvis", "CHEST": "sternum"}}),
    )
    names = [i.name for i in rec.imus]
    assert names == ["pelvis", "right_ankle", "left_ankle", "left_foot", "sternum", "right_foot"]
    assert rec.metadata["imulog.device.pelvis"]["serial"] == "5718"
    rec = convert_files(
        [shared_data / "devices/delsys_trigno/truncated_trigno_sample.csv"],
        options=ConvertOptions(extra={"names": {"10": "wrist"}}),
    )
    assert [i.name for i in rec.imus] == ["wrist", "mini_sensor_11"]
    assert [a.name for a in rec.analogs] == ["wrist", "mini_sensor_11"]


def test_every_lab_device_folder_converts_and_passes_doctor(shared_data, tmp_path):
    """Every file of the lab-system folders converts with no --format, one trial per recording, doctor ok."""
    folders = ["xsens_mtmanager", "apdm_csv", "opensense_sto", "optitrack_motive", "delsys_trigno"]
    data = tmp_path / "devices"
    for f in folders:
        shutil.copytree(shared_data / "devices" / f, data / f)
    out = tmp_path / "out"
    code, output = run("convert", data, "-o", out)
    assert code == 0, output
    trials = sorted(str(p.relative_to(out)) for p in out.rglob("*.mcap"))
    assert len(trials) == 10 + 2 + 2 + 1 + 2, trials
    for path in out.rglob("*.mcap"):
        assert check_file(path).ok, path
    # every data file is attached to exactly one trial
    attached = []
    for path in out.rglob("*.mcap"):
        with TrialReader(path) as trial:
            attached += [a.name for a in trial.attachments()]
    expected = [p.name for f in folders for p in (data / f).iterdir() if not p.name.startswith(("LICENSE", "NOTICE"))]
    assert sorted(attached) == sorted(expected)


LAB_FORMATS = {
    "xsens": ".txt",
    "apdm": ".h5",
    "mvnx": ".mvnx",
    "opensim-sto": ".sto",
    "motive": ".csv",
    "qualisys": ".tsv",
    "delsys": ".csv",
}


def test_lab_formats_are_plugins_and_listed(repo_root):
    import tomllib

    from imulog.converters.registry import BUILTIN

    eps = tomllib.loads((repo_root / "pyproject.toml").read_text())["project"]["entry-points"]["imulog.converters"]
    for name in LAB_FORMATS:
        assert eps[name] == BUILTIN[name], name  # the same plug-in whether installed or from a source checkout
    code, output = run("convert", "--list-formats")
    assert code == 0
    lines = {line.split()[0]: line for line in output.splitlines() if line.strip()}
    for name, ext in LAB_FORMATS.items():
        assert ext in lines[name].split() and len(lines[name]) > 40, lines.get(name)


def _mutate(rng, data: bytes) -> bytes:
    """One random damage: cut, flipped bytes, a line deleted, duplicated, stripped of a delimiter or replaced."""
    kind = rng.integers(6)
    if kind == 0:
        return data[: rng.integers(len(data))]
    if kind == 1:
        b = bytearray(data)
        for i in rng.integers(len(b), size=rng.integers(1, 5)):
            b[i] = rng.integers(256)
        return bytes(b)
    lines = data.split(b"\n")
    i = int(rng.integers(len(lines)))
    if kind == 2 and len(lines) > 2:
        del lines[i]
    elif kind == 3:
        lines.insert(i, lines[int(rng.integers(len(lines)))])
    elif kind == 4:
        lines[i] = lines[i].replace([b",", b"\t", b" ", b";", b"."][int(rng.integers(5))], b"", 1)
    else:
        lines[i] = [b"", b"nan", b"-1e400", b"\x00", b"NaN\tNaN", b'<frame time="1">', b"0" * 40][int(rng.integers(7))]
    return b"\n".join(lines)


def test_damaged_lab_exports_raise_only_conversion_errors(shared_data, tmp_path):
    """Seeded fuzzing of every lab format (cut files, flipped bytes, lost/duplicated/garbled lines): the converter
    either reads the file or raises ConversionError with a one-line message, never another exception."""
    from imulog.converters import ConversionError
    from imulog.converters.registry import get
    from test_convert_apdm import write_apdm_h5  # tests/ is on sys.path (rootdir import mode)
    from test_convert_mvnx import write_mvnx
    from test_convert_qualisys import write_qtm

    d = shared_data / "devices"
    write_mvnx(tmp_path / "m.mvnx", n=6)
    write_qtm(tmp_path / "q.tsv", n=10)
    write_apdm_h5(tmp_path / "a.h5", n=50)
    cases = [
        ("xsens", shared_data / XSENS / "MT2022_ACC_GYRO_ROT_ALL_TAB_NAN_00B42D4B.txt"),
        ("xsens", shared_data / XSENS / "MT2022_ACC_GYRO_ROT_MAT_SPACE_00B42D4B.txt"),
        ("apdm", d / "apdm_csv/apdm_format7.csv"),
        ("opensim-sto", d / "opensense_sto/myComplexTasksTrial_orientations.sto"),
        ("motive", d / "optitrack_motive/sample_optitrack_take.csv"),
        ("delsys", d / "delsys_trigno/trigno_sample_header.csv"),
        ("mvnx", tmp_path / "m.mvnx"),
        ("qualisys", tmp_path / "q.tsv"),
        ("apdm", tmp_path / "a.h5"),  # h5py's own errors on a damaged file become ConversionError too
    ]
    rng = np.random.default_rng(14)
    for fmt, src in cases:
        conv, data = get(fmt), src.read_bytes()
        target = tmp_path / f"damaged{src.suffix}"
        for _ in range(25):
            target.write_bytes(_mutate(rng, data))
            try:
                conv.convert(target)
            except ConversionError as e:
                assert "\n" not in str(e) and str(target) in str(e), (fmt, str(e))


def test_inputs_with_different_start_times_keep_the_first_and_say_so(shared_data, tmp_path):
    """Motive (capture PC local time) and APDM Format=7 (UTC) of 'one session': the first input's start time is
    kept and the other one is named in a warning, never silently replaced."""
    files = [
        shared_data / "devices/optitrack_motive/sample_optitrack_take.csv",
        shared_data / "devices/apdm_csv/apdm_format7.csv",
    ]
    rec = convert_files(files)
    assert rec.metadata["imulog.trial"]["start_time"] == "2016-01-05T15:49:50.755000"
    assert rec.metadata["imulog.trial"]["time_zone"] == "unknown (device local time)"
    (warning,) = [w for w in rec.warnings if "start time" in w]
    assert warning.startswith("apdm_format7.csv: start time 2019-02-22T23:51:44.438281+00:00 (UTC) differs")
    # inputs without a start time (the two files of one old-header Xsens recording) say nothing about it
    quiet = convert_files(sorted((shared_data / XSENS).glob("MT46_01-000_*.txt")))
    assert "imulog.trial" not in quiet.metadata and not [w for w in quiet.warnings if "start time" in w]


def test_recordings_that_share_a_name_get_a_trial_each(tmp_path, shared_data):
    """``trial.csv`` (IMU) and ``trial.c3d`` (markers) beside a second IMU recording are not one session: two
    trials that both took the name ``trial``, so the second was refused as existing (and with --overwrite would
    have replaced the first). Each keeps its own: ``trial.csv.mcap``, ``trial.c3d.mcap``, ``other.mcap``."""
    from imulog.archive import TrialReader

    folder = tmp_path / "lab"
    folder.mkdir()
    for src, name in (
        ("imu_text/fusion_sensor_data.csv", "trial.csv"),
        ("c3d/ktk_sample_propulsion_upperlimb.c3d", "trial.c3d"),
        ("imu_text/shimmer_consensys_export.csv", "other.csv"),
    ):
        (folder / name).write_bytes((shared_data / src).read_bytes())
    out = tmp_path / "trials"
    for extra in ([], ["--overwrite"]):
        r = CliRunner().invoke(cli, ["convert", str(folder), "-o", str(out), *extra])
        assert r.exit_code == 0, r.output
        assert "wrote 3 trial(s)" in r.output
    assert sorted(p.name for p in out.iterdir()) == ["other.mcap", "trial.c3d.mcap", "trial.csv.mcap"]
    kinds = {}
    for p in out.iterdir():
        with TrialReader(p) as t:
            kinds[p.name] = sorted(c.topic.split("/")[1] for c in t.channels if not c.topic.startswith("/derived"))
    assert kinds["trial.c3d.mcap"] == ["markers"] and kinds["trial.csv.mcap"] == ["imu"]


def test_two_folders_of_one_name_keep_a_trial_each(tmp_path, shared_data):
    """``imulog convert a/data b/data -o out``: both folders' trials go under out/data/; a recording named ``t`` in
    each is two trials (``t.csv``, ``t.csv_2``), not one refused or overwritten."""
    for folder, src in (("a", "imu_text/fusion_sensor_data.csv"), ("b", "imu_text/shimmer_consensys_export.csv")):
        (tmp_path / folder / "data").mkdir(parents=True)
        (tmp_path / folder / "data" / "t.csv").write_bytes((shared_data / src).read_bytes())
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["convert", str(tmp_path / "a" / "data"), str(tmp_path / "b" / "data"), "-o", str(out)])
    assert r.exit_code == 0 and "wrote 2 trial(s)" in r.output, r.output
    assert sorted(p.name for p in (out / "data").iterdir()) == ["t.csv.mcap", "t.csv_2.mcap"]


def test_output_names_do_not_depend_on_the_format(tmp_path, shared_data):
    """One rule for every format: a trial is named by its recording's stem (``ax3_sample.cwa`` -> ``ax3_sample``,
    as ``imuData01.csv`` -> ``imuData01``; a self-contained binary used to keep its extension, ``ax3_sample.cwa``),
    and every trial of a stem shared by several keeps its file's extension (``ax3_sample.cwa``, an APDM
    ``ax3_sample.csv``)."""
    folder = tmp_path / "mixed"
    folder.mkdir()
    for src in (
        "devices/axivity_cwa/ax3_sample.cwa",
        "devices/axivity_cwa/ax6_sample.cwa",
        "devices/apdm_csv/imuData01.csv",
    ):
        shutil.copy(shared_data / src, folder)
    out = tmp_path / "out"
    code, output = run("convert", folder, "-o", out)
    assert code == 0, output
    assert sorted(p.name for p in out.iterdir()) == ["ax3_sample.mcap", "ax6_sample.mcap", "imuData01.mcap"]
    # another device's recording that shares the stem (an Axivity CSV named so would be the .cwa's OMGUI export,
    # skipped: tests/test_convert_exports.py)
    shutil.copy(shared_data / "devices/apdm_csv/imuData01.csv", folder / "ax3_sample.csv")
    code, output = run("convert", folder, "-o", tmp_path / "out2")
    assert code == 0, output
    assert sorted(p.name for p in (tmp_path / "out2").iterdir()) == [
        "ax3_sample.csv.mcap",
        "ax3_sample.cwa.mcap",
        "ax6_sample.mcap",
        "imuData01.mcap",
    ]
