"""Issue 24: an append that changes the alignment rebuilds the orientation, marker and event twins block by block,
equal to the twins of the whole channels, without decoding a whole channel."""

from __future__ import annotations

import dataclasses

import numpy as np
from click.testing import CliRunner
from read_spy import record_reads

from imulog.archive import TrialReader, append_derived, write_trial
from imulog.archive import twin_blocks as tb
from imulog.archive.timeline import TrialAxis
from imulog.archive.twins import AXES_RATE_HZ, OVERVIEW_AFTER_S, TWIN_RATE_HZ, decimation
from imulog.archive.writer import _imu_origin, stream_twins
from imulog.cli import cli
from imulog.model import Intervals, SignalStream
from imulog.simulate import simulate


def _pieces(stream: SignalStream, cuts: list[int]):
    edges = [0, *cuts, len(stream.t_ns)]
    return lambda: iter(
        dataclasses.replace(stream, t_ns=stream.t_ns[a:b], values=stream.values[a:b])
        for a, b in zip(edges[:-1], edges[1:], strict=True)
    )


def _orientation(n: int, rate_hz: float, seed: int = 1) -> SignalStream:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    t = np.round(np.arange(n) * 1e9 / rate_hz + rng.normal(0, 2e5, n)).astype(np.int64)  # jittered clock
    return SignalStream("/derived/orientation/wrist", t, ["qw", "qx", "qy", "qz"], ["1"] * 4, q, "wrist")


def test_kept_samples_are_the_whole_channels_decimation(monkeypatch):
    """Uneven blocks keep exactly the samples ``decimation`` keeps of the whole channel, for both twin rates."""
    for n, rate, cuts in ((5_000, 100.0, [1, 7, 1_234, 4_999]), (2_000, 60.0, [])):
        whole = _orientation(n, rate)
        got = tb.kept_samples(_pieces(whole, cuts), 0)
        assert got is not None
        stream, keeps = got
        for r, keep in zip((TWIN_RATE_HZ, AXES_RATE_HZ), keeps, strict=True):
            want = decimation(whole.t_ns, r)
            np.testing.assert_array_equal(stream.t_ns[keep], whole.t_ns[want])
            np.testing.assert_array_equal(stream.values[keep], whole.values[want])
    # a channel longer than the overview threshold, its median interval from the first samples only
    monkeypatch.setattr(tb, "MEDIAN_SAMPLES", 700)
    rate = 1.23  # past OVERVIEW_AFTER_S with few samples (k = ceil(12.3): away from a rounding edge)
    n = int(OVERVIEW_AFTER_S * rate) + 500
    whole = _orientation(n, rate, seed=2)
    stream, keeps = tb.kept_samples(_pieces(whole, list(range(300, n, 300))), n)
    assert len(stream.t_ns) < n / 5
    np.testing.assert_array_equal(stream.t_ns[keeps[0]], whole.t_ns[decimation(whole.t_ns)])
    assert tb.kept_samples(lambda: iter([]), 0) is None


def test_alignment_append_never_reads_the_whole_orientation(tmp_path, monkeypatch):
    """Appending a new alignment rewrites the orientation twins from blocks, equal to today's whole-channel twins."""
    sim = simulate("r2g", seed=4, repetitions=4)
    path = write_trial(tmp_path / "trial.mcap", sim.recording)
    runner = CliRunner()
    for args in (["process", "orientation", str(path)], ["process", "align", str(path), "--window", "60"]):
        result = runner.invoke(cli, args)
        assert result.exit_code == 0, result.output + repr(result.exception)
    with TrialReader(path) as trial:
        record = dict(trial.metadata["imulog.alignment"])
        topics = [t for t in trial.topics() if t.startswith("/derived/orientation/")]
    assert topics
    record["offset_ns"] = int(record["offset_ns"]) + 250_000_000  # a changed clock map: the twins' log times move
    original = TrialReader.read

    def no_whole_orientation(self, topic, start_ns=None, end_ns=None):
        assert not topic.startswith("/derived/orientation/"), f"whole-channel read of {topic}"
        return original(self, topic, start_ns, end_ns)

    monkeypatch.setattr(TrialReader, "read", no_whole_orientation)
    monkeypatch.setattr(tb, "MEDIAN_SAMPLES", 1_000)  # and the median interval from the first samples only
    append_derived(path, [], run={"step": "test"}, metadata={"imulog.alignment": record})
    monkeypatch.setattr(TrialReader, "read", original)
    with TrialReader(path) as trial:
        records = trial.metadata
        assert records["imulog.alignment"]["offset_ns"] == record["offset_ns"]
        channels = {c.topic: c for c in trial.channels}
        imus = {t.split("/")[2] for t in channels if t.startswith("/imu/") and t.count("/") == 2}
        axis = TrialAxis(records, imus)
        origin = _imu_origin(trial, [], records)
        for topic in topics:
            want = stream_twins(trial.read(topic), axis, records, origin)  # today's: the whole channel
            assert len(want) == 2
            for twin in want:
                stored = trial.messages(twin.topic)
                assert [bytes(p) for p in stored] == twin.payload_list(), twin.topic
                assert channels[twin.topic].metadata["sample_count"] == twin.metadata["sample_count"]


def test_alignment_append_rebuilds_marker_and_event_twins_from_blocks(tmp_path, monkeypatch):
    """The raw reference-clock markers and events an alignment append re-twins are read block by block (small chunks:
    several blocks each), never whole, and their twins equal those of the whole channels."""
    import imulog.archive._builder as builder

    sim = simulate("r2g", seed=5, repetitions=3)
    rec = sim.recording
    t = rec.markers[0].t_ns
    starts = t[::37][1:]  # an event every 0.37 s of the marker clock, some lasting 0.1 s
    ends = starts + np.where(np.arange(len(starts)) % 3 == 0, 100_000_000, 0)
    labels = [f"event {k}" for k in range(len(starts))]
    rec.events.append(Intervals("/events/vicon", starts, ends, labels, np.arange(len(starts)) % 5 - 1))
    monkeypatch.setattr(builder, "CHUNK_TARGET_BYTES", 2048)
    path = write_trial(tmp_path / "trial.mcap", rec)
    monkeypatch.undo()
    result = CliRunner().invoke(cli, ["process", "align", str(path), "--window", "60"])
    assert result.exit_code == 0, result.output + repr(result.exception)
    with TrialReader(path) as trial:
        record = dict(trial.metadata["imulog.alignment"])
        topics = [
            c.topic for c in trial.channels if c.kind in ("markers", "intervals") and not c.metadata.get("twin_of")
        ]
        topics = [tp for tp in topics if not tp.startswith("/derived/")]
        assert "/events/vicon" in topics and any(tp.startswith("/markers/") for tp in topics)
        for topic in topics:
            assert len(list(trial.iter_blocks(topic))) > 3, topic
    record["offset_ns"] = int(record["offset_ns"]) - 180_000_000  # a changed clock map: the twins' log times move
    reads = record_reads(monkeypatch)
    append_derived(path, [], run={"step": "test"}, metadata={"imulog.alignment": record})
    assert not [r for r in reads if r[0] in topics], "a raw marker or event channel was read whole"
    monkeypatch.undo()
    with TrialReader(path) as trial:
        records = trial.metadata
        channels = {c.topic: c for c in trial.channels}
        imus = {tp.split("/")[2] for tp in channels if tp.startswith("/imu/") and tp.count("/") == 2}
        axis = TrialAxis(records, imus)
        origin = _imu_origin(trial, [], records)
        for topic in topics:
            want = stream_twins(trial.read(topic), axis, records, origin)  # the whole channel's twins
            assert len(want) == 1
            twin = want[0]
            stored = trial.messages(twin.topic)
            assert [bytes(p) for p in stored] == twin.payload_list(), twin.topic
            for key in ("sample_count", "start_ns", "end_ns", "rate_hz", "twin_of", "clock"):
                assert channels[twin.topic].metadata.get(key) == twin.metadata.get(key), (twin.topic, key)


def test_twin_hash_joins_a_bounded_block_of_rows():
    """A long twin held as wide rows (a week's 0.1 Hz orientation overview: 60,480 messages of ~0.7 KB) is
    hashed a few MB at a time, not 65,536 rows at once (three copies of the whole twin: 120 MB on the week);
    the hash is the same as over the messages one by one."""
    import tracemalloc

    from imulog.archive.hashing import payload_hash, rows_hash

    rng = np.random.default_rng(4)
    rows = rng.integers(0, 256, (40_000, 600), dtype=np.uint8)  # 24 MB
    mask = np.ones(rows.shape, dtype=bool)
    mask[:, 500:] = rng.random((40_000, 100)) < 0.5  # messages of different lengths
    want = payload_hash(bytes(r[k]) for r, k in zip(rows[:300], mask[:300], strict=True))
    assert rows_hash(rows[:300], mask[:300]) == want == rows_hash(rows[:300], mask[:300], block=7)
    tracemalloc.start()
    try:
        digest = rows_hash(rows, mask)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert digest == rows_hash(rows, mask, block=40_000)
    assert peak < 16e6, f"{peak / 1e6:.0f} MB joined at once for {rows.nbytes / 1e6:.0f} MB of rows"
