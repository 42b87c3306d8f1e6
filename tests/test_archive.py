"""imulog.archive: round trips, selection, metadata, attachments, append/replace, steps, locking, CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_archive_helpers import (
    assert_bit_identical,
    assert_stream_equal,
    load_broad,
    load_nexus_markers,
    synthetic_recording,
)

from imulog.archive import (
    ArchiveCorruptError,
    ArchiveError,
    ArchiveExistsError,
    ArchiveLockedError,
    TrialReader,
    append_derived,
    write_trial,
)
from imulog.archive.doctor import check_file
from imulog.cli import cli
from imulog.model import Intervals, PoseStream, Recording, SignalStream
from imulog.steps.base import StepResult, run_step


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture
def trial(tmp_path: Path, rng: np.random.Generator) -> tuple[Path, Recording]:
    src = tmp_path / "wrist_imu.csv"
    src.write_bytes(b"timestamp,ax\n0,1\n")
    rec = synthetic_recording(rng, sources=[src])
    path = write_trial(tmp_path / "trial.mcap", rec)
    return path, rec


def _orientation(rec: Recording, rng: np.random.Generator, scale: float = 1.0) -> SignalStream:
    t = rec.imus[0].t_ns
    return SignalStream(
        "/derived/orientation/wrist", t, ["qw", "qx", "qy", "qz"], ["1"] * 4, scale * rng.normal(size=(len(t), 4))
    )


# ----------------------------------------------------------------------------------------------- round trip


def test_round_trip_every_schema_is_bit_identical(trial):
    path, rec = trial
    with TrialReader(path) as tr:
        assert tr.topics() == [s.topic for s in rec.streams()]
        schemas = {c.topic: c.schema_name for c in tr.channels if not c.metadata.get("twin_of")}
        assert set(schemas.values()) == {
            "imulog.ImuBlock",
            "imulog.MarkerBlock",
            "imulog.AnalogBlock",
            "imulog.SignalBlock",
            "imulog.IntervalEvent",
            "imulog.PoseBlock",
        }
        for stream in rec.streams():
            assert_stream_equal(stream, tr.read(stream.topic))


def test_real_broad_imu_and_optical_poses_round_trip(tmp_path, shared_data):
    rec = load_broad(shared_data / "broad" / "05_undisturbed_slow_rotation_with_breaks_B.hdf5")
    assert np.isnan(rec.poses[0].position).any(), "the real trial has tracking gaps"
    path = write_trial(tmp_path / "broad.mcap", rec)
    with TrialReader(path) as tr:
        for stream in rec.streams():
            assert_stream_equal(stream, tr.read(stream.topic))
        info = {c.topic: c for c in tr.channels}
        assert info["/imu/hand"].sample_count == len(rec.imus[0])
        assert info["/imu/hand"].rate_hz == pytest.approx(285.714, rel=1e-4)
        assert info["/imu/hand"].message_count == int(np.ceil(len(rec.imus[0]) / 285.714))  # ~1 s blocks
        both = np.hstack([rec.poses[0].position, rec.poses[0].orientation])
        nan_rows = int(np.count_nonzero(~np.all(np.isfinite(both), axis=1)))
        assert int(info["/poses/optitrack"].metadata["nan_samples"]) == nan_rows
        (att,) = tr.attachments()
        assert att.data == (shared_data / "broad" / "05_undisturbed_slow_rotation_with_breaks_B.hdf5").read_bytes()


def test_real_vicon_markers_with_gaps_round_trip(tmp_path, shared_data):
    markers = load_nexus_markers(shared_data / "vicon_nexus" / "markers.csv")
    assert len(markers.labels) == 51 and len(markers) == 580
    assert not markers.valid.all(), "the real export has gaps"
    path = write_trial(tmp_path / "vicon.mcap", Recording(markers=[markers]))
    with TrialReader(path) as tr:
        back = tr.read("/markers/vicon")
    assert_stream_equal(markers, back)
    assert back.valid.sum() == markers.valid.sum()


def test_time_range_selection_matches_numpy_masks(tmp_path, rng):
    rec = synthetic_recording(rng, n_imu=40_000)  # several chunks per channel
    path = write_trial(tmp_path / "t.mcap", rec)
    imu = rec.imus[0]
    with TrialReader(path) as tr:
        assert len([ci for ci in tr.summary.chunk_indexes if 0 in ci.message_index_offsets]) >= 2
        for a, b in [(0.1, 0.2), (0.5, 0.9), (0.0, 1.0), (0.33, 0.331)]:
            lo = int(imu.t_ns[0] + a * (imu.t_ns[-1] - imu.t_ns[0]))
            hi = int(imu.t_ns[0] + b * (imu.t_ns[-1] - imu.t_ns[0]))
            part = tr.read("/imu/wrist", lo, hi)
            keep = (imu.t_ns >= lo) & (imu.t_ns < hi)
            assert_bit_identical(part.t_ns, imu.t_ns[keep], "t")
            assert_bit_identical(part.acc, imu.acc[keep], "acc")
        # negative device times (clamped MCAP log times) still select exactly
        mk = rec.markers[0]
        part = tr.read("/markers/vicon", -3_000_000_000, 1_000_000_000)
        keep = (mk.t_ns >= -3_000_000_000) & (mk.t_ns < 1_000_000_000)
        assert_bit_identical(part.pos, mk.pos[keep], "pos")
        ev = tr.read("/events/c3d", 0, 15_000_000)
        assert ev.labels == ["x", "reach"]


def test_metadata_attachments_and_channel_metadata(trial):
    path, rec = trial
    with TrialReader(path) as tr:
        md = tr.metadata
        assert md["imulog.trial"] == rec.metadata["imulog.trial"]  # ints stay ints, strings stay strings
        assert md["imulog.anthropometrics"] == rec.metadata["imulog.anthropometrics"]
        assert md["imulog.device.wrist"]["model"] == "LSM9DS1"
        raw = md["imulog.raw"]
        assert set(raw["channels"]) == set(tr.topics())
        assert raw["channels"]["/imu/wrist"] == tr.channel_hash("/imu/wrist") == tr.compute_channel_hash("/imu/wrist")
        (att,) = tr.attachments()
        assert att.name == "wrist_imu.csv" and att.data == b"timestamp,ax\n0,1\n"
        assert raw["attachments"] == {"wrist_imu.csv": att.sha256}
        imu = tr.channel("/imu/wrist")
        assert json.loads(imu.metadata["units"]) == ["m/s^2", "rad/s", "uT", "degC"]
        assert imu.metadata["frame_id"] == "wrist"
        assert imu.start_ns == int(rec.imus[0].t_ns[0]) and imu.end_ns == int(rec.imus[0].t_ns[-1])
        assert int(imu.metadata["nan_samples"]) == 41  # 40 NaN rows + one odd NaN payload
        assert tr.channel("/markers/vicon").metadata["source"] == "markers.csv"


def test_read_pandas_and_arrow(trial):
    path, rec = trial
    with TrialReader(path) as tr:
        df = tr.read_pandas("/imu/wrist")
        table = tr.read_arrow("/markers/vicon")
        ev = tr.read_pandas("/events/c3d")
    imu = rec.imus[0]
    assert list(df.columns[:4]) == ["t_ns", "acc_x", "acc_y", "acc_z"]
    assert_bit_identical(df["gyr_z"].to_numpy(), imu.gyr[:, 2], "gyr_z")
    assert table.column_names[:5] == ["t_ns", "O_x", "O_y", "O_z", "O_valid"]
    assert table.schema.metadata[b"units"] == b"m"
    assert_bit_identical(table.column("Y_z").to_numpy(), rec.markers[0].pos[:, 2, 2], "Y_z")
    assert ev["label"].tolist() == ["Foot Strike", "x", "reach"]


def test_write_refuses_existing_file_and_leaves_nothing_on_error(tmp_path, trial, monkeypatch):
    path, rec = trial
    before = path.read_bytes()
    with pytest.raises(ArchiveExistsError):
        write_trial(path, rec)
    with pytest.raises(ArchiveError, match="share the topic"):
        write_trial(path, Recording(signals=[rec.signals[0], rec.signals[0]]), overwrite=True)
    with pytest.raises(ArchiveError, match="source file to attach not found"):
        write_trial(tmp_path / "new.mcap", Recording(signals=[rec.signals[0]], sources=[str(tmp_path / "missing")]))

    from imulog.archive import writer

    real_encode = writer.codec.encode

    def failing_encode(stream, *args):
        if stream.topic == "/poses/cluster":
            raise RuntimeError("disk on fire")
        return real_encode(stream, *args)

    monkeypatch.setattr(writer.codec, "encode", failing_encode)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_trial(path, rec, overwrite=True)  # fails after most channels were written to the temp file
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_trial(tmp_path / "new.mcap", rec)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trial.mcap", "wrist_imu.csv"]  # no temp, no lock


# ----------------------------------------------------------------------------------------------- append


def test_append_keeps_raw_bytes_and_is_valid_mcap(trial, rng):
    path, rec = trial
    before = path.read_bytes()
    with TrialReader(path) as tr:
        # raw channels come first; the viewer twins after them are rewritten when the alignment changes
        raw_ids = {c.channel_id for c in tr.channels if not c.metadata.get("twin_of")}
        old_end = max(
            ci.message_index_offsets[cid] + ci.message_index_length
            for ci in tr.summary.chunk_indexes
            for cid in ci.message_index_offsets
            if cid in raw_ids
        )
        raw_hash = tr.metadata["imulog.raw"]["sha256"]
    phases = Intervals("/derived/phases/wrist", [1, 5], [4, 9], ["reach", "lift"], [1, 1])
    append_derived(
        path,
        [_orientation(rec, rng), phases],
        run={"step": "orientation", "algorithm": "vqf", "params": {"tau_acc": 3.0}, "inputs": ["/imu/wrist"]},
        metadata={"imulog.alignment": {"offset_ns": -12, "drift_ppm": 1.5}},
    )
    after = path.read_bytes()
    assert after[:old_end] == before[:old_end]  # every raw byte is unchanged
    report = check_file(path)
    assert report.ok, report.problems
    with TrialReader(path) as tr:
        assert tr.metadata["imulog.raw"]["sha256"] == raw_hash
        assert tr.metadata["imulog.alignment"] == {"offset_ns": -12, "drift_ppm": 1.5}
        ch = tr.channel("/derived/phases/wrist")
        assert ch.metadata["algorithm"] == "vqf" and ch.params == {"tau_acc": 3.0}
        assert ch.inputs == {"/imu/wrist": tr.channel_hash("/imu/wrist")}
        assert ch.metadata["imulog_version"]
        assert tr.runs()[1]["outputs"].keys() == {"/derived/orientation/wrist", "/derived/phases/wrist"}
        assert_stream_equal(tr.read("/derived/phases/wrist"), phases)
        for stream in rec.streams():
            assert_stream_equal(stream, tr.read(stream.topic))
    # the reference mcap library reads it and validates every CRC
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        n = sum(1 for _ in reader.iter_messages())
        assert n == reader.get_summary().statistics.message_count


def test_replace_copies_untouched_chunks_verbatim(trial, rng):
    path, rec = trial
    with TrialReader(path) as tr:
        conversion_end = tr.summary.data_end_offset
    run = {"step": "orientation", "algorithm": "vqf", "params": {"tau": 1}, "inputs": ["/imu/wrist"]}
    append_derived(path, [_orientation(rec, rng)], run=run)
    other = SignalStream(
        "/derived/static/wrist", rec.imus[0].t_ns, ["static"], ["1"], rng.integers(0, 2, len(rec.imus[0]))
    )
    append_derived(path, [other], run={"step": "static", "algorithm": "thr", "params": {}, "inputs": []})

    def chunk_bytes(topic: str) -> list[bytes]:
        with TrialReader(path) as tr:
            cid = next(c.channel_id for c in tr.channels if c.topic == topic)
            data = path.read_bytes()
            return [
                data[ci.chunk_start_offset : ci.chunk_start_offset + ci.chunk_length]
                for ci in tr.summary.chunk_indexes
                if cid in ci.message_index_offsets
            ]

    static_chunks = chunk_bytes("/derived/static/wrist")
    new = _orientation(rec, rng, scale=2.0)
    before = path.read_bytes()
    append_derived(path, [new], run={**run, "params": {"tau": 2}})
    after = path.read_bytes()
    assert after[:conversion_end] == before[:conversion_end]  # raw part untouched by the rewrite
    assert chunk_bytes("/derived/static/wrist") == static_chunks  # copied, not recompressed
    assert check_file(path).ok
    with TrialReader(path) as tr:
        assert tr.topics().count("/derived/orientation/wrist") == 1
        assert_stream_equal(tr.read("/derived/orientation/wrist"), new)
        assert tr.channel("/derived/orientation/wrist").params == {"tau": 2}
        assert tr.runs()[3]["replaced"] == ["/derived/orientation/wrist"]
        for stream in rec.streams():
            assert_stream_equal(stream, tr.read(stream.topic))
    with pytest.raises(ArchiveError, match="exists"):
        append_derived(path, [new], run=run, replace=False)
    with pytest.raises(ArchiveError, match="/derived/"):
        append_derived(path, [SignalStream("/imu/wrist", [0], ["a"], ["1"], [1.0])], run=run)


def test_run_step_skips_identical_runs_and_tracks_input_hashes(trial):
    path, rec = trial
    calls = []

    def orientation(tau: float):
        def compute(tr: TrialReader) -> StepResult:
            calls.append(("orientation", tau))
            imu = tr.read("/imu/wrist")
            q = np.tile([1.0, 0, 0, 0], (len(imu), 1)) * tau
            return StepResult(
                streams=[SignalStream("/derived/orientation/wrist", imu.t_ns, ["qw", "qx", "qy", "qz"], ["1"] * 4, q)]
            )

        return compute

    def static(tr: TrialReader) -> StepResult:
        calls.append(("static", None))
        q = tr.read("/derived/orientation/wrist")
        return StepResult(
            streams=[SignalStream("/derived/static/wrist", q.t_ns, ["static"], ["1"], q.values[:, 0] > 0)],
            metadata={"imulog.static": {"n": int(len(q))}},
        )

    kw = {"step": "orientation", "algorithm": "demo", "inputs": ["/imu/wrist"]}
    first = run_step(path, params={"tau": 1.0}, compute=orientation(1.0), **kw)
    assert not first.skipped and first.topics == ["/derived/orientation/wrist"]
    again = run_step(path, params={"tau": 1.0}, compute=orientation(1.0), **kw)
    assert again.skipped and again.run == first.run
    size = path.stat().st_size
    s1 = run_step(
        path, step="static", algorithm="thr", params=None, inputs=["/derived/orientation/wrist"], compute=static
    )
    assert not s1.skipped
    s2 = run_step(
        path, step="static", algorithm="thr", params=None, inputs=["/derived/orientation/wrist"], compute=static
    )
    assert s2.skipped
    assert path.stat().st_size > size
    # new orientation params -> orientation replaced -> static's input hash changed -> static recomputes
    run_step(path, params={"tau": 2.0}, compute=orientation(2.0), **kw)
    s3 = run_step(
        path, step="static", algorithm="thr", params=None, inputs=["/derived/orientation/wrist"], compute=static
    )
    assert not s3.skipped
    forced = run_step(path, params={"tau": 2.0}, compute=orientation(2.0), force=True, **kw)
    assert not forced.skipped
    assert calls == [
        ("orientation", 1.0),
        ("static", None),
        ("orientation", 2.0),
        ("static", None),
        ("orientation", 2.0),
    ]
    assert check_file(path).ok


# ----------------------------------------------------------------------------------------------- safety


_HOLD_LOCK = """
import sys, time
from imulog.archive.files import writer_lock
with writer_lock(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(60)
"""


def test_second_concurrent_writer_is_refused(trial, rng):
    path, rec = trial
    before = path.read_bytes()
    proc = subprocess.Popen([sys.executable, "-c", _HOLD_LOCK, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "locked"
        with pytest.raises(ArchiveLockedError, match=rf"another process \(pid {proc.pid}\) is writing"):
            append_derived(path, [_orientation(rec, rng)], run={"step": "x"})
        with pytest.raises(ArchiveLockedError):
            write_trial(path, rec, overwrite=True)
        assert path.read_bytes() == before
    finally:
        proc.kill()  # SIGKILL: the kernel drops the lock with the process
        proc.wait()
    append_derived(path, [_orientation(rec, rng)], run={"step": "x"})
    assert check_file(path).ok


def test_bad_inputs_give_one_line_errors(tmp_path, trial):
    path, _ = trial
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("hello, this is not an MCAP file at all" * 3)
    truncated = tmp_path / "cut.mcap"
    truncated.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    runner = CliRunner()
    for bad, reason in [(not_mcap, "not an MCAP file"), (truncated, "truncated"), (empty, "too short")]:
        with pytest.raises(ArchiveCorruptError, match=reason):
            TrialReader(bad)
        for cmd in (["info"], ["doctor"], ["export", "--topic", "/imu/wrist", "-o", str(tmp_path / "x.csv")]):
            res = runner.invoke(cli, [cmd[0], str(bad), *cmd[1:]])
            assert res.exit_code == 1, (cmd, res.output)
            lines = res.output.strip().splitlines()
            assert len(lines) == 1 and reason in lines[0] and str(bad) in lines[0], res.output
        with pytest.raises(ArchiveCorruptError):
            append_derived(bad, [SignalStream("/derived/a", [0], ["a"], ["1"], [1.0])], run={})
    with TrialReader(path) as tr, pytest.raises(ArchiveError, match="no channel '/imu/ankle'"):
        tr.read("/imu/ankle")


# ----------------------------------------------------------------------------------------------- CLI


def test_cli_info_doctor_export(trial, tmp_path, rng):
    path, rec = trial
    append_derived(path, [_orientation(rec, rng)], run={"step": "orientation", "algorithm": "vqf", "params": {"a": 1}})
    runner = CliRunner()
    res = runner.invoke(cli, ["info", str(path)])
    assert res.exit_code == 0, res.output
    for text in (
        "/imu/wrist",
        "imulog.ImuBlock",
        "imulog.PoseBlock",
        "imulog.trial",
        "derived runs",
        "#1 orientation",
    ):
        assert text in res.output
    res = runner.invoke(cli, ["info", str(path), "--json"])
    data = json.loads(res.output)
    imu = next(c for c in data["channels"] if c["topic"] == "/imu/wrist")
    assert imu["samples"] == len(rec.imus[0]) and imu["nan_samples"] == 41 and imu["time_gaps"] == 0
    assert imu["rate_hz"] == pytest.approx(1e9 / np.median(np.diff(rec.imus[0].t_ns)), rel=1e-5)
    assert data["runs"]["1"]["algorithm"] == "vqf"
    assert data["metadata"]["imulog.trial"]["subject"] == "S01"
    res = runner.invoke(cli, ["doctor", str(path)])
    assert res.exit_code == 0 and "ok" in res.output
    import pandas as pd

    out = tmp_path / "imu.parquet"
    res = runner.invoke(cli, ["export", str(path), "--topic", "/imu/wrist", "-o", str(out)])
    assert res.exit_code == 0, res.output
    df = pd.read_parquet(out)
    assert_bit_identical(df["mag_y[uT]"].to_numpy(), rec.imus[0].mag[:, 1], "mag_y")  # units in the names
    out_csv = tmp_path / "phases.csv"
    res = runner.invoke(cli, ["export", str(path), "--topic", "/events/c3d", "-o", str(out_csv)])
    assert res.exit_code == 0
    assert pd.read_csv(out_csv)["label"].tolist() == ["Foot Strike", "x", "reach"]
    res = runner.invoke(cli, ["export", str(path), "--topic", "/nope", "-o", str(tmp_path / "nope.csv")])
    assert res.exit_code == 1 and "no channel '/nope'" in res.output
    res = runner.invoke(cli, ["export", str(path), "--topic", "/imu/wrist", "-o", str(tmp_path / "x.xlsx")])
    assert res.exit_code == 2 and "--to" in res.output  # a usage error: unknown format


def test_info_lists_time_gaps(tmp_path):
    t = np.concatenate([np.arange(100), np.arange(200, 300)]).astype(np.int64) * 10_000_000
    sig = SignalStream("/derived/gappy", t, ["v"], ["1"], np.ones(200))
    pose = PoseStream("/poses/p", t[:5], np.zeros((5, 3)))
    path = write_trial(tmp_path / "g.mcap", Recording(signals=[sig], poses=[pose]))
    with TrialReader(path) as tr:
        assert tr.channel("/derived/gappy").metadata["time_gaps"] == "1"
        assert tr.channel("/derived/gappy").rate_hz == pytest.approx(100.0)


def test_mcap_log_times_start_at_the_trial_start_and_payload_keeps_negative_times(trial):
    path, rec = trial
    with TrialReader(path) as tr:
        ch = tr.channel("/markers/vicon")
        assert ch.start_ns == -5_000_000_000
        starts = [ci.message_start_time for ci in tr.summary.chunk_indexes if ch.channel_id in ci.message_index_offsets]
        # no start time in this trial: the documented fixed epoch, 2000-01-01T00:00:00Z
        assert min(starts) == 946_684_800 * 10**9
        assert tr.metadata["imulog.timeline"]["source"].startswith("fixed epoch")
    with TrialReader(path) as tr:
        assert_stream_equal(rec.markers[0], tr.read("/markers/vicon"))


def test_files_from_other_mcap_writers_are_read_checked_and_appended(tmp_path):
    """A file written by the `mcap` package (schemas/channels inside interleaved chunks, no data CRC)."""
    import json as _json

    from mcap.writer import Writer

    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("Thing", "jsonschema", b"{}")
        a, b = w.register_channel("/a", "json", sid), w.register_channel("/b", "json", sid)
        for i in range(50):
            w.add_message(a, i, _json.dumps({"x": i}).encode(), i)
            w.add_message(b, i, b"{}", i)
        w.add_metadata("site", {"lab": "x"})
        w.finish()
    assert check_file(path).ok
    with TrialReader(path) as tr:
        assert tr.topics() == ["/a", "/b"] and tr.channel("/a").message_count == 50
        assert tr.metadata == {"site": {"lab": "x"}}
        with pytest.raises(ArchiveError, match="not an imulog stream type"):
            tr.read("/a")
    sig = SignalStream("/derived/z", [1, 2], ["v"], ["1"], [1.0, 2.0])
    append_derived(path, [sig], run={"step": "z"})
    report = check_file(path)
    assert report.ok, report.problems
    with TrialReader(path) as tr:
        assert_stream_equal(tr.read("/derived/z"), sig)
        assert [bytes(p) for p in tr.messages("/a")][:2] == [b'{"x": 0}', b'{"x": 1}']


def test_clock_jumping_back_round_trips_in_write_order(tmp_path):
    """A device clock reset (times jump back) keeps sample order; time selection still picks by time."""
    t = np.concatenate([np.arange(3000) * 10_000_000 + 50_000_000_000, np.arange(2000) * 10_000_000]).astype(np.int64)
    sig = SignalStream("/derived/reset", t, ["v"], ["1"], np.arange(len(t), dtype=float))
    path = write_trial(tmp_path / "r.mcap", Recording(signals=[sig]))
    with TrialReader(path) as tr:
        assert_stream_equal(tr.read("/derived/reset"), sig)
        part = tr.read("/derived/reset", 0, 1_000_000_000)
    keep = (t >= 0) & (t < 1_000_000_000)
    assert_bit_identical(part.values[:, 0], sig.values[keep, 0], "values")


def test_append_refuses_provenance_that_no_longer_matches_the_inputs(trial, rng):
    path, rec = trial
    with pytest.raises(ArchiveError, match="input /imu/wrist changed while the step ran"):
        append_derived(path, [_orientation(rec, rng)], run={"step": "o", "inputs": {"/imu/wrist": "0" * 64}})


def test_append_keeps_file_mode_and_follows_symlinks(trial, rng, tmp_path):
    path, rec = trial
    path.chmod(0o640)
    link = tmp_path / "link.mcap"
    link.symlink_to(path)
    append_derived(link, [_orientation(rec, rng)], run={"step": "o"})
    assert link.is_symlink() and (path.stat().st_mode & 0o777) == 0o640
    with TrialReader(link) as tr:
        assert "/derived/orientation/wrist" in tr.topics()


def test_remove_derived_channel(trial, rng):
    from imulog.archive import check_file as check
    from imulog.archive import remove_derived

    path, rec = trial
    append_derived(path, [_orientation(rec, rng)], run={"step": "o"})
    with TrialReader(path) as tr:
        conversion_end = min(ci.chunk_start_offset for ci in tr.summary.chunk_indexes) + 1
    before = path.read_bytes()
    remove_derived(path, ["/derived/orientation/wrist"])
    assert path.read_bytes()[:conversion_end] == before[:conversion_end]
    assert check(path).ok
    with TrialReader(path) as tr:
        assert "/derived/orientation/wrist" not in tr.topics()
        assert tr.runs()[2]["removed"] == ["/derived/orientation/wrist"]
        for stream in rec.streams():
            assert_stream_equal(stream, tr.read(stream.topic))
    with pytest.raises(ArchiveError, match="only derived channels can be removed"):
        remove_derived(path, ["/imu/wrist"])
    with pytest.raises(ArchiveError, match="no channel"):
        remove_derived(path, ["/derived/nothing"])


def test_export_to_unwritable_place_is_a_one_line_error(trial, tmp_path):
    path, _ = trial
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = CliRunner().invoke(cli, ["export", str(path), "--topic", "/imu/wrist", "-o", str(blocker / "sub" / "x.csv")])
    assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1 and "cannot write" in res.output


def test_export_empty_time_range_is_refused(trial, tmp_path):
    """--end-ns before --start-ns used to write a header-only file and report success."""
    path, _ = trial
    out = tmp_path / "x.csv"
    args = ["export", str(path), "--topic", "/imu/wrist", "-o", str(out), "--start-ns", "10", "--end-ns", "5"]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 2 and "--end-ns" in res.output and not out.exists()
