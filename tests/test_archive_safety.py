"""Damage and interruption: doctor finds every flipped byte and truncation; a killed append changes nothing."""

from __future__ import annotations

import contextlib
import os
import random
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_archive_helpers import synthetic_recording

from imulog.archive import ArchiveCorruptError, TrialReader, append_derived, write_trial
from imulog.archive import _mcap as m
from imulog.archive.doctor import check_file
from imulog.archive.files import writer_lock
from imulog.archive.journal import journal_path
from imulog.cli import cli
from imulog.model import SignalStream


@pytest.fixture(scope="module")
def small_trial(tmp_path_factory) -> Path:
    """A small trial with every record type: raw chunks, attachment, metadata, an appended derived channel."""
    tmp = tmp_path_factory.mktemp("safety")
    src = tmp / "source.csv"
    src.write_bytes(b"t,ax\n0,1.0\n1,2.0\n")
    rng = np.random.default_rng(5)
    rec = synthetic_recording(rng, n_imu=200, sources=[src])
    rec.markers[0] = type(rec.markers[0])(
        "vicon", rec.markers[0].t_ns[:150], ["O", "X", "Y", "A"], rec.markers[0].pos[:150]
    )
    rec.analogs[0] = type(rec.analogs[0])(
        "emg", rec.analogs[0].t_ns[:150], ["a", "b"], ["V", "V"], rec.analogs[0].values[:150]
    )
    rec.poses[0] = type(rec.poses[0])("/poses/cluster", rec.poses[0].t_ns[:20], rec.poses[0].position[:20])
    path = write_trial(tmp / "small.mcap", rec)
    t = rec.imus[0].t_ns
    append_derived(path, [SignalStream("/derived/x", t, ["v"], ["1"], rng.normal(size=len(t)))], run={"step": "x"})
    assert check_file(path).ok
    return path


def _record_boundaries(data: bytes) -> list[int]:
    """Start offset of every record in the file (data section, summary, footer) and the closing magic."""
    offsets = []
    pos = len(m.MAGIC)
    while pos < len(data) - len(m.MAGIC):
        offsets.append(pos)
        op, length = m._REC.unpack_from(data, pos)
        pos += 9 + length
    return [*offsets, len(data) - len(m.MAGIC)]


def _positions(data: bytes, n_random: int, seed: int) -> list[int]:
    rng = random.Random(seed)
    edges = _record_boundaries(data)
    around = {p + d for p in edges for d in (0, 1, 8, 9) if 0 <= p + d < len(data)}  # opcode, length, first field
    around |= set(range(8)) | set(range(len(data) - 8 - m.FOOTER_SIZE, len(data)))  # magics and footer
    return sorted(around | {rng.randrange(len(data)) for _ in range(n_random)})


def test_doctor_reports_every_flipped_byte(small_trial, tmp_path):
    data = small_trial.read_bytes()
    bad = tmp_path / "flipped.mcap"
    positions = _positions(data, n_random=150, seed=1)
    assert len(positions) > 250
    missed = []
    for pos in positions:
        corrupted = bytearray(data)
        corrupted[pos] ^= 1 << (pos % 8)
        bad.write_bytes(corrupted)
        report = check_file(bad)
        if report.ok:
            missed.append(pos)
    assert not missed, f"flips at {missed[:10]} went unnoticed"


def test_doctor_reports_every_truncation(small_trial, tmp_path):
    data = small_trial.read_bytes()
    bad = tmp_path / "cut.mcap"
    rng = random.Random(2)
    cuts = sorted(set(_record_boundaries(data)) | {rng.randrange(1, len(data)) for _ in range(60)} | {0, len(data) - 1})
    for cut in cuts:
        bad.write_bytes(data[:cut])
        assert not check_file(bad).ok, cut


def test_doctor_cli_exit_codes_and_one_line_reasons(small_trial, tmp_path):
    runner = CliRunner()
    res = runner.invoke(cli, ["doctor", str(small_trial)])
    assert res.exit_code == 0 and "raw-data hash ok" in res.output
    data = small_trial.read_bytes()
    with TrialReader(small_trial) as tr:
        chunk = tr.summary.chunk_indexes[0]
    cases = {
        # a byte inside the first chunk's compressed data
        "chunk": (chunk.chunk_start_offset + chunk.chunk_length - 10, "chunk"),
        # a byte of the summary section
        "summary": (len(data) - 8 - m.FOOTER_SIZE - 5, "summary CRC mismatch"),
    }
    for name, (pos, reason) in cases.items():
        corrupted = bytearray(data)
        corrupted[pos] ^= 0xFF
        bad = tmp_path / f"{name}.mcap"
        bad.write_bytes(corrupted)
        res = runner.invoke(cli, ["doctor", str(bad)])
        assert res.exit_code == 1, name
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and reason in lines[0], res.output
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: chunk.chunk_start_offset + chunk.chunk_length // 2])  # mid-chunk
    res = runner.invoke(cli, ["doctor", str(cut)])
    assert res.exit_code == 1 and "truncated" in res.output


def test_doctor_detects_modified_raw_data_even_with_valid_crcs(small_trial, tmp_path):
    """A rewritten raw channel with correct CRCs (e.g. edited by another tool) fails the raw-data hash."""
    from imulog.archive import _builder
    from imulog.archive.writer import write_stream

    with TrialReader(small_trial) as tr:
        imu = tr.read("/imu/wrist")
        others = [tr.read(t) for t in tr.topics() if t != "/imu/wrist"]
        metadata = tr.metadata
    imu.acc[0, 0] += 1e-9
    forged = tmp_path / "forged.mcap"
    with open(forged, "wb") as f:
        b = _builder.McapBuilder.new(f, "forger")
        for s in [imu, *others]:
            write_stream(b, s)
        from imulog.archive.metadata import encode_record

        for name, values in metadata.items():
            b.add_metadata(name, encode_record(values))
        b.finish()
    report = check_file(forged)
    assert any("raw channel /imu/wrist changed" in p for p in report.problems), report.problems


# ----------------------------------------------------------------------------------------------- killed appends


def _derived(n: int, seed: int) -> SignalStream:
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.int64) * 1_000_000
    return SignalStream("/derived/killed", t, ["a", "b", "c", "d"], ["1"] * 4, rng.normal(size=(n, 4)))


def _fork_append(path: Path, stream: SignalStream, *, kill_at: int | None = None, wait_fd: int | None = None) -> int:
    """Fork a child that appends ``stream`` to ``path``; it SIGKILLs itself at its ``kill_at``-th I/O step."""
    pid = os.fork()
    if pid:
        return pid
    try:  # child: never returns into pytest
        if wait_fd is not None:
            os.read(wait_fd, 1)
        if kill_at is not None:
            from imulog.archive import _builder, files

            counter = [0]

            def tick():
                counter[0] += 1
                if counter[0] >= kill_at:
                    os.kill(os.getpid(), signal.SIGKILL)

            real_write, real_fsync, real_replace = _builder.McapBuilder._out, os.fsync, os.replace

            def write(self, data):
                tick()
                real_write(self, data[: len(data) // 2])  # die half-way through a write, too
                self.f.flush()
                tick()
                real_write(self, data[len(data) // 2 :])

            def fsync(fd):
                tick()
                real_fsync(fd)
                tick()

            def replace(a, b):
                tick()
                real_replace(a, b)
                tick()

            _builder.McapBuilder._out = write
            files.os.fsync = fsync
            files.os.replace = replace
        append_derived(path, [stream], run={"step": "kill-test", "algorithm": "none"})
        os._exit(0)
    except BaseException:
        os._exit(3)


def _check_after_kill(path: Path, original: bytes, conversion_end: int, stream: SignalStream) -> str:
    """What a reader sees right after the kill (before any writer ran) and what the next writer leaves (it undoes
    an unfinished append from its journal): the original trial or the complete append, the same for both."""
    assert check_file(path).ok  # doctor, too, reads an interrupted append as the trial before it
    with TrialReader(path) as tr:
        seen = "appended" if "/derived/killed" in tr.topics() else "unchanged"
        if seen == "appended":
            assert np.array_equal(tr.read("/derived/killed").values, stream.values)
    with writer_lock(path):  # what every writer does first
        pass
    assert not journal_path(path).exists()
    now = path.read_bytes()
    if now == original:
        assert seen == "unchanged"
        return "unchanged"
    assert seen == "appended"
    assert now[:conversion_end] == original[:conversion_end]
    report = check_file(path)
    assert report.ok, report.problems
    with TrialReader(path) as tr:
        back = tr.read("/derived/killed")
    assert np.array_equal(back.values, stream.values)
    return "appended"


def _steps_of_one_append(path: Path, stream: SignalStream) -> int:
    """How many I/O steps one append takes (run in a child that is killed at a step it never reaches)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            from imulog.archive import _builder, files

            n = [0]
            real_write, real_fsync, real_replace = _builder.McapBuilder._out, os.fsync, os.replace

            def write(self, data):
                n[0] += 2
                real_write(self, data)

            def fsync(fd):
                n[0] += 2
                real_fsync(fd)

            def replace(a, b):
                n[0] += 2
                real_replace(a, b)

            _builder.McapBuilder._out, files.os.fsync, files.os.replace = write, fsync, replace
            append_derived(path, [stream], run={"step": "count"})
            os.write(w, str(n[0]).encode())
            os._exit(0)
        except BaseException:
            os._exit(3)
    os.close(w)
    _, status = os.waitpid(pid, 0)
    steps = int(os.read(r, 64) or b"0")
    os.close(r)
    assert os.waitstatus_to_exitcode(status) == 0
    return steps


def test_append_killed_at_every_io_step_leaves_original_valid(small_trial, tmp_path):
    path = tmp_path / "trial.mcap"
    original = small_trial.read_bytes()
    path.write_bytes(original)
    with TrialReader(path) as tr:
        conversion_end = tr.summary.data_end_offset
    stream = _derived(3000, seed=1)
    probe = tmp_path / "probe.mcap"
    probe.write_bytes(original)
    total = _steps_of_one_append(probe, stream)
    assert total > 20
    outcomes = []
    for k in range(1, total + 2):
        path.write_bytes(original)
        pid = _fork_append(path, stream, kill_at=k)
        _, status = os.waitpid(pid, 0)
        code = os.waitstatus_to_exitcode(status)
        assert code in (-signal.SIGKILL, 0), code
        outcomes.append(_check_after_kill(path, original, conversion_end, stream))
    # killed before the journal is removed -> unchanged; after -> the complete new file; never anything between
    first_appended = outcomes.index("appended")
    assert set(outcomes[:first_appended]) == {"unchanged"} and set(outcomes[first_appended:]) == {"appended"}
    assert first_appended >= total - 4
    # the lock died with the killed writers and their temp files are cleaned by the next writer
    path.write_bytes(original)
    append_derived(path, [stream], run={"step": "after"})
    assert check_file(path).ok
    assert not list(tmp_path.glob(".trial.mcap.*"))


def _random_kills(small_trial: Path, tmp_path: Path, runs: int) -> dict[str, int]:
    path = tmp_path / "trial.mcap"
    original = small_trial.read_bytes()
    with TrialReader(small_trial) as tr:
        conversion_end = tr.summary.data_end_offset
    stream = _derived(60_000, seed=2)
    # time one full append in a child to spread the kills over its duration
    path.write_bytes(original)
    r, w = os.pipe()
    t0 = time.perf_counter()
    pid = _fork_append(path, stream, wait_fd=r)
    os.write(w, b"g")
    os.waitpid(pid, 0)
    duration = time.perf_counter() - t0
    rng = random.Random(3)
    outcomes = {"unchanged": 0, "appended": 0}
    for _ in range(runs):
        path.write_bytes(original)
        pid = _fork_append(path, stream, wait_fd=r)
        os.write(w, b"g")
        time.sleep(rng.uniform(0, duration * 1.1))
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        outcomes[_check_after_kill(path, original, conversion_end, stream)] += 1
    os.close(r)
    os.close(w)
    return outcomes


def test_append_killed_at_random_times_leaves_original_valid(small_trial, tmp_path):
    outcomes = _random_kills(small_trial, tmp_path, runs=25)
    assert outcomes["unchanged"] > 0


@pytest.mark.slow
def test_append_killed_at_random_times_many_runs(small_trial, tmp_path):
    outcomes = _random_kills(small_trial, tmp_path, runs=200)
    assert outcomes["unchanged"] > 0 and outcomes["appended"] > 0


def test_damaged_summary_without_crc_gives_archive_errors_not_tracebacks(small_trial, tmp_path):
    """With the summary CRC zeroed (allowed by MCAP), random summary damage must still end in a reason."""
    import struct

    from imulog.archive import ArchiveError

    data = small_trial.read_bytes()
    summary_start = struct.unpack_from("<Q", data, len(data) - 8 - m.FOOTER_SIZE + 9)[0]
    rng = random.Random(4)
    bad = tmp_path / "fuzz.mcap"
    noticed = 0
    for _ in range(120):
        b = bytearray(data)
        b[-8 - 4 : -8] = b"\0\0\0\0"  # "no summary CRC"
        for _ in range(rng.choice([1, 3])):
            b[rng.randrange(summary_start, len(b) - 8 - m.FOOTER_SIZE)] = rng.randrange(256)
        bad.write_bytes(b)
        try:
            with TrialReader(bad) as tr:
                for topic in tr.topics():
                    with contextlib.suppress(ArchiveError):
                        tr.read(topic)
                tr.metadata  # noqa: B018
                tr.attachments()
        except ArchiveError:
            pass
        noticed += not check_file(bad).ok
    assert noticed >= 100  # the rest changed only private/unknown-opcode bytes or values equal to the old ones


DAMAGED_ARCHIVE_COMMANDS = [
    ["info"],
    ["doctor"],
    ["export", "--topic", "/imu/wrist", "-o", "{out}/x.parquet"],
    ["process", "orientation"],
    ["process", "align"],
    ["process", "trajectory"],
    ["process", "metrics"],
    ["process", "phases"],
    ["process", "kinematics"],
    ["process", "calibrate", "--calibration", "{out}/cal.json"],
    ["evaluate"],
    ["calibrate", "-o", "{out}/cal2.json"],
    ["view", "--save", "{out}/x.rrd"],
]


@pytest.mark.parametrize("command", DAMAGED_ARCHIVE_COMMANDS, ids=[" ".join(c[:2]) for c in DAMAGED_ARCHIVE_COMMANDS])
def test_commands_report_a_truncated_archive_in_one_line(small_trial, tmp_path, command):
    """Every command given a cut-off archive: exit 1 and one 'Error: FILE: ...' line, never a traceback
    (the reprocessing commands used to let ArchiveCorruptError escape)."""
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(small_trial.read_bytes()[: small_trial.stat().st_size // 2])
    (tmp_path / "cal.json").write_text(
        '{"format": "imulog.calibration/1", "acc": {"bias": [0, 0, 0], "matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}}'
    )
    args = [a.replace("{out}", str(tmp_path)) for a in command]
    where = 2 if args[0] == "process" else 1
    result = CliRunner().invoke(cli, [*args[:where], str(cut), *args[where:]])
    assert result.exit_code == 1, result.output + repr(result.exception)
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit)
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert errors == [
        f"Error: {cut}: truncated or unfinished MCAP file (no closing magic / footer); `imulog salvage` recovers "
        "its intact channels"
    ] or (args[0] == "calibrate" and errors and str(cut) in errors[0] and "truncated" in errors[0]), result.output
    assert f"{cut}: {cut}" not in result.output


# ---------------------------------------------------------------------------------------------- streaming reads


@pytest.fixture(scope="module")
def chunked_trial(tmp_path_factory) -> Path:
    """Every stream type written in small chunks (many per channel)."""
    from imulog.archive import _builder

    mp = pytest.MonkeyPatch()
    mp.setattr(_builder, "CHUNK_TARGET_BYTES", 16_000)
    try:
        path = write_trial(tmp_path_factory.mktemp("chunked") / "t.mcap", synthetic_recording(np.random.default_rng(8)))
    finally:
        mp.undo()
    return path


def test_iter_blocks_pieces_concatenate_to_read(chunked_trial):
    from imulog.archive.tables import stream_columns

    rng = np.random.default_rng(4)
    with TrialReader(chunked_trial) as tr:
        for info in (tr.channel(t) for t in tr.topics()):  # imulog's channels (not the viewer twins)
            whole = stream_columns(tr.read(info.topic))
            n_chunks = sum(info.channel_id in ci.message_index_offsets for ci in tr.summary.chunk_indexes)
            pieces = [stream_columns(p) for p in tr.iter_blocks(info.topic)]
            if n_chunks > 1 and len(whole[next(iter(whole))]):
                assert len(pieces) > 1, info.topic  # really one piece per chunk, not one piece
            for key, col in whole.items():
                joined = (
                    [v for p in pieces for v in p[key]]
                    if isinstance(col, list)
                    else (np.concatenate([p[key] for p in pieces]) if pieces else col[:0])
                )
                assert np.array_equal(
                    np.asarray(joined),
                    np.asarray(col),
                    equal_nan=col.dtype.kind == "f" if isinstance(col, np.ndarray) else False,
                ), f"{info.topic} {key}"
            t = whole.get("t_ns", whole.get("start_ns"))
            if len(t) > 2:
                lo, hi = sorted(int(x) for x in rng.choice(np.asarray(t), 2, replace=False))
                part = stream_columns(tr.read(info.topic, lo, hi))
                got = [stream_columns(p) for p in tr.iter_blocks(info.topic, lo, hi)]
                key = "t_ns" if "t_ns" in part else "start_ns"
                joined = np.concatenate([p[key] for p in got]) if got else np.asarray(part[key])[:0]
                assert np.array_equal(joined, part[key]), f"{info.topic} [{lo}, {hi})"


def test_iter_blocks_yields_intact_chunks_then_refuses_the_damaged_one(chunked_trial, tmp_path):
    with TrialReader(chunked_trial) as tr:
        cid = next(c.id for c in tr.summary.channels.values() if c.topic == "/imu/wrist")
        chunks = sorted(
            (ci for ci in tr.summary.chunk_indexes if cid in ci.message_index_offsets),
            key=lambda ci: ci.chunk_start_offset,
        )
        good = [p.t_ns for p in tr.iter_blocks("/imu/wrist")][:2]
    assert len(chunks) >= 4
    data = bytearray(chunked_trial.read_bytes())
    data[chunks[2].chunk_start_offset + chunks[2].chunk_length - 5] ^= 0x08  # compressed data of the 3rd chunk
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    seen = []
    with (
        TrialReader(bad) as tr,
        pytest.raises(ArchiveCorruptError, match=rf"/imu/wrist: chunk at byte {chunks[2].chunk_start_offset} "),
    ):
        for piece in tr.iter_blocks("/imu/wrist"):
            seen.append(piece.t_ns)
    assert len(seen) == 2 and all(np.array_equal(a, b) for a, b in zip(seen, good, strict=True))
