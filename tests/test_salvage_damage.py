"""Salvage of damaged converted trials: random cuts inside the data section and random byte flips.

Every output must pass ``doctor`` and hold every chunk before the damage (a cut keeps every chunk that ends
before it; a flip every chunk that does not hold the flipped byte); a cut inside the first chunk is refused as
"nothing recoverable". Trials: the simulated drinking trial (``recordings/sim``, converted) and two real
files of ../shared/data (a BROAD HDF5 recording, an Axivity AX6 ``.cwa``), converted with 64 kB chunks so a
cut or flip has many chunks around it. CI runs a few of each (``IMULOG_SALVAGE_CUTS``, default 3, and
``IMULOG_SALVAGE_FLIPS``, default 2, per trial; ``IMULOG_SALVAGE_SEED`` picks other positions); the issue's run is

    IMULOG_SALVAGE_CUTS=30 IMULOG_SALVAGE_FLIPS=10 pytest -s tests/test_salvage_damage.py

which prints one line per trial with the counts.
"""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, _builder
from imulog.archive import _mcap as m
from imulog.archive.doctor import check_file
from imulog.archive.errors import ArchiveError
from imulog.archive.salvage import salvage
from imulog.cli import cli

CUTS = int(os.environ.get("IMULOG_SALVAGE_CUTS", "3"))
FLIPS = int(os.environ.get("IMULOG_SALVAGE_FLIPS", "2"))
SEED = int(os.environ.get("IMULOG_SALVAGE_SEED", "26"))
REPO = Path(__file__).resolve().parents[1]


def _sources(shared: Path) -> dict[str, list[str]]:
    sim = REPO / "recordings" / "sim"
    return {
        "sim_r2g": [
            str(sim / "r2g_s00_t00_imu.csv"),
            str(sim / "r2g_s00_t00_vicon.csv"),
            "--meta-file",
            str(sim / "r2g_s00_t00_meta.json"),
        ],
        "broad_hdf5": [str(shared / "broad" / "02_undisturbed_slow_rotation_B.hdf5")],
        "axivity_cwa": [str(shared / "devices" / "axivity_cwa" / "ax6_sample.cwa")],
    }


@pytest.fixture(scope="module", params=["sim_r2g", "broad_hdf5", "axivity_cwa"])
def converted(request, tmp_path_factory, shared_data) -> Path:
    if request.param == "broad_hdf5":
        pytest.importorskip("h5py")
    out = tmp_path_factory.mktemp("damage") / f"{request.param}.mcap"
    mp = pytest.MonkeyPatch()
    mp.setattr(_builder, "CHUNK_TARGET_BYTES", 64_000)
    try:
        res = CliRunner().invoke(cli, ["convert", *_sources(shared_data)[request.param], "-o", str(out)])
    finally:
        mp.undo()
    assert res.exit_code == 0, res.output
    assert check_file(out).ok
    return out


def _chunks(data: bytes) -> list[tuple[int, int, list[tuple[str, bytes]]]]:
    """(start, end, [(topic, payload)]) of every chunk of the intact file."""
    s = m.read_summary_from_bytes(data)
    topics = {c.id: c.topic for c in s.channels.values()}
    out = []
    for op, pos, body in m.iter_records(data, len(m.MAGIC), s.data_end_offset):
        if op == m.Op.CHUNK:
            raw = m.decompress_chunk(m.parse_chunk(body))
            out.append((pos, pos + 9 + len(body), [(topics[c], bytes(p)) for c, _, p in m.chunk_messages(raw)]))
    return out


def _holds(path: Path, chunks: list[tuple[int, int, list[tuple[str, bytes]]]]) -> bool:
    """Whether every message of ``chunks`` is in the salvaged file, in order, per channel."""
    with TrialReader(path) as tr:
        got = {c.topic: [bytes(p) for p in tr.messages(c.topic)] for c in tr.channels}
    want: dict[str, list[bytes]] = {}
    for _, _, msgs in chunks:
        for topic, p in msgs:
            want.setdefault(topic, []).append(p)
    for topic, payloads in want.items():
        have = iter(got.get(topic, []))
        if not all(any(p == q for q in have) for p in payloads):  # a subsequence, in order
            return False
    return True


def test_cuts_and_flips_salvage_to_files_that_pass_doctor(converted, tmp_path):
    data = converted.read_bytes()
    s = m.read_summary_from_bytes(data)
    chunks = _chunks(data)
    data_start = chunks[0][0]
    rng = random.Random(SEED)
    counts = {"cut": 0, "cut_ok": 0, "cut_refused": 0, "flip": 0, "flip_ok": 0, "flip_all_others": 0}
    out = tmp_path / "fixed.mcap"
    for k in range(CUTS + FLIPS):
        flip = k >= CUTS
        at = rng.randrange(data_start, s.data_end_offset)
        if flip:
            broken_bytes = bytearray(data)
            broken_bytes[at] ^= rng.randrange(1, 256)
        else:
            broken_bytes = bytearray(data[:at])
        broken = tmp_path / "broken.mcap"
        broken.write_bytes(bytes(broken_bytes))
        kind = "flip" if flip else "cut"
        counts[kind] += 1
        try:
            salvage(broken, out, overwrite=True)
        except ArchiveError as exc:
            assert not flip and at < chunks[0][1] and "nothing recoverable" in str(exc), f"{kind} at {at}: {exc}"
            counts["cut_refused"] += 1
            continue
        problems = check_file(out).problems
        assert not problems, f"{kind} at {at}: {problems}"
        before = [c for c in chunks if c[1] <= at]
        assert _holds(out, before), f"{kind} at {at}: a chunk before the damage is missing"
        counts[f"{kind}_ok"] += 1
        if flip and _holds(out, [c for c in chunks if not c[0] <= at < c[1]]):
            counts["flip_all_others"] += 1
    print(f"\n{converted.name}: {len(data)} bytes, {len(chunks)} chunks: {counts}")
    assert counts["cut_ok"] + counts["cut_refused"] == CUTS and counts["flip_ok"] == FLIPS


@pytest.mark.parametrize("converted", ["sim_r2g", "axivity_cwa"], indirect=True)
def test_a_flip_in_each_kind_of_record(converted, tmp_path):
    """One flipped byte in the middle of a record of every kind: the output passes doctor, keeps every chunk
    that does not hold the byte, and drops a metadata record only when the byte is in it (located by the
    data-section CRC, since metadata records have no CRC of their own)."""
    data = converted.read_bytes()
    s = m.read_summary_from_bytes(data)
    chunks = _chunks(data)
    first: dict[int, tuple[int, int]] = {}
    metadata: list[tuple[int, int]] = []
    for op, pos, body in m.iter_records(data, len(m.MAGIC), s.data_end_offset):
        first.setdefault(op, (pos, pos + 9 + len(body)))
        if op == m.Op.METADATA:
            metadata.append((pos, pos + 9 + len(body)))
    targets = [(op, (a + b) // 2) for op, (a, b) in first.items()]
    targets += [(m.Op.METADATA, (a + b) // 2) for a, b in metadata]
    targets.append((m.Op.CHUNK, chunks[1][0] + 12))  # a chunk's start time: a field no CRC covers
    assert {m.Op.SCHEMA, m.Op.CHANNEL, m.Op.METADATA, m.Op.MESSAGE_INDEX, m.Op.CHUNK} <= {op for op, _ in targets}
    out = tmp_path / "fixed.mcap"
    for op, at in targets:
        broken = bytearray(data)
        broken[at] ^= 0x5A
        (tmp_path / "broken.mcap").write_bytes(bytes(broken))
        report = salvage(tmp_path / "broken.mcap", out, overwrite=True)
        assert check_file(out).ok, (m.OP_NAMES[op], at, check_file(out).problems)
        assert _holds(out, [c for c in chunks if not c[0] <= at < c[1]]), (m.OP_NAMES[op], at)
        dropped = [d.split(" at byte ")[1].split(":")[0] for d in report.dropped_metadata]
        hit = [str(a) for a, b in metadata if a <= at < b]
        assert dropped == hit, (m.OP_NAMES[op], at, report.dropped_metadata)


@pytest.mark.parametrize("converted", ["sim_r2g"], indirect=True)
def test_steps_run_on_a_salvaged_trial_and_keep_its_salvage_record(converted, tmp_path):
    data = bytearray(converted.read_bytes())
    chunks = _chunks(bytes(data))
    imu = [c for c in chunks if c[2] and c[2][0][0].startswith("/imu/")]
    start, end, msgs = imu[len(imu) // 2]  # a chunk in the middle of an IMU channel
    topic = msgs[0][0]
    data[(start + end) // 2] ^= 0x20
    (tmp_path / "broken.mcap").write_bytes(bytes(data))
    fixed = tmp_path / "fixed.mcap"
    runner = CliRunner()
    res = runner.invoke(cli, ["salvage", str(tmp_path / "broken.mcap"), "-o", str(fixed)])
    assert res.exit_code == 0 and "partial: " + topic in res.output, res.output
    res = runner.invoke(cli, ["process", "orientation", str(fixed)])
    assert res.exit_code == 0, res.output
    with TrialReader(fixed) as tr:
        spans = tr.metadata["imulog.salvage"]["lost_spans"][topic]
        run = next(r for r in tr.runs().values() if r["step"].startswith("orientation"))
        assert run["salvage"]["partial_inputs"] == {topic: spans}
        assert run["salvage"]["source"].endswith("broken.mcap") and run["salvage"]["data_crc"] == "mismatch"
    assert check_file(fixed).ok  # the processed salvaged trial is still sound
