"""``imulog convert`` sniffs each file's format once (issue 24): of files, the streaming decision and the conversion
share one detection, whether the file is converted whole or piece by piece; of folders, the grouping's detection is
the one the sessions, the sibling metadata, the session reader and the conversion use (``--inspect`` too)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest
from click.testing import CliRunner
from imulog.converters import registry

from imulog.archive import TrialReader
from imulog.cli import cli

REPO = Path(__file__).resolve().parents[1]
SIM = REPO / "recordings" / "sim"


@pytest.fixture
def detections(monkeypatch) -> Counter:
    """Every call of the format detector, counted by file name (both names it is imported under)."""
    calls: Counter = Counter()
    real = registry.detect

    def counting(path):
        calls[Path(path).name] += 1
        return real(path)

    monkeypatch.setattr("imulog.converters.registry.detect", counting)
    monkeypatch.setattr("imulog.commands.convert_common.detect", counting)
    monkeypatch.setattr("imulog.commands.convert_folders.detect", counting)
    return calls


def _convert(*args: str) -> str:
    result = CliRunner().invoke(cli, ["convert", *args])
    assert result.exit_code == 0, result.output
    return result.output


def test_imu_and_vicon_files_are_each_detected_once(detections, tmp_path):
    imu, vicon = SIM / "r2g_s00_t00_imu.csv", SIM / "r2g_s00_t00_vicon.csv"
    out = tmp_path / "t.mcap"
    _convert(str(imu), str(vicon), "-o", str(out))
    assert detections == Counter({imu.name: 1, vicon.name: 1})
    with TrialReader(out) as t:
        formats = t.metadata["imulog.conversion"]["formats"]
    assert formats == {imu.name: "delimited", vicon.name: "vicon-csv"}


@pytest.mark.parametrize("streamed", [False, True])
def test_one_file_is_detected_once_whole_or_piece_by_piece(detections, tmp_path, monkeypatch, streamed):
    imu = SIM / "r2g_s00_t00_imu.csv"
    if streamed:
        monkeypatch.setattr("imulog.commands.convert_stream.STREAM_MIN_BYTES", 0)  # any file is "large"
    output = _convert(str(imu), "-o", str(tmp_path / "t.mcap"))
    assert ("converted piece by piece" in output) == streamed, output
    assert detections == Counter({imu.name: 1})


def test_forced_format_is_not_detected(detections, tmp_path):
    _convert(str(SIM / "r2g_s00_t00_vicon.csv"), "--format", "vicon-csv", "-o", str(tmp_path / "v.mcap"))
    assert not detections


def test_undetectable_file_fails_with_one_line_and_no_trial(detections, tmp_path):
    junk = tmp_path / "notes.csv"
    junk.write_text("hello,world\n1,2\n")
    out = tmp_path / "t.mcap"
    result = CliRunner().invoke(cli, ["convert", str(junk), "-o", str(out)])
    assert result.exit_code != 0 and "notes.csv" in result.output, result.output
    assert not out.exists()
    assert detections == Counter({junk.name: 1})


def test_folder_files_are_each_detected_once(detections, tmp_path):
    """A folder with an IMU export and an optical one beside it (one session: the optical test and the sibling
    metadata see the grouping's formats) is one trial, each file detected once."""
    imu, vicon = SIM / "r2g_s00_t00_imu.csv", SIM / "r2g_s00_t00_vicon.csv"
    _convert(str(SIM), "-o", str(tmp_path / "out"))
    assert detections == Counter({imu.name: 1, vicon.name: 1})  # mapping, metadata and truth files are not data
    with TrialReader(tmp_path / "out" / "r2g_s00_t00.mcap") as t:
        formats = t.metadata["imulog.conversion"]["formats"]
        subject = t.metadata["imulog.trial"].get("subject")
    assert formats == {imu.name: "delimited", vicon.name: "vicon-csv"}
    assert subject is not None  # r2g_s00_t00_meta.json beside the exports was found through the detected format


@pytest.mark.parametrize("streamed", [False, True])
def test_session_folder_is_detected_once_whole_or_piece_by_piece(
    detections, shared_data, tmp_path, monkeypatch, streamed
):
    """The Empatica E4 folder (a session read by one converter): each file detected once, whether the session is
    read whole or in time windows."""
    folder = shared_data / "devices" / "empatica_e4"
    monkeypatch.setattr("imulog.commands.convert_stream.STREAM_MIN_BYTES", 0 if streamed else 1 << 60)
    out = tmp_path / "e4.mcap"
    output = _convert(str(folder), "-o", str(out))
    assert ("converted piece by piece" in output) == streamed, output
    data = sorted(p.name for p in folder.iterdir() if p.suffix == ".csv")
    assert data and all(detections[name] == 1 for name in data), detections
    assert set(detections) - set(data) <= {p.name for p in folder.glob("LICENSE*")}  # a licence is looked at once
    with TrialReader(out) as t:
        conversion = t.metadata["imulog.conversion"]
    assert conversion["formats"] == dict.fromkeys(data, "empatica-e4")
    assert bool(conversion.get("streamed")) == streamed


def test_folder_file_that_fails_is_left_out_after_one_detection(detections, tmp_path):
    """A file detected as an optical export that then fails to convert is skipped with its reason; the rest make
    the trial, and nothing is detected again while retrying without it."""
    folder = tmp_path / "in"
    folder.mkdir()
    imu = SIM / "r2g_s00_t00_imu.csv"
    (folder / imu.name).write_bytes(imu.read_bytes())
    (folder / "r2g_s00_t00_imu.mapping.json").write_bytes((SIM / "r2g_s00_t00_imu.mapping.json").read_bytes())
    head = (SIM / "r2g_s00_t00_vicon.csv").read_text().splitlines(keepends=True)[:5]  # the header, no data rows
    (folder / "r2g_s00_t00_vicon.csv").write_text("".join(head))
    result = CliRunner().invoke(cli, ["convert", str(folder), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "skipped" in result.output and "r2g_s00_t00_vicon.csv" in result.output, result.output
    assert detections == Counter({imu.name: 1, "r2g_s00_t00_vicon.csv": 1})
    with TrialReader(tmp_path / "out" / "r2g_s00_t00.mcap") as t:
        assert t.metadata["imulog.conversion"]["formats"] == {imu.name: "delimited"}


def test_folder_inspect_detects_each_file_once(detections):
    output = _convert(str(SIM), "--inspect")
    assert "vicon-csv" in output and "delimited" in output, output
    assert detections == Counter({"r2g_s00_t00_imu.csv": 1, "r2g_s00_t00_vicon.csv": 1})
