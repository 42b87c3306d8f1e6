"""The pieces of ``imulog record`` without a network: the stream mapping from LSL headers, the stream filters, and
the live writer's flushed ``.part`` file (a copy taken at any moment salvages into a trial doctor accepts)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.archive.errors import ArchiveLockedError
from imulog.cli import cli
from imulog.live.lsl import StreamFilter, config_summary, shared_names
from imulog.live.mapping import chunk_to_recording, header_info, stream_names
from imulog.live.writer import LiveTrialWriter, part_path
from imulog.model import ImuStream, Recording


def header(name: str, stype: str, labels: list[str], units: list[str], fmt: str = "float32", rate: float = 100.0):
    channels = "".join(
        f"<channel><label>{lab}</label>{f'<unit>{u}</unit>' if u else ''}</channel>"
        for lab, u in zip(labels, units, strict=True)
    )
    return (
        f'<?xml version="1.0"?><info><name>{name}</name><type>{stype}</type><channel_count>{len(labels)}'
        f"</channel_count><channel_format>{fmt}</channel_format><source_id>x</source_id><nominal_srate>{rate}"
        f"</nominal_srate><desc><channels>{channels}</channels></desc></info>"
    )


def test_imu_stream_by_labels_and_units_in_si():
    labels = ["AccX", "AccY", "AccZ", "GyroX", "GyroY", "GyroZ", "battery"]
    units = ["g", "g", "g", "deg/s", "deg/s", "deg/s", "V"]
    info = header_info(header("Wrist IMU", "IMU", labels, units), 1)
    t = np.array([10.0, 10.01])
    samples = [[0, 0, 1, 90, 0, 0, 3.7], [0, 1, 0, 0, 180, 0, 3.6]]
    rec = chunk_to_recording(info, "wrist_imu", t, samples, "lsl:wrist_imu")
    (imu,) = rec.imus
    assert imu.topic == "/imu/wrist_imu"
    np.testing.assert_allclose(imu.acc[0], [0, 0, 9.80665])
    np.testing.assert_allclose(imu.gyr[1], [0, np.pi, 0])
    np.testing.assert_array_equal(imu.t_ns, [10_000_000_000, 10_010_000_000])
    (rest,) = rec.signals  # the channel that is not an IMU quantity stays a signal, with its unit
    assert rest.topic == "/signals/wrist_imu" and rest.columns == ["battery"] and rest.units == ["V"]
    assert rec.metadata["imulog.device.wrist_imu"]["stream_type"] == "IMU"


def test_mocap_markers_strings_events_and_plain_signals():
    info = header_info(header("Cam", "MoCap", ["RSHO_X", "RSHO_Y", "RSHO_Z"], ["mm"] * 3), 2)
    rec = chunk_to_recording(info, "cam", np.array([1.0]), [[1000.0, 20.0, float("nan")]], "lsl:cam")
    (mk,) = rec.markers
    assert mk.labels == ["RSHO"] and not mk.valid[0, 0]  # NaN = occluded
    info = header_info(header("Events", "Markers", ["label"], [""], fmt="string", rate=0), 3)
    rec = chunk_to_recording(info, "events", np.array([1.0, 2.5]), [["go"], ["stop"]], "lsl:events")
    (ev,) = rec.events
    assert ev.topic == "/events/events" and ev.labels == ["go", "stop"]
    np.testing.assert_array_equal(ev.start_ns, ev.end_ns)
    info = header_info(header("EMG", "EMG", ["bic", "tri"], ["mV", "mV"]), 4)
    rec = chunk_to_recording(info, "emg", np.array([1.0]), [[0.1, 0.2]], "lsl:emg")
    assert not rec.imus and rec.signals[0].columns == ["bic", "tri"] and rec.signals[0].units == ["mV", "mV"]


def test_names_and_filters():
    assert stream_names(["Wrist IMU", "EMG", "EMG"]) == ["wrist_imu", "emg_2", "emg_3"]
    assert StreamFilter.parse("type = IMU") == StreamFilter("type", "IMU")
    assert str(StreamFilter.parse("source_id=xio:12=3")) == "source_id=xio:12=3"
    for bad in ("colour=red", "name=", "IMU"):
        with pytest.raises(ValueError, match="name=, type=, source_id=VALUE"):
            StreamFilter.parse(bad)
    with pytest.raises(ValueError, match="not valid XML"):
        header_info("<info><name>cut", 1)


class _Info:
    """The part of a pylsl StreamInfo that shared_names reads."""

    def __init__(self, name: str, source_id: str, host: str = "lab") -> None:
        self._n, self._s, self._h = name, source_id, host

    def name(self) -> str:
        return self._n

    def source_id(self) -> str:
        return self._s

    def hostname(self) -> str:
        return self._h


def test_streams_of_one_name_are_told_apart_by_source_id():
    infos = [_Info("wrist", "xio-1"), _Info("vicon", "vicon-1"), _Info("wrist", "replay:/imu/wrist", "vm")]
    assert shared_names(infos) == [
        "2 streams are named wrist (source_id xio-1 on host lab; source_id replay:/imu/wrist on host vm): all are "
        "recorded; to record one, pick it with --stream source_id=..."
    ]
    assert shared_names(infos[:2]) == []


def test_the_lsl_configuration_that_decides_what_is_visible(tmp_path):
    """The error that finds no stream names the configuration in use: its session, scope and ports."""
    cfg = tmp_path / "lsl_api.cfg"
    cfg.write_text("[multicast]\nResolveScope = machine ; this computer\n[lab]\nSessionID = mine\n")
    assert config_summary([tmp_path / "missing.cfg", cfg]) == (
        f"LSL configuration {cfg}: SessionID mine, ResolveScope machine, MulticastPort 16571, BasePort 16572"
    )
    assert config_summary([]) == (
        "LSL configuration liblsl defaults: SessionID default, ResolveScope site, MulticastPort 16571, BasePort 16572"
    )


def _piece(k: int, n: int = 50) -> Recording:
    t = (np.arange(n) + k * n) * 10_000_000 + 5_000_000_000
    rng = np.random.default_rng(k)
    imu = ImuStream("wrist", t, acc=rng.normal(size=(n, 3)), gyr=rng.normal(size=(n, 3)))
    return Recording(imus=[imu], metadata={"imulog.device.wrist": {"format": "lsl"}})


def test_flushed_part_file_salvages_at_every_moment(tmp_path):
    out = tmp_path / "trial.mcap"
    copies = []
    with LiveTrialWriter(out, metadata={"imulog.trial": {"start_time": "2026-01-01T10:00:00+00:00"}}) as w:
        for k in range(4):
            w.write(_piece(k))
            w.flush()
            copy = tmp_path / f"cut{k}.mcap.part"
            shutil.copy(part_path(out), copy)  # what a SIGKILL right now would leave
            copies.append(copy)
        with pytest.raises(ArchiveLockedError, match="is writing this archive"):
            LiveTrialWriter(out).__enter__()  # a second recorder into the same file is refused
    assert out.exists() and not part_path(out).exists()
    runner = CliRunner()
    for k, copy in enumerate(copies):
        fixed = tmp_path / f"fixed{k}.mcap"
        assert runner.invoke(cli, ["salvage", str(copy), "-o", str(fixed)]).exit_code == 0
        doctor = runner.invoke(cli, ["doctor", str(fixed)])
        assert doctor.exit_code == 0 and ": ok" in doctor.output, doctor.output
        with TrialReader(fixed) as t:
            imu = t.read("/imu/wrist")
            assert t.metadata["imulog.trial"]["start_time"] == "2026-01-01T10:00:00+00:00"
            assert "imulog.timeline" in t.metadata
        assert len(imu.t_ns) == 50 * (k + 1)  # everything flushed before the copy
        expected = np.concatenate([_piece(j).imus[0].acc for j in range(k + 1)])
        np.testing.assert_array_equal(imu.acc, expected)
    with TrialReader(out) as t:
        assert t.channel("/imu/wrist").sample_count == 200
    assert ": ok" in runner.invoke(cli, ["doctor", str(out)]).output


def test_a_kill_before_the_first_sample_leaves_an_mcap_start_salvage_names(tmp_path):
    out = tmp_path / "trial.mcap"
    copy = tmp_path / "early.mcap.part"
    with LiveTrialWriter(out, metadata={"imulog.trial": {"start_time": "2026-01-01T10:00:00+00:00"}}) as w:
        shutil.copy(part_path(out), copy)  # what a SIGKILL before any stream sent a sample would leave
        w.write(_piece(0))
    assert copy.read_bytes().startswith(b"\x89MCAP")  # the magic and header were fsynced at open
    result = CliRunner().invoke(cli, ["salvage", str(copy), "-o", str(tmp_path / "fixed.mcap")])
    assert result.exit_code == 1
    assert result.output.strip().splitlines() == [
        f"Error: {copy}: nothing recoverable: cut before any channel was written"
    ]
    assert not (tmp_path / "fixed.mcap").exists()


def test_an_error_keeps_the_part_file_only_with_samples(tmp_path):
    out = tmp_path / "trial.mcap"
    with pytest.raises(RuntimeError), LiveTrialWriter(out):
        raise RuntimeError("no stream answered")
    assert not out.exists() and not part_path(out).exists()  # nothing was recorded: nothing is left
    with pytest.raises(RuntimeError), LiveTrialWriter(out) as w:
        w.write(_piece(0))
        w.write(_piece(1))  # written, not flushed yet: the error flushes it
        raise RuntimeError("device unplugged")
    assert not out.exists() and w.kept_part and part_path(out).exists()
    fixed = tmp_path / "fixed.mcap"
    assert CliRunner().invoke(cli, ["salvage", str(part_path(out)), "-o", str(fixed)]).exit_code == 0
    with TrialReader(fixed) as t:
        assert len(t.read("/imu/wrist").t_ns) == 100
