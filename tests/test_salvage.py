"""imulog salvage: recover every intact chunk of a truncated or damaged MCAP file (imulog's or the mcap library's)."""

from __future__ import annotations

import hashlib
import random
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_archive_helpers import synthetic_recording

from imulog.archive import TrialReader, _builder, append_derived, write_trial
from imulog.archive import _mcap as m
from imulog.archive.doctor import check_file
from imulog.archive.errors import ArchiveError
from imulog.archive.salvage import salvage
from imulog.cli import cli
from imulog.model import SignalStream


def _chunks_with_messages(data: bytes) -> list[tuple[int, int, list[tuple[int, bytes]]]]:
    """(record start, record end, [(channel id, payload)]) of every chunk, read from the intact file."""
    out = []
    for op, pos, body in m.iter_records(data, len(m.MAGIC), m.read_summary_from_bytes(data).data_end_offset):
        if op == m.Op.CHUNK:
            raw = m.decompress_chunk(m.parse_chunk(body))
            out.append((pos, pos + 9 + len(body), [(cid, bytes(p)) for cid, _, p in m.chunk_messages(raw)]))
    return out


@pytest.fixture(scope="module")
def many_chunks(tmp_path_factory) -> Path:
    """A trial with ~25 small chunks over 6 channels (raw and derived), an attachment and metadata."""
    tmp = tmp_path_factory.mktemp("salvage")
    src = tmp / "export.csv"
    src.write_bytes(b"t,ax\n" + b"".join(b"%d,1.5\n" % k for k in range(2000)))
    mp = pytest.MonkeyPatch()
    mp.setattr(_builder, "CHUNK_TARGET_BYTES", 24_000)
    try:
        rng = np.random.default_rng(2)
        rec = synthetic_recording(rng, n_imu=3000, sources=[src])
        path = write_trial(tmp / "trial.mcap", rec)
        t = rec.imus[0].t_ns
        append_derived(path, [SignalStream("/derived/x", t, ["v"], ["1"], rng.normal(size=len(t)))], run={"step": "x"})
    finally:
        mp.undo()
    assert check_file(path).ok
    return path


def _recovered(path: Path) -> dict[str, list[bytes]]:
    with TrialReader(path) as tr:
        return {c.topic: [bytes(p) for p in tr.messages(c.topic)] for c in tr.channels}  # viewer twins included


def _expected_prefix(data: bytes, cut: int) -> dict[int, list[bytes]]:
    """Per channel id of the intact file: messages of the chunks that end at or before ``cut``."""
    out: dict[int, list[bytes]] = {}
    for _, end, msgs in _chunks_with_messages(data):
        if end <= cut:
            for cid, p in msgs:
                out.setdefault(cid, []).append(p)
    return out


def test_intact_file_salvages_to_an_identical_sound_trial(many_chunks, tmp_path):
    before = hashlib.sha256(many_chunks.read_bytes()).hexdigest()
    report = salvage(many_chunks, tmp_path / "fixed.mcap")
    assert report.complete and report.summary_found
    assert hashlib.sha256(many_chunks.read_bytes()).hexdigest() == before  # input untouched
    assert check_file(tmp_path / "fixed.mcap").ok  # raw-data hash recorded at conversion still holds
    assert _recovered(tmp_path / "fixed.mcap") == _recovered(many_chunks)
    with TrialReader(tmp_path / "fixed.mcap") as a, TrialReader(many_chunks) as b:
        assert [x.data for x in a.attachments()] == [x.data for x in b.attachments()]
        assert {k: v for k, v in a.metadata.items() if k != "imulog.salvage"} == b.metadata


def test_every_chunk_before_a_random_cut_is_recovered(many_chunks, tmp_path):
    data = many_chunks.read_bytes()
    with TrialReader(many_chunks) as tr:
        topic_of = {c.id: c.topic for c in tr.summary.channels.values()}
    chunks = _chunks_with_messages(data)
    assert len(chunks) >= 20
    rng = random.Random(7)
    cuts = sorted({rng.randrange(200, len(data)) for _ in range(30)} | {chunks[3][1], chunks[3][1] - 1})
    out = tmp_path / "fixed.mcap"
    for cut in cuts:
        broken = tmp_path / "cut.mcap"
        broken.write_bytes(data[:cut])
        try:
            salvage(broken, out, overwrite=True)
        except ArchiveError as exc:  # only when not even the first chunk survived: nothing recoverable
            assert cut < chunks[0][1] and "nothing recoverable" in str(exc), f"cut at {cut}: {exc}"
            continue
        got = _recovered(out)
        for cid, payloads in _expected_prefix(data, cut).items():
            assert got.get(topic_of[cid], [])[: len(payloads)] == payloads, f"cut at {cut}: {topic_of[cid]}"
            assert len(got[topic_of[cid]]) == len(payloads), f"cut at {cut}: extra messages in {topic_of[cid]}"
        assert check_file(out).ok, (cut, check_file(out).problems)  # recomputed channel records, raw record


def test_a_damaged_chunk_is_dropped_and_everything_else_kept(many_chunks, tmp_path):
    data = bytearray(many_chunks.read_bytes())
    chunks = _chunks_with_messages(bytes(data))
    start, end, msgs = chunks[5]
    data[start + (end - start) // 2] ^= 0x10  # inside the compressed data
    broken = tmp_path / "flipped.mcap"
    broken.write_bytes(bytes(data))
    report = salvage(broken, tmp_path / "fixed.mcap")
    assert any(f"chunk at byte {start}" in line for line in report.lost)
    with TrialReader(many_chunks) as tr:
        topic = tr.summary.channels[msgs[0][0]].topic
    assert report.channels[topic]["chunks_lost"] == 1
    got = _recovered(tmp_path / "fixed.mcap")
    want: dict[int, list[bytes]] = {}
    for k, (_, _, ms) in enumerate(chunks):
        if k != 5:
            for cid, p in ms:
                want.setdefault(cid, []).append(p)
    with TrialReader(many_chunks) as tr:
        for cid, payloads in want.items():
            assert got[tr.summary.channels[cid].topic] == payloads
    assert check_file(tmp_path / "fixed.mcap").ok  # sound: the partial channel's records and imulog.raw recomputed
    with TrialReader(tmp_path / "fixed.mcap") as tr, TrialReader(many_chunks) as orig:
        record = tr.metadata["imulog.salvage"]
        assert record["partial_channels"] == [topic]
        assert record["raw_original"]["sha256"] == orig.metadata["imulog.raw"]["sha256"]
        ((after, before),) = record["lost_spans"][topic]["spans"]  # one chunk lost: one span, between its neighbours
        lost = orig.read(topic)
        kept = tr.read(topic)
        t_lost = np.setdiff1d(lost.t_ns, kept.t_ns)
        assert len(t_lost) and after < t_lost.min() and t_lost.max() < before
        assert tr.channel(topic).sample_count == len(kept.t_ns) == len(lost.t_ns) - len(t_lost)


def test_mcap_library_file_without_summary(tmp_path):
    """Another writer: schemas and channels inside chunks, several channels per chunk, cut before the summary."""
    from mcap.writer import Writer

    path = tmp_path / "other.mcap"
    expected: dict[str, list[bytes]] = {"/a": [], "/b": []}
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=2000)
        w.start(profile="", library="test")
        sid = w.register_schema("S", "jsonschema", b"{}")
        ids = {t: w.register_channel(t, "json", sid) for t in expected}
        for k in range(600):
            t = "/a" if k % 3 else "/b"
            payload = b'{"k": %d}' % k
            w.add_message(ids[t], log_time=k * 1000, data=payload, publish_time=k * 1000)
            expected[t].append(payload)
        w.finish()
    data = path.read_bytes()
    summary_start = m.read_summary_from_bytes(data).summary_start
    chunks = [(s, e) for s, e, _ in _chunks_with_messages(data)]
    assert len(chunks) > 10
    rng = random.Random(3)
    for cut in sorted({rng.randrange(chunks[0][1], summary_start) for _ in range(12)} | {summary_start}):
        broken = tmp_path / "cut.mcap"
        broken.write_bytes(data[:cut])
        report = salvage(broken, tmp_path / "fixed.mcap", overwrite=True)
        got = _recovered(tmp_path / "fixed.mcap")
        n_whole = sum(1 for _, e in chunks if e <= cut)
        want = _expected_prefix(data, cut)
        with TrialReader(path) as tr:
            for cid, payloads in want.items():
                topic = tr.summary.channels[cid].topic
                assert got[topic] == payloads, f"cut at {cut}"
        assert sum(c["chunks_kept"] for c in report.channels.values()) >= n_whole


def test_cli_salvage_refuses_its_input_as_output_and_reports_losses(many_chunks, tmp_path):
    runner = CliRunner()
    res = runner.invoke(cli, ["salvage", str(many_chunks), "-o", str(many_chunks)])
    assert res.exit_code == 1 and "must not be the input" in res.output
    broken = tmp_path / "cut.mcap"
    broken.write_bytes(many_chunks.read_bytes()[: many_chunks.stat().st_size // 2])
    res = runner.invoke(cli, ["salvage", str(broken), "-o", str(tmp_path / "fixed.mcap")])
    assert res.exit_code == 0, res.output
    assert "recovered" in res.output and "lost:" in res.output
    not_mcap = tmp_path / "junk.mcap"
    not_mcap.write_bytes(b"hello world" * 10)
    res = runner.invoke(cli, ["salvage", str(not_mcap), "-o", str(tmp_path / "x.mcap")])
    assert res.exit_code == 1 and "not an MCAP file" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "x.mcap").exists()


def test_salvage_does_not_launder_a_damaged_metadata_record(many_chunks, tmp_path):
    """Metadata records have no CRC of their own: the data-section CRC locates the damaged byte, the record goes."""
    data = bytearray(many_chunks.read_bytes())
    with TrialReader(many_chunks) as tr:
        idx = next(i for i in tr.summary.metadata_indexes if i.name == "imulog.trial")
    data[idx.offset + idx.length - 3] ^= 0x01  # inside the last value of the record
    broken = tmp_path / "meta.mcap"
    broken.write_bytes(bytes(data))
    assert not check_file(broken).ok
    report = salvage(broken, tmp_path / "fixed.mcap")
    assert report.data_crc == "mismatch" and "imulog.trial" not in report.metadata
    assert any(d.startswith(f"imulog.trial at byte {idx.offset}") for d in report.dropped_metadata), report
    assert "imulog.raw" in report.metadata and "imulog.anthropometrics" in report.metadata  # the intact ones stay
    assert check_file(tmp_path / "fixed.mcap").ok
    with TrialReader(tmp_path / "fixed.mcap") as tr:
        assert "imulog.trial" not in tr.metadata
        assert tr.metadata["imulog.salvage"]["dropped_metadata"] == report.dropped_metadata


def test_exit_1_with_one_line_when_nothing_is_recoverable_or_the_output_would_fail_doctor(many_chunks, tmp_path):
    """Exit 0 only for an output that passes doctor: a cut inside the first chunk, or messages that pass their
    chunk's CRC but do not decode, give exit 1, one line, and no output."""
    from mcap.writer import Writer

    from imulog.archive import codec

    data = many_chunks.read_bytes()
    first_end = _chunks_with_messages(data)[0][1]
    runner = CliRunner()
    cut = tmp_path / "first_chunk_cut.mcap"
    cut.write_bytes(data[: first_end - 10])
    res = runner.invoke(cli, ["salvage", str(cut), "-o", str(tmp_path / "a.mcap")])
    assert res.exit_code == 1 and "nothing recoverable" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "a.mcap").exists()

    garbage = tmp_path / "garbage.mcap"  # a sound MCAP file whose imulog.ImuBlock messages are not protobuf
    with open(garbage, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("imulog.ImuBlock", "protobuf", codec.file_descriptor_set("imulog.ImuBlock"))
        ch = w.register_channel("/imu/x", "protobuf", sid)
        for k in range(10):
            w.add_message(ch, log_time=k, data=b"\xff\xff\xff\xff", publish_time=k)
        w.finish()
    res = runner.invoke(cli, ["salvage", str(garbage), "-o", str(tmp_path / "b.mcap")])
    assert res.exit_code == 1 and "would not pass doctor" in res.output and "/imu/x" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "b.mcap").exists()


def test_crc_locates_one_damaged_byte_and_only_one():
    """The locator behind salvage's metadata check: one damaged byte is found exactly, in or out of the ranges
    tried; the stored CRC's own damage is told apart; two damaged bytes are (almost always) not pinned on one."""
    import zlib

    from imulog.archive.crc_locate import crc_field_damage, locate_byte_error

    rng = random.Random(11)
    wrong = 0
    for _ in range(100):
        n = rng.randrange(50, 20_000)
        data = rng.randbytes(n)
        p = rng.randrange(n)
        bad = bytearray(data)
        bad[p] ^= rng.randrange(1, 256)
        syndrome = zlib.crc32(data) ^ zlib.crc32(bytes(bad))
        assert locate_byte_error(syndrome, n, [(0, n // 2), (n // 2, n)]) == p
        assert locate_byte_error(syndrome, n, [(0, p), (p + 1, n)]) is None  # not where it is not
        assert not crc_field_damage(syndrome)
        bad[(p + 1 + rng.randrange(n - 1)) % n] ^= rng.randrange(1, 256)
        wrong += locate_byte_error(zlib.crc32(data) ^ zlib.crc32(bytes(bad)), n, [(0, n)]) is not None
    assert wrong <= 1
    assert crc_field_damage(0x00AB0000) and not crc_field_damage(0x01010000)


def test_a_streamed_trial_keeps_the_final_stream_meta(tmp_path, monkeypatch):
    """A trial written piece by piece whose stream meta changed after its first piece (the closing statistics record
    holds the final one): salvaged intact, and with one of its chunks damaged, readers still see the final meta."""
    import json

    import imulog.archive.streaming as streaming
    from imulog.model import ImuStream, Recording

    rng = np.random.default_rng(4)
    monkeypatch.setattr(streaming, "CHUNK_TARGET_BYTES", 4096)
    path = tmp_path / "streamed.mcap"
    with streaming.StreamingTrialWriter(path) as w:
        for k in range(4):
            t = (k * 500 + np.arange(500)) * 10_000_000
            w.write(Recording(imus=[ImuStream("wrist", t, acc=rng.normal(size=(500, 3)), meta={"missing": k})]))
    assert w.meta_changes == ["/imu/wrist: its meta changed after the channel was written (missing)"]
    with TrialReader(path) as tr:
        assert json.loads(tr.channel("/imu/wrist").metadata["meta"]) == {"missing": 3}
    salvage(path, tmp_path / "intact.mcap")
    data = bytearray(path.read_bytes())
    with TrialReader(path) as tr:
        imu = next(c.id for c in tr.summary.channels.values() if c.topic == "/imu/wrist")
    start, end, _ = [c for c in _chunks_with_messages(bytes(data)) if c[2][0][0] == imu][1]
    data[start + (end - start) // 2] ^= 0x10
    (tmp_path / "flipped.mcap").write_bytes(bytes(data))
    report = salvage(tmp_path / "flipped.mcap", tmp_path / "fixed.mcap")
    assert report.channels["/imu/wrist"]["chunks_lost"] == 1
    for out in ("intact.mcap", "fixed.mcap"):
        assert check_file(tmp_path / out).ok
        with TrialReader(tmp_path / out) as tr:
            assert json.loads(tr.channel("/imu/wrist").metadata["meta"]) == {"missing": 3}, out
            assert tr.read("/imu/wrist").meta == {"missing": 3}
