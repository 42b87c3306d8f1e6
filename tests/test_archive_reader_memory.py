"""What ``TrialReader.iter_blocks`` holds grows with the file's chunks only by a fixed-size row per chunk."""

from __future__ import annotations

import gc
import tracemalloc

import numpy as np

from imulog.archive import TrialReader, _builder, write_trial
from imulog.model import ImuStream, Recording


def _trial(path, n: int):
    """``n`` samples of a 50 Hz IMU (acc, gyr)."""
    rng = np.random.default_rng(7)
    t = np.arange(n, dtype=np.int64) * 20_000_000
    imu = ImuStream("wrist", t, acc=rng.normal(0, 1, (n, 3)), gyr=rng.normal(0, 1, (n, 3)), meta={"rate_hz": 50.0})
    return write_trial(path, Recording(imus=[imu]))


def _iteration_peak(trial) -> tuple[int, int, int]:
    """Samples read, chunks in the file, and the traced peak (bytes) of reading the IMU block by block in an
    open reader (the summary read at opening is not counted: it is the same before and after this change)."""
    with TrialReader(trial) as reader:
        gc.collect()
        tracemalloc.start()
        try:
            n = sum(len(block) for block in reader.iter_blocks("/imu/wrist"))
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        return n, reader.summary.chunk_count, peak


def test_iter_blocks_keeps_no_parsed_chunk_index_per_chunk(tmp_path, monkeypatch):
    """The reader parsed every ChunkIndex of the file (with its offsets map) on the first read and kept the list
    while open. With 16 KiB chunks (many small chunks, so the per-chunk bookkeeping is what grows) 4x the samples
    raised the traced peak of reading the IMU block by block by 1.74 MB for 2,630 more chunks (660 bytes a chunk);
    now the reader keeps 32 bytes per chunk of the channel read (offsets, times, summary numbers) and parses one
    ChunkIndex at a time: 71-78 kB (27-30 bytes a chunk of the file). With the default 2 MiB chunks a day at
    100 Hz is a few dozen chunks either way (benchmarks/reader_memory.py)."""
    monkeypatch.setattr(_builder, "CHUNK_TARGET_BYTES", 16 * 1024)
    small, big = _trial(tmp_path / "small.mcap", 100_000), _trial(tmp_path / "big.mcap", 400_000)
    _iteration_peak(small)  # imports and first-use caches out of the measurement
    n_small, chunks_small, peak_small = _iteration_peak(small)
    n_big, chunks_big, peak_big = _iteration_peak(big)
    assert (n_small, n_big) == (100_000, 400_000)
    more_chunks = chunks_big - chunks_small
    assert more_chunks > 2000  # the case the bound is about: thousands of chunks more
    grown = peak_big - peak_small
    assert grown < 100 * more_chunks, (grown, more_chunks)  # before: 660 bytes per chunk


def test_blocks_and_ranges_unchanged_with_many_chunks(tmp_path, monkeypatch):
    """The lazily parsed chunk indexes select the same chunks: every block, and a time range, equal ``read``."""
    monkeypatch.setattr(_builder, "CHUNK_TARGET_BYTES", 16 * 1024)
    trial = _trial(tmp_path / "t.mcap", 50_000)
    with TrialReader(trial) as reader:
        whole = reader.read("/imu/wrist")
        blocks = list(reader.iter_blocks("/imu/wrist"))
        assert len(blocks) > 50
        np.testing.assert_array_equal(np.concatenate([b.t_ns for b in blocks]), whole.t_ns)
        np.testing.assert_array_equal(np.concatenate([b.gyr for b in blocks]), whole.gyr)
        lo, hi = int(whole.t_ns[12_345]), int(whole.t_ns[23_456])
        part = list(reader.iter_blocks("/imu/wrist", lo, hi))
        np.testing.assert_array_equal(np.concatenate([b.t_ns for b in part]), whole.t_ns[12_345:23_456])
        np.testing.assert_array_equal(reader.read("/imu/wrist", lo, hi).acc, whole.acc[12_345:23_456])
        assert reader.summary._chunk_indexes is None  # no read built the whole list of parsed indexes
