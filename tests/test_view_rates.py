"""What the viewer sends at less than the full rate, and channels read while they are logged."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr

from imulog.model import Intervals, PoseStream
from imulog.view import from_recording, rates, show
from imulog.view import layout as L
from imulog.view.rrd import read_column, summarize
from imulog.view.sample import SampleTrialParams, sample_recording
from imulog.view.source import ArchiveStreams, open_trial, read_trial
from imulog.view.streams import scalar_column

FRAME_NS = 1e9 / rates.DISPLAY_RATE_HZ


def _latest_at(t_rows: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Index of the latest row at or before each query time (-1: none)."""
    return np.searchsorted(t_rows, t_query, side="right") - 1


def test_display_rows_keep_one_sample_per_frame():
    t = np.arange(1000, dtype=np.int64) * 10_000_000 + 123  # 10 s at 100 Hz
    rows = rates.display_rows(t)
    assert rows[0] == 0 and rows[-1] == len(t) - 1 and np.all(np.diff(rows) > 0)
    assert len(rows) <= 10 * rates.DISPLAY_RATE_HZ + 2
    shown = rows[_latest_at(t[rows], t)]  # what the viewer draws at each sample's time
    assert np.max(t - t[shown]) < FRAME_NS


def test_display_rows_slow_streams_and_gaps():
    slow = np.arange(50, dtype=np.int64) * 50_000_000  # 20 Hz: below the display rate, nothing dropped
    np.testing.assert_array_equal(rates.display_rows(slow), np.arange(50))
    t = np.concatenate([np.arange(100), np.arange(400, 500)]).astype(np.int64) * 10_000_000  # a 3-s gap
    rows = rates.display_rows(t)
    assert 100 in rows  # the first sample after the gap is drawn at once
    assert np.max(t - t[rows[_latest_at(t[rows], t)]]) < FRAME_NS
    assert list(rates.display_rows(np.array([5, 7], np.int64))) == [0, 1]
    assert len(rates.display_rows(np.zeros(0, np.int64))) == 0


def test_pattern_changes_against_a_loop():
    rng = np.random.default_rng(3)
    valid = rng.random((500, 4)) > 0.05
    valid[100:140] = True
    expected = [k for k in range(len(valid)) if k == 0 or not np.array_equal(valid[k], valid[k - 1])]
    np.testing.assert_array_equal(rates.pattern_changes(valid), expected)
    assert list(rates.pattern_changes(np.ones((30, 3), bool))) == [0]
    assert len(rates.pattern_changes(np.zeros((0, 3), bool))) == 0


def test_scalar_column_is_the_arrays_own_buffer():
    """The time series are sent as arrow views of the float64 arrays: the same column as rr.Scalars.columns
    builds, without its copy."""
    values = np.random.default_rng(0).normal(size=(1000, 3))
    column = scalar_column(values).as_arrow_array()
    expected = next(iter(rr.Scalars.columns(scalars=values))).as_arrow_array()
    assert column.equals(expected) and len(column) == 1000
    assert column.values.buffers()[1].address == values.ctypes.data  # no copy
    one = scalar_column(values[:, 0]).as_arrow_array()  # a strided column: copied once, one value per row
    assert one.equals(next(iter(rr.Scalars.columns(scalars=values[:, 0]))).as_arrow_array())


def test_marker_class_ids_follow_the_visible_markers(tmp_path):
    """With an occluded marker the labels (class ids) are sent where the visible set changes; carried forward
    (latest-at, as the viewer queries) they name every point of every frame correctly."""
    rec = sample_recording(SampleTrialParams(duration_s=10.0))
    markers = rec.markers[0]
    assert not markers.valid.all()  # the sample trial occludes a marker for a while
    out = tmp_path / "m.rrd"
    show([from_recording(rec, "m")], sink="save", save_paths=[out])
    entity = L.marker_entity(markers.name)
    t_pos, points = read_column(out, entity, "Points3D:positions")
    t_ids, ids = read_column(out, entity, "Points3D:class_ids")
    assert len(t_pos) == len(markers) == summarize(out)[entity].rows
    assert 1 < len(t_ids) < len(markers) // 10  # only where the set changes, not at every frame
    carried = _latest_at(t_ids, t_pos)
    assert carried.min() >= 0
    for k in range(len(markers)):
        visible = np.flatnonzero(markers.valid[k])
        assert ids[carried[k]] == visible.tolist()
        assert len(points[k]) == len(visible)
        np.testing.assert_allclose(points[k], markers.pos[k, visible], atol=1e-5)


@pytest.fixture(scope="module")
def archived(tmp_path_factory):
    from imulog.archive import write_trial

    tmp = tmp_path_factory.mktemp("rates")
    return write_trial(tmp / "t.mcap", sample_recording(SampleTrialParams(duration_s=10.0)))


def test_open_trial_reads_each_channel_when_reached(archived, monkeypatch):
    from imulog.archive import TrialReader

    data = open_trial(archived)
    with TrialReader(archived) as tr:
        assert isinstance(data.streams, ArchiveStreams) and sorted(data.streams.topics) == sorted(tr.topics())
    reads: list[str] = []
    real_read = TrialReader.read
    monkeypatch.setattr(TrialReader, "read", lambda self, topic, *a, **k: reads.append(topic) or real_read(self, topic))
    it = iter(data.streams)
    first = next(it)
    assert reads == [first.topic]  # nothing else read yet
    rest = list(it)
    kinds = [isinstance(s, Intervals) for s in [first, *rest]]
    assert kinds == sorted(kinds, reverse=True)  # intervals first
    topics = [s.topic for s in [first, *rest]]
    pose = topics.index(L.CLUSTER_POSE_TOPIC)
    assert isinstance([first, *rest][pose], PoseStream)
    assert all(pose < topics.index(t) for t in topics if t.startswith(L.TRAJECTORY_PREFIX))


def test_open_trial_and_read_trial_give_the_same_recording(archived, tmp_path):
    lazy, eager = tmp_path / "lazy.rrd", tmp_path / "eager.rrd"
    show([open_trial(archived)], sink="save", save_paths=[lazy])
    show([read_trial(archived)], sink="save", save_paths=[eager])
    a, b = summarize(lazy), summarize(eager)
    assert a.keys() == b.keys()
    for entity in a:
        assert (a[entity].rows, a[entity].t_min_ns, a[entity].t_max_ns) == (
            b[entity].rows,
            b[entity].t_min_ns,
            b[entity].t_max_ns,
        ), entity
        assert a[entity].components == b[entity].components, entity
    _, err_lazy = read_column(lazy, L.error_entity("/derived/trajectory/zupt"), "Scalars:scalars")
    _, err_eager = read_column(eager, L.error_entity("/derived/trajectory/zupt"), "Scalars:scalars")
    assert err_lazy == err_eager and len(err_lazy) > 0  # anchored on the Vicon pose read before it


def test_a_damaged_chunk_met_while_logging_leaves_no_rrd(archived, tmp_path):
    from imulog.archive import ArchiveCorruptError, TrialReader

    with TrialReader(archived) as tr:
        cid = next(c.id for c in tr.summary.channels.values() if c.topic == "/imu/wrist")
        chunk = next(ci for ci in tr.summary.chunk_indexes if cid in ci.message_index_offsets)
    bad = bytearray(archived.read_bytes())
    bad[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0x10
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(bad))
    data = open_trial(damaged)  # the summary is intact: the damage is met when the IMU channel is read
    out = tmp_path / "damaged.rrd"
    with pytest.raises(ArchiveCorruptError, match="/imu/wrist"):
        show([data], sink="save", save_paths=[out])
    assert not out.exists()
