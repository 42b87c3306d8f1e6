"""What a new user reads on the real multi-IMU and stream files of ../shared/data/devices when a step cannot run:
the error says what the trial has instead and what to do (the user audit's walk through README and docs/cli.md)."""

from __future__ import annotations

from click.testing import CliRunner

from imulog.cli import cli


def run(*args) -> tuple[int, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.output


def test_a_trial_without_an_imu_says_what_it_has(shared_data, tmp_path):
    """LabRecorder's minimal.xdf holds an EEG-typed stream and string markers, no IMU: the steps used to say only
    'no /imu/* channel in the trial'."""
    path = tmp_path / "minimal.mcap"
    assert run("convert", shared_data / "devices/xdf/minimal.xdf", "-o", path)[0] == 0
    for step in (["process", "orientation"], ["process", "phases"], ["process", "metrics"]):
        code, text = run(*step, path)
        assert code == 1 and len(text.strip().splitlines()) == 1, text
        assert "no /imu/* channel in the trial (it has /signals/senddatac, /events/senddatastring)" in text
        assert "acc_x" in text and "docs/converters.md" in text


def test_align_without_an_optical_reference_says_how_to_bring_one(shared_data, tmp_path):
    """Two Xsens sensors of one recording and nothing optical: align names both kinds of optical reference (markers,
    a rigid body's poses) and the command that puts one in the trial; evaluate names both too."""
    folder = shared_data / "devices/xsens_mtmanager"
    path = tmp_path / "xsens.mcap"
    files = sorted(folder.glob("MT_012005D6_031-000_*.txt"))
    assert run("convert", *files, "-o", path)[0] == 0
    code, text = run("process", "align", path)
    assert code == 1 and "/poses/*" in text and "imulog convert IMU_FILE OPTICAL_FILE -o trial.mcap" in text, text
    code, text = run("evaluate", path)
    assert code == 1 and "/markers/*" in text and "/poses/*" in text, text


def test_a_table_export_without_topic_lists_the_channels(shared_data, tmp_path):
    """One NilsPod sensor: `imulog export trial -o x.csv` needs --topic; the error used to send the user to
    `imulog info`, it now gives an example and the channels (the viewer twins left out)."""
    path = tmp_path / "nilspod.mcap"
    assert run("convert", shared_data / "devices/nilspod/NilsPodX-6F13_20210109_162824.bin", "-o", path)[0] == 0
    code, text = run("export", path, "-o", tmp_path / "x.csv")
    assert code == 2 and "e.g. --topic /imu/nilspod_6f13" in text and "/signals/nilspod_6f13" in text, text
    assert "/derived/viewer" not in text and not (tmp_path / "x.csv").exists()
