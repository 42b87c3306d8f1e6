"""``imulog convert`` piece by piece writes the archive it writes from the whole file (issue 24, point 4): BIDS-motion,
NilsPodLib CSV (and the NilsPod .bin), Xsens MT text and XDF, on every real file of those formats in
``../shared/data/devices`` and on a BIDS dataset imulog exports. Each file is converted twice through the command,
once whole (the streaming threshold out of reach) and once in tiny pieces through the streaming writer, and the two
trials are compared channel by channel and sample by sample: topics, every array of every decoded stream, every
channel's metadata (its time axis map included), every metadata record. What legitimately differs is left out and
said: the payload hashes (``sha256`` and ``imulog.raw``; messages are cut at piece borders) and the
``streamed`` flag of ``imulog.conversion``. The streaming writer's own contract (declared spans and meta) is tested
at the end."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import detect

from imulog.archive import TrialReader
from imulog.cli import cli

#: the real recordings, found as the conftest's ``shared_data`` fixture finds them (listed here at collection)
SHARED_DATA = Path(os.environ.get("IMULOG_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))

TEXT = "imulog.converters._pieces.PIECE_BYTES"
DEV = "devices"
CASES = [
    ("xdf/clock_resets.xdf", ("imulog.converters.xdf.PIECE_BYTES", 20_000)),
    ("xdf/minimal.xdf", ("imulog.converters.xdf.PIECE_BYTES", 64)),
    ("xdf/empty_streams.xdf", ("imulog.converters.xdf.PIECE_BYTES", 64)),
    ("nilspod/NilsPodX-6F13_20210109_162824_data.csv", (TEXT, 4096)),
    ("nilspod/NilsPodX-6F13_20210109_162824.bin", ("imulog.converters.nilspod.PIECE_SAMPLES", 100)),
] + [  # every MT Manager export in the shared folder
    (f"xsens_mtmanager/{p.name}", (TEXT, 16 if "012005D6_031" not in p.name else 16384))
    for p in sorted((SHARED_DATA / DEV / "xsens_mtmanager").glob("MT*.txt"))
]
SKIP_CHANNEL_KEYS = {"sha256", "stats_record"}
SKIP_RECORDS = {"imulog.raw", "imulog.channel_stats"}


def convert_twice(src: Path, tmp: Path, setting: tuple[str, int], monkeypatch) -> tuple[Path, Path]:
    """(the trial converted whole, the trial converted in tiny pieces) through ``imulog convert``."""
    import imulog.commands.convert_stream as cs

    whole, pieces = tmp / "whole.mcap", tmp / "pieces.mcap"
    monkeypatch.setattr(cs, "STREAM_MIN_BYTES", 1 << 60)
    r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(whole)])
    assert r.exit_code == 0 and "piece by piece" not in r.output, r.output
    monkeypatch.setattr(cs, "STREAM_MIN_BYTES", 0)
    monkeypatch.setattr(*setting)
    assert len(list(detect(src).iter_chunks(src))) > 1, "the tiny piece size must cut the file"
    r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(pieces)])
    assert r.exit_code == 0 and "converted piece by piece" in r.output, r.output
    return whole, pieces


def assert_same_trial(a_path: Path, b_path: Path) -> None:
    with TrialReader(a_path) as a, TrialReader(b_path) as b:
        assert a.topics() == b.topics()
        for topic in a.topics():
            sa, sb = a.read(topic), b.read(topic)
            assert type(sa) is type(sb)
            for f in dataclasses.fields(sa):
                va, vb = getattr(sa, f.name), getattr(sb, f.name)
                if isinstance(va, np.ndarray):
                    assert va.dtype == vb.dtype and va.shape == vb.shape and va.tobytes() == vb.tobytes(), (topic, f)
                else:
                    assert va == vb, (topic, f.name)
            ma = {k: v for k, v in a.channel(topic).metadata.items() if k not in SKIP_CHANNEL_KEYS}
            mb = {k: v for k, v in b.channel(topic).metadata.items() if k not in SKIP_CHANNEL_KEYS}
            assert ma == mb, (topic, {k for k in {*ma, *mb} if ma.get(k) != mb.get(k)})
        twins = sorted(c.topic for c in a.channels if c.metadata.get("twin_of"))
        assert twins == sorted(c.topic for c in b.channels if c.metadata.get("twin_of"))
        ra = {k: v for k, v in a.metadata.items() if k not in SKIP_RECORDS}
        rb = {k: v for k, v in b.metadata.items() if k not in SKIP_RECORDS}
        assert rb["imulog.conversion"].pop("streamed") is True
        assert ra == rb, {k for k in {*ra, *rb} if ra.get(k) != rb.get(k)}
        assert a.metadata["imulog.raw"]["attachments"] == b.metadata["imulog.raw"]["attachments"]


@pytest.mark.parametrize(("rel", "setting"), CASES, ids=[Path(c[0]).name for c in CASES])
def test_pieces_write_the_whole_files_archive(rel, setting, shared_data, tmp_path, monkeypatch):
    whole, pieces = convert_twice(shared_data / DEV / rel, tmp_path, setting, monkeypatch)
    assert_same_trial(whole, pieces)


def test_every_shared_file_of_the_four_formats_is_a_case(shared_data):
    """A new shared file of these formats must be added above (the acceptance list is the folder)."""
    found = {
        f"{p.parent.name}/{p.name}"
        for folder in ("xdf", "nilspod", "xsens_mtmanager")
        for p in (shared_data / DEV / folder).iterdir()
        if p.suffix in (".xdf", ".bin") or p.name.endswith("_data.csv") or p.name.startswith("MT")
    }
    assert found == {rel for rel, _ in CASES} and len(found) == 17


def test_bids_dataset_pieces_write_the_whole_files_archive(tmp_path, monkeypatch):
    """A BIDS-motion dataset imulog exports from the simulated drinking trial (IMU and markers with gaps)."""
    repo = Path(__file__).resolve().parents[1]
    sim = repo / "recordings" / "sim"
    trial = tmp_path / "raw.mcap"
    r = CliRunner().invoke(
        cli, ["convert", str(sim / "r2g_s00_t00_imu.csv"), str(sim / "r2g_s00_t00_vicon.csv"), "-o", str(trial)]
    )
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["export", str(trial), "--to", "bids", "-o", str(tmp_path / "bids")])
    assert r.exit_code == 0, r.output
    motion = sorted((tmp_path / "bids").rglob("*_motion.tsv"))
    assert len(motion) >= 2
    for src in motion:
        out = tmp_path / src.stem
        out.mkdir()
        whole, pieces = convert_twice(src, out, (TEXT, 8192), monkeypatch)
        assert_same_trial(whole, pieces)


# ------------------------------------------------------------------------ the streaming writer's contract
def _imu(t0_s: float, n: int, rate: float, meta: dict):
    from imulog.model import ImuStream

    t = np.round((t0_s + np.arange(n) / 100.0) * 1e9).astype(np.int64)
    return ImuStream(name="wrist", t_ns=t, acc=np.ones((n, 3)), meta={"rate_hz": rate, **meta})


def _markers(t0_s: float, n: int):
    from imulog.model import MarkerStream

    t = np.round((t0_s + np.arange(n) / 100.0) * 1e9).astype(np.int64)
    return MarkerStream(name="vicon", t_ns=t, labels=["m"], pos=np.zeros((n, 1, 3)))


def test_writer_takes_spans_and_meta_declared_up_front(tmp_path):
    """Markers whose samples come in a later piece but start before the first piece's IMU samples (as XDF's
    interleaved streams do), and an IMU whose meta only the end knows: declared up front, the streamed trial equals
    the whole one; undeclared, the writer refuses a wrong time axis and notes the changed meta."""
    from imulog.converters._binary import concat_chunks

    from imulog.archive import ArchiveError, write_trial
    from imulog.archive.streaming import StreamingTrialWriter, write_trial_streaming
    from imulog.model import PIECES_RECORD, Recording

    final = {"missing": 7}
    p1 = Recording(imus=[_imu(10.0, 300, 100.0, {"missing": 3})], metadata={"imulog.device.wrist": {"model": "x"}})
    p2 = Recording(imus=[_imu(13.0, 300, 100.0, final)], markers=[_markers(5.0, 1000)])
    declared = dict(p1.metadata)
    declared[PIECES_RECORD] = {
        "spans": {"/imu/wrist": [10_000_000_000, 15_990_000_000], "/markers/vicon": [5_000_000_000, 14_990_000_000]},
        "meta": {"/imu/wrist": {"rate_hz": 100.0, **final}},
    }
    whole = write_trial(tmp_path / "whole.mcap", concat_chunks([p1, p2]), attach_sources=False)
    first = dataclasses.replace(p1, metadata=declared)
    streamed = write_trial_streaming(tmp_path / "streamed.mcap", [first, p2])
    assert_same_channels(whole, streamed)
    with TrialReader(streamed) as t:
        assert PIECES_RECORD not in t.metadata
    with pytest.raises(
        ArchiveError,
        match=r"time axis taken from its first piece \(device_origin_ns 10000000000\) is not the whole recording.s \(5000000000\)",
    ):
        write_trial_streaming(tmp_path / "undeclared.mcap", [p1, p2])
    assert not (tmp_path / "undeclared.mcap").exists()
    later = Recording(imus=[_imu(13.0, 300, 100.0, final)])
    with StreamingTrialWriter(tmp_path / "meta.mcap") as w:
        w.write(p1)
        w.write(later)
    assert w.meta_changes == ["/imu/wrist: its meta changed after the channel was written (missing)"]
    wrong = dataclasses.replace(
        p1, metadata={PIECES_RECORD: {"meta": {"/imu/wrist": {"rate_hz": 100.0, "missing": 3}}}}
    )
    with pytest.raises(ArchiveError, match="unlike the meta its first piece declared"):
        write_trial_streaming(tmp_path / "wrong.mcap", [wrong, later])


def assert_same_channels(a_path: Path, b_path: Path) -> None:
    with TrialReader(a_path) as a, TrialReader(b_path) as b:
        assert sorted(a.topics()) == sorted(b.topics())
        for topic in a.topics():
            np.testing.assert_array_equal(a.read(topic).t_ns, b.read(topic).t_ns)
            ma = {k: v for k, v in a.channel(topic).metadata.items() if k not in SKIP_CHANNEL_KEYS}
            mb = {k: v for k, v in b.channel(topic).metadata.items() if k not in SKIP_CHANNEL_KEYS}
            assert ma == mb, topic
        assert a.metadata["imulog.timeline"] == b.metadata["imulog.timeline"]


#: delimited text whose rate the reader refines as it reads (the exact median step of every piece so far): a
#: Shimmer export of host receive stamps (a fitted clock, 19/20 ms steps) cut so that the first piece holds one or
#: two rows, and a time-column export cut into about 150 rows a piece
TEXT_RATE_CASES = [
    ("imu_text/shimmer_consensys_export.csv", 600),
    ("imu_text/shimmer_consensys_export.csv", 1024),
    ("imu_text/fusion_sensor_data.csv", 16384),
]


@pytest.mark.parametrize(
    ("rel", "piece_bytes"), TEXT_RATE_CASES, ids=[f"{Path(r).stem}-{b}" for r, b in TEXT_RATE_CASES]
)
def test_text_rate_refined_over_pieces_is_the_whole_files(rel, piece_bytes, shared_data, tmp_path, monkeypatch):
    """The rate over the whole file, as the whole-file path estimates it, reaches the channel: the streaming writer
    keeps the final stream meta in its closing record and readers take it (the Channel record has the first
    piece's rate, which differed: 51.2947092 Hz against 51.2947066 Hz on the Shimmer file)."""
    whole, pieces = convert_twice(shared_data / rel, tmp_path, (TEXT, piece_bytes), monkeypatch)
    assert_same_trial(whole, pieces)
