"""Issue 24: an append holds the trial's chunk indexes as the summary's bytes, not one object per chunk.

Every append checks the summary against the data section's record heads and writes the old chunk indexes into
the new summary. Both used to build every ChunkIndex (about 0.9 KB each) and a dict of every chunk and message
index seen: ``imulog process heading`` on a two-IMU week (about 10,000 chunks) grew with the recording although
it reads no samples. Here a trial of many small chunks is appended to (a metadata record, as heading does; a
derived channel; the same channel replaced, which rewrites the file) while a spy counts the ChunkIndex objects
alive at once; the files are the same as before (doctor accepts them, the old indexes come back equal).
"""

from __future__ import annotations

import weakref

import numpy as np
import pytest
from test_archive_helpers import synthetic_recording

from imulog.archive import _builder, append_derived, mcap_summary, streaming, write_trial
from imulog.archive import _mcap as m
from imulog.archive.doctor import check_file
from imulog.model import SignalStream


def _summary(path) -> m.Summary:
    with open(path, "rb") as f:
        return m.read_summary(f, path.stat().st_size)


class LiveIndexes:
    """Counts the ChunkIndex objects parsed from a summary that are alive at the same time."""

    def __init__(self, monkeypatch) -> None:
        self.live = self.most = self.parsed = 0
        real = mcap_summary.parse_chunk_index

        def spy(body):
            ci = real(body)
            self.live += 1
            self.parsed += 1
            self.most = max(self.most, self.live)
            weakref.finalize(ci, self._gone)
            return ci

        monkeypatch.setattr(mcap_summary, "parse_chunk_index", spy)

    def _gone(self) -> None:
        self.live -= 1


@pytest.fixture()
def many_chunks(tmp_path, monkeypatch):
    """A trial of every stream type written in chunks of 2 KiB (hundreds of chunks)."""
    for mod in (_builder, streaming):
        monkeypatch.setattr(mod, "CHUNK_TARGET_BYTES", 2048)
    path = write_trial(tmp_path / "t.mcap", synthetic_recording(np.random.default_rng(3), n_imu=20_000))
    assert len(_summary(path).chunk_indexes) >= 200
    return path


def _derived(n: int, seed: int) -> SignalStream:
    t = np.arange(n, dtype=np.int64) * 10_000_000 + 1_700_000_000_000_000_000
    return SignalStream("/derived/x", t, ["v"], ["1"], np.random.default_rng(seed).normal(size=n))


def test_appends_hold_no_chunk_index_per_chunk(many_chunks, monkeypatch):
    path = many_chunks
    before = _summary(path)
    old = list(before.chunk_indexes)
    steps = [
        ("metadata only (heading)", [], {"imulog.heading": {"note": "x"}}),
        ("a derived channel, in place", [_derived(5_000, 1)], {}),
        ("the channel replaced: a rewrite", [_derived(6_000, 2)], {}),
    ]
    for what, streams, metadata in steps:
        spy = LiveIndexes(monkeypatch)
        append_derived(path, streams, run={"step": "x"}, metadata=metadata)
        assert spy.parsed >= len(old), what  # every index was read (checked, written again) ...
        assert spy.most <= 2, f"{what}: {spy.most} ChunkIndex objects alive at once"  # ... one at a time
        monkeypatch.undo()
        report = check_file(path)
        assert report.ok, (what, report.problems)
        after = _summary(path)
        kept = [ci for ci in after.chunk_indexes if ci.chunk_start_offset < before.data_end_offset]
        assert kept == old, what  # the trial's own chunks indexed as before
        st = after.statistics
        assert st.chunk_count == len(after.chunk_indexes)
        assert st.message_start_time == min(c.message_start_time for c in after.chunk_indexes)
        assert st.message_end_time == max(c.message_end_time for c in after.chunk_indexes)


def test_a_chunk_index_that_disagrees_is_still_refused(many_chunks, tmp_path):
    """The walk of record heads compares each chunk as it passes: a wrong index in the middle is found."""
    from test_summary_repair import with_summary

    from imulog.archive.errors import ArchiveCorruptError

    s = _summary(many_chunks)
    middle = s.chunk_indexes[len(s.chunk_indexes) // 2]

    def edit(records):
        out = []
        for r in records:
            if r[0] == m.Op.CHUNK_INDEX and m.parse_chunk_index(r[9:]).chunk_start_offset == middle.chunk_start_offset:
                ci = m.parse_chunk_index(r[9:])
                ci.uncompressed_size += 1
                r = ci.encode()
            out.append(r)
        return out

    bad = with_summary(many_chunks, tmp_path / "bad.mcap", edit)
    message = f"chunk index for byte {middle.chunk_start_offset} disagrees with the chunk"
    assert message in check_file(bad).problems
    with pytest.raises(ArchiveCorruptError, match=message):
        append_derived(bad, [], run={"step": "x"}, metadata={"imulog.heading": {"note": "x"}})
