"""``imulog convert`` of files sniffs each file's format once (issue 24): the streaming decision and the conversion
share one detection, whether the file is converted whole or piece by piece."""

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
