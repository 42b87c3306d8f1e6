"""imulog info: compact by default (-v for every run's parameters and the twins); empty channels show that."""

from __future__ import annotations

import json
import shutil

import numpy as np
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.model import ImuStream, Recording, SignalStream


def run(*args) -> str:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


def test_compact_by_default_everything_with_v(processed_r2g):
    short, full = run("info", processed_r2g), run("info", processed_r2g, "-v")
    with TrialReader(processed_r2g) as trial:
        twins = [c.topic for c in trial.channels if c.metadata.get("twin_of")]
        n_runs = len(trial.runs())
    assert twins and all(t not in short for t in twins) and all(t in full for t in twins)
    assert f"+ {len(twins)} viewer twins under /derived/viewer/" in short
    assert "params=" not in short and full.count("params=") == n_runs
    assert max(len(line) for line in short.splitlines()) <= 160  # no 1-2 kB line per run
    assert len(short) < 0.5 * len(full)
    assert "#1 orientation:wrist" in short and "/derived/phases/wrist" in short


def test_a_channel_without_samples_shows_no_rate_duration_or_gaps(tmp_path):
    t = np.arange(100, dtype=np.int64) * 10_000_000
    imu = ImuStream("wrist", t, acc=np.zeros((100, 3)), gyr=np.zeros((100, 3)))
    empty = SignalStream("/derived/x", np.zeros(0, np.int64), ["a"], ["1"], np.zeros((0, 1)))
    path = write_trial(tmp_path / "e.mcap", Recording(imus=[imu], signals=[empty]))
    row = next(line for line in run("info", path).splitlines() if "/derived/x" in line)
    assert row.split()[:7] == ["/derived/x", "[empty]", "imulog.SignalBlock", "-", "0", "-", "-"]


def _after_a_channel_record(data: bytes, near: int) -> int:
    """The end of the last top-level MCAP Channel record before byte ``near`` (or the first one after it): a cut
    there keeps the channel's record and loses every chunk of its messages (a writer puts a channel's record just
    before the chunk of its first message), whatever the storage layout makes the file's size."""
    ends, pos = [], 8  # past the magic
    while pos + 9 <= len(data):
        op, length = data[pos], int.from_bytes(data[pos + 1 : pos + 9], "little")
        if op == 0x0F:  # DataEnd: the summary follows
            break
        if op == 0x04:  # Channel
            ends.append(pos + 9 + length)
        pos += 9 + length
    before = [e for e in ends if e <= near]
    return before[-1] if before else ends[0]


def test_salvaged_trial_channel_lost_at_the_cut_is_empty(processed_r2g, tmp_path):
    """Half a processed trial, salvaged: the channels whose chunks were past the cut hold nothing, and info says
    so (it used to print their recorded rate, samples and duration)."""
    cut = tmp_path / "cut.mcap"
    data = processed_r2g.read_bytes()
    cut.write_bytes(data[: _after_a_channel_record(data, len(data) // 2)])
    shutil.copy(cut, tmp_path / "keep.mcap")
    run("salvage", cut, "-o", tmp_path / "fixed.mcap")
    text = run("info", tmp_path / "fixed.mcap", "-v")  # -v: viewer twins too
    doc = json.loads(run("info", tmp_path / "fixed.mcap", "--json"))
    empty = [c for c in doc["channels"] if c["messages"] == 0]
    assert empty, "the cut should leave a channel without messages"
    for c in empty:
        assert c["samples"] == 0 and c["rate_hz"] is None and c["duration_s"] is None
        row = next(line for line in text.splitlines() if line.strip().startswith(c["topic"] + " "))
        assert "[empty]" in row and " 0 " in row
    kept = [c for c in doc["channels"] if c["messages"] and c["topic"] == "/imu/wrist"]
    assert kept and kept[0]["samples"] > 0


def test_a_unit_the_source_does_not_state_shows_as_a_question_mark(shared_data, tmp_path):
    """LabRecorder's BioSemi test stream declares no unit for its 8 channels: the units column says ``? x8``, not
    a blank `` x8`` that reads as a misaligned table."""
    trial = tmp_path / "x.mcap"
    run("convert", shared_data / "devices" / "xdf" / "clock_resets.xdf", "-o", trial)
    (row,) = [line for line in run("info", trial).splitlines() if line.strip().startswith("/signals/biosemi")]
    assert row.rstrip().endswith("  ? x8")


def test_rate_is_samples_per_second_with_the_declared_rate_beside(shared_data, tmp_path):
    """The real AX6 .cwa (declared 100 Hz): its time stamps are quantised, so the median step said 97.56 Hz while
    the recording holds 98.41 samples per second (what the conversion warns about); info shows the latter and the
    declared rate beside it (they differ by more than 1 %). BROAD's 285.714 Hz equals its declared rate: no note."""
    cwa = tmp_path / "ax6.mcap"
    run("convert", shared_data / "devices/axivity_cwa/ax6_sample.cwa", "-o", cwa)
    doc = json.loads(run("info", cwa, "--json"))
    imu = next(c for c in doc["channels"] if c["topic"].startswith("/imu/"))
    device = doc["metadata"][f"imulog.device.{imu['topic'][5:]}"]
    assert abs(imu["mean_rate_hz"] - (imu["samples"] - 1) / imu["duration_s"]) < 1e-9
    assert abs(imu["mean_rate_hz"] - device["rate_hz"]) < 1e-3  # the conversion's rate
    assert imu["rate_hz"] < 97.6 and imu["declared_rate_hz"] == 100.0  # the median step's, kept in --json
    row = next(line for line in run("info", cwa).splitlines() if imu["topic"] in line)
    assert "98.4135 (declared 100)" in row and "97.56" not in row
    broad = tmp_path / "broad.mcap"
    run("convert", shared_data / "broad/02_undisturbed_slow_rotation_B.hdf5", "-o", broad)
    row = next(line for line in run("info", broad).splitlines() if "/imu/imu" in line)
    assert "285.714 " in row and "declared" not in row
    # a Delsys sensor's device record holds its fastest channel's rate (EMG, 1259 Hz); its IMU stream declares its
    # own 148.148 Hz, which is the one compared
    trigno = tmp_path / "trigno.mcap"
    run("convert", shared_data / "devices/delsys_trigno/truncated_trigno_sample.csv", "-o", trigno)
    rows = [line for line in run("info", trigno).splitlines() if "/imu/mini_sensor" in line]
    assert len(rows) == 2 and all("148.148 " in r and "declared" not in r for r in rows), rows
