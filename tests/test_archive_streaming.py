"""Writing a trial piece by piece (bounded memory) gives the same data as writing it at once."""

from __future__ import annotations

import numpy as np
import pytest
from imulog.converters import axivity

from imulog.archive import TrialReader, write_trial
from imulog.archive.doctor import check_file
from imulog.archive.streaming import STATS_RECORD, write_trial_streaming
from imulog.simulate.home import HomeParams, write_home_cwa


@pytest.fixture(scope="module")
def cwa(tmp_path_factory):
    path = tmp_path_factory.mktemp("stream") / "home.cwa"
    write_home_cwa(path, HomeParams(days=1 / 48, rate_hz=25.0, seed=4))
    return path


def test_pieces_equal_the_whole(cwa, tmp_path):
    whole = write_trial(tmp_path / "whole.mcap", axivity.read_cwa(cwa), attach_sources=True)
    pieces = list(axivity.iter_chunks(cwa, blocks_per_chunk=150))
    assert len(pieces) > 5
    streamed = write_trial_streaming(
        tmp_path / "streamed.mcap", iter(pieces), metadata=pieces[0].metadata, sources=[cwa]
    )
    with TrialReader(whole) as a, TrialReader(streamed) as b:
        assert a.topics() == b.topics()
        for topic in a.topics():
            sa, sb = a.read(topic), b.read(topic)
            np.testing.assert_array_equal(sa.t_ns, sb.t_ns)
            for name in ("acc", "gyr", "values"):
                if getattr(sa, name, None) is not None:
                    np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name))
            ca, cb = a.channel(topic), b.channel(topic)
            assert (ca.sample_count, ca.start_ns, ca.end_ns) == (cb.sample_count, cb.start_ns, cb.end_ns)
            assert ca.rate_hz == pytest.approx(cb.rate_hz, rel=1e-5)
            for key in ("time_gaps", "nan_samples"):
                assert ca.metadata.get(key) == cb.metadata.get(key), (topic, key)
            assert b.channel_hash(topic) == b.compute_channel_hash(topic)
        assert STATS_RECORD in b.metadata and b.metadata["imulog.trial"] == a.metadata["imulog.trial"]
        assert b.metadata["imulog.raw"]["attachments"] == a.metadata["imulog.raw"]["attachments"]
        assert [x.name for x in b.attachments()] == ["home.cwa"]
        assert b.attachments()[0].data == cwa.read_bytes()
        twins_a = sorted(c.topic for c in a.channels if c.metadata.get("twin_of"))
        twins_b = sorted(c.topic for c in b.channels if c.metadata.get("twin_of"))
        assert twins_a == twins_b
    report = check_file(streamed)
    assert not report.problems, report.problems


def test_mcap_library_reads_it(cwa, tmp_path):
    from mcap.reader import make_reader

    streamed = write_trial_streaming(tmp_path / "s.mcap", axivity.iter_chunks(cwa, blocks_per_chunk=500))
    with open(streamed, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        n = sum(1 for _ in reader.iter_messages(topics=["/imu/ax6_4321"]))
    assert (
        n
        == summary.statistics.channel_message_counts[
            next(c.id for c in summary.channels.values() if c.topic == "/imu/ax6_4321")
        ]
    )


def test_failure_leaves_nothing(cwa, tmp_path):
    def broken():
        yield from axivity.iter_chunks(cwa, blocks_per_chunk=150)
        raise RuntimeError("the source went away")

    out = tmp_path / "broken.mcap"
    with pytest.raises(RuntimeError):
        write_trial_streaming(out, broken())
    assert not out.exists() and not list(tmp_path.glob("*.tmp*"))


def test_convert_streams_large_files(cwa, tmp_path, monkeypatch):
    from click.testing import CliRunner

    from imulog.cli import cli
    from imulog.commands import convert_stream as convert_command

    monkeypatch.setattr(convert_command, "STREAM_MIN_BYTES", 0)  # every file counts as large here
    out = tmp_path / "streamed.mcap"
    result = CliRunner().invoke(cli, ["convert", str(cwa), "-o", str(out), "--meta", "subject=S07"])
    assert result.exit_code == 0, result.output
    assert "converted piece by piece" in result.output
    monkeypatch.setattr(convert_command, "STREAM_MIN_BYTES", 1 << 40)
    whole = tmp_path / "whole.mcap"
    assert CliRunner().invoke(cli, ["convert", str(cwa), "-o", str(whole)]).exit_code == 0
    with TrialReader(out) as a, TrialReader(whole) as b:
        np.testing.assert_array_equal(a.read("/imu/ax6_4321").acc, b.read("/imu/ax6_4321").acc)
        assert a.metadata["imulog.trial"]["subject"] == "S07"
        assert a.metadata["imulog.trial"]["start_time"] == b.metadata["imulog.trial"]["start_time"]
        assert a.metadata["imulog.conversion"]["streamed"] is True
        assert a.metadata["imulog.conversion"]["sha256"] == b.metadata["imulog.conversion"]["sha256"]
    assert CliRunner().invoke(cli, ["doctor", str(out)]).exit_code == 0
    # a damaged block stops the streamed conversion with the block named, and leaves nothing
    damaged = tmp_path / "damaged.cwa"
    data = bytearray(cwa.read_bytes())
    data[1024 + 512 * 700 + 100] ^= 0xFF
    damaged.write_bytes(bytes(data))
    monkeypatch.setattr(convert_command, "STREAM_MIN_BYTES", 0)
    bad = CliRunner().invoke(cli, ["convert", str(damaged), "-o", str(tmp_path / "bad.mcap")])
    assert bad.exit_code != 0 and "data block 700" in bad.output
    assert not (tmp_path / "bad.mcap").exists()
