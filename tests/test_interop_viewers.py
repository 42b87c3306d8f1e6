"""Trials as other tools see them (issue 16 items 1-3): one time axis, numbers, and viewer twins.

Opened with Rerun's own MCAP loader (``rerun.chunk.McapReader``, the Rust importer, no imulog code) and
decoded with the ``mcap`` package + ``foxglove-schemas-protobuf`` + ``mcap-ros2-support``.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_archive_helpers import generic_times

from imulog.archive import TrialReader, append_derived, check_file, write_trial
from imulog.archive.twin_filter import lowpass_at
from imulog.archive.twins import TWIN_RATE_HZ
from imulog.model import ImuStream, Intervals, MarkerStream, PoseStream, Recording, SignalStream
from imulog.process.alignment import reference_to_device

rr_chunk = pytest.importorskip("rerun.chunk")

START = "2019-02-14T08:58:00-05:00"
START_NS = 1_550_152_680 * 10**9  # the same instant, ns since the Unix epoch
DEV0 = 2_775 * 10**9  # IMU device clock at its first sample (46 min after the Vicon clock's zero)
LAG_NS = 1_500_000_000  # Vicon started 1.5 s before the IMU
K = int(np.ceil(100.0 / TWIN_RATE_HZ))  # the twins keep every K-th sample of these 100 Hz channels
ALIGNMENT = {"imu": "/imu/wrist", "offset_ns": LAG_NS - DEV0, "drift_ppm": 0.0, "t0_ns": DEV0}


def _quat_z(angle: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cos(angle / 2), np.zeros_like(angle), np.zeros_like(angle), np.sin(angle / 2)])


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """A converted then 'processed' trial: IMU on its device clock, Vicon on its own, then aligned."""
    rng = np.random.default_rng(4)
    n = 2000  # 20 s at 100 Hz
    t_dev = DEV0 + np.arange(n, dtype=np.int64) * 10_000_000
    t_ref = np.arange(n, dtype=np.int64) * 10_000_000  # Vicon clock from 0
    gyr = rng.normal(0, 1, (n, 3))
    acc = rng.normal(0, 9.81, (n, 3))
    imu = ImuStream("wrist", t_dev, acc=acc, gyr=gyr)
    pos = np.stack([rng.normal(0, 0.02, (n, 3)) + [0.4 + 0.05 * k, 0.2, 0.9] for k in range(4)], axis=1)
    valid = np.ones((n, 4), dtype=bool)
    valid[100:110, 2] = False
    pos[~valid] = np.nan
    markers = MarkerStream("vicon", t_ref, ["O", "X", "Y", "A"], pos, valid)
    rec = Recording(imus=[imu], markers=[markers], metadata={"imulog.trial": {"task": "r2g", "start_time": START}})
    path = write_trial(tmp_path_factory.mktemp("interop") / "trial.mcap", rec)
    q = _quat_z(np.linspace(0, 3, n))
    orientation = SignalStream("/derived/orientation/wrist", t_dev, ["qw", "qx", "qy", "qz"], ["1"] * 4, q)
    append_derived(path, [orientation], run={"step": "orientation", "algorithm": "test"})
    cluster = PoseStream("/derived/vicon/cluster_pose", t_ref, pos[:, 0], _quat_z(np.linspace(0, 1, n)))
    append_derived(
        path, [cluster], run={"step": "align", "algorithm": "test"}, metadata={"imulog.alignment": ALIGNMENT}
    )
    phases = Intervals("/derived/phases/wrist", t_dev[[200, 900]], t_dev[[600, 1500]], ["reach", "lift"], [1, 1])
    append_derived(path, [phases], run={"step": "phases", "algorithm": "test"})
    path_xyz = np.cumsum(rng.normal(0, 0.001, (n, 3)), axis=0)
    trajectory = SignalStream("/derived/trajectory/zupt", t_ref, ["x", "y", "z"], ["m"] * 3, path_xyz, "world")
    reps = [
        {"index": 1, "start_ns": int(t_ref[100]), "end_ns": int(t_ref[699])},
        {"index": 2, "start_ns": int(t_ref[800]), "end_ns": int(t_ref[1799])},
    ]
    record = {"imu": "/imu/wrist", "clock": "reference", "repetitions": reps}
    append_derived(path, [trajectory], run={"step": "trajectory"}, metadata={"imulog.trajectory": record})
    return path, imu, markers, q, cluster


def _rerun_entities(path) -> dict[str, list]:
    out: dict[str, list] = {}
    for chunk in rr_chunk.McapReader(path).stream():
        out.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch())
    return out


def _log_times(batches) -> np.ndarray:
    t = [
        rb.column("message_log_time").to_numpy().astype("datetime64[ns]").astype(np.int64)
        for rb in batches
        if "message_log_time" in rb.schema.names
    ]
    return np.sort(np.concatenate([x for x in t if len(x)]))


def _column(batches, name: str) -> list:
    return [row for rb in batches if name in rb.schema.names for row in rb.column(name).to_pylist()]


def test_one_time_axis_from_the_trial_start(processed):
    path, imu, markers, _, _ = processed
    assert check_file(path).ok
    with TrialReader(path) as tr:
        timeline = tr.metadata["imulog.timeline"]
        assert timeline["epoch_ns"] == START_NS and timeline["time_zone"] == "-05:00"
        assert timeline["clocks"] == "separate"
        starts = {
            c.topic: min(
                ci.message_start_time for ci in tr.summary.chunk_indexes if c.channel_id in ci.message_index_offsets
            )
            for c in tr.channels
        }
        # raw channels never move: each clock from its own first sample at the trial start
        assert starts["/imu/wrist"] == START_NS and starts["/markers/vicon"] == START_NS
        # written after align: through the alignment, on the IMU's axis (Vicon started LAG_NS earlier)
        assert starts["/derived/vicon/cluster_pose"] == START_NS - LAG_NS
        assert starts["/derived/viewer/markers/vicon"] == START_NS - LAG_NS
        # payloads keep the device and capture clocks; time-range reads still prune correctly
        assert tr.read("/imu/wrist").t_ns[0] == DEV0
        part = tr.read("/imu/wrist", start_ns=DEV0 + 7 * 10**9, end_ns=DEV0 + 9 * 10**9)
        assert np.array_equal(part.t_ns, imu.t_ns[700:900])
        part = tr.read("/derived/vicon/cluster_pose", start_ns=12 * 10**9, end_ns=13 * 10**9)
        assert np.array_equal(part.t_ns, markers.t_ns[1200:1300])


def test_rerun_loader_puts_imu_and_vicon_in_one_window(processed):
    path, imu, markers, _, _ = processed
    ents = _rerun_entities(path)
    imu_t = _log_times(ents["/derived/viewer/imu/wrist"])
    vicon_t = _log_times(ents["/derived/viewer/markers/vicon"])
    # the same 20 s window, shifted by the measured lag only (before: 46 minutes apart)
    assert abs(int(imu_t[0]) - START_NS) < 10**6 and abs(int(vicon_t[0]) - (START_NS - LAG_NS)) < 10**6
    assert abs(int(imu_t[-1]) - int(vicon_t[-1]) - LAG_NS) < 50_000_000
    assert (min(imu_t[-1], vicon_t[-1]) - max(imu_t[0], vicon_t[0])) / 1e9 > 18


def test_rerun_loader_plots_imu_draws_markers_and_moves_the_imu_frame(processed):
    path, imu, markers, q, cluster = processed
    ents = _rerun_entities(path)
    # IMU: ROS 2 sensor_msgs/Imu twin -> Scalars, which Rerun plots as time series without a blueprint
    scalars = np.array(_column(ents["/derived/viewer/imu/wrist"], "Scalars:scalars"), dtype=np.float64)
    assert scalars.shape == (2000 // K, 6)  # 100 Hz -> the twins' rate
    cols = _column(ents["/derived/viewer/imu/wrist"], "SeriesLines:names")[0]  # one static row of 6 names
    gyr_cols = [cols.index(f"gyroscope/{a}") for a in "xyz"]
    acc_cols = [cols.index(f"accelerometer/{a}") for a in "xyz"]
    keep = np.arange(0, 2000, K)  # every K-th sample of the low-passed signal (imulog.archive.twin_filter)
    gyr, acc = (lowpass_at(x, keep, K, imu.t_ns) for x in (imu.gyr, imu.acc))
    assert np.allclose(scalars[:, gyr_cols], gyr) and np.allclose(scalars[:, acc_cols], acc)
    assert not np.allclose(scalars[:, gyr_cols], imu.gyr[::K], atol=0.1)  # white noise: filtered, not sampled
    # markers: foxglove.PointCloud -> Points3D, only the markers seen
    points = _column(ents["/derived/viewer/markers/vicon"], "Points3D:positions")
    assert len(points) == 2000 // K and len(points[0]) == 4 and len(points[100 // K]) == 3  # sample 100: Y hidden
    assert np.allclose(np.array(points[0]), markers.pos[0], atol=1e-6)  # positions as sampled (not filtered)
    # the IMU frame: FrameTransform -> Transform3D world -> wrist, placed at the cluster, rotating
    tf = ents["/derived/viewer/orientation/wrist"]
    assert {v for row in _column(tf, "Transform3D:child_frame") for v in row} == {"wrist"}
    cluster_tf = ents["/derived/viewer/vicon/cluster_pose"]  # pose twins get frame names unique in the trial
    assert {v for row in _column(cluster_tf, "Transform3D:child_frame") for v in row} == {"vicon_cluster_pose"}
    quats = np.array(_column(tf, "Transform3D:quaternion"), dtype=np.float64).reshape(-1, 4)  # x, y, z, w
    assert np.allclose(quats[:, [3, 0, 1, 2]], q[::K], atol=1e-6)
    translation = np.array(_column(tf, "Transform3D:translation"), dtype=np.float64).reshape(-1, 3)
    shift = LAG_NS // 10_000_000  # the IMU's sample k is Vicon sample k + 150
    assert np.allclose(translation[:100], cluster.position[shift : shift + 100 * K : K], atol=1e-6)
    # ... and as coloured points along its axes in its own frame, which the transform moves: drawn as is
    axes = ents["/derived/viewer/axes/wrist"]
    assert {v for row in _column(axes, "CoordinateFrame:frame") for v in row} == {"wrist"}
    points = np.array(_column(axes, "Points3D:positions")[0], dtype=np.float64)
    assert points.shape == (36, 3) and np.allclose(points.max(axis=0), [0.12, 0.12, 0.12], atol=1e-6)
    assert len(_column(axes, "Points3D:positions")) == 100  # 5 Hz: constant points, a few bytes
    assert not np.allclose(translation[0], translation[-1]) and not np.allclose(quats[0], quats[-1])
    # phases: foxglove.Log -> TextLog
    texts = [v for row in _column(ents["/derived/viewer/phases/wrist"], "TextLog:text") for v in row]
    assert texts == ["reach #1 (4.00 s)", "lift #1 (6.00 s)"]


def test_every_channel_decodes_as_numbers_with_mcap_and_foxglove_schemas(processed):
    pytest.importorskip("foxglove_schemas_protobuf")
    pytest.importorskip("mcap_ros2")
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    path, imu, markers, q, _ = processed
    got: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory(), Ros2DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            got.setdefault(channel.topic, []).append((schema.name, message.log_time, decoded))
    # canonical blocks: packed repeated doubles come out as floats
    blocks = [d for _, _, d in got["/imu/wrist"]]
    assert isinstance(blocks[0].gyr[0], float)
    assert np.array_equal(np.concatenate([np.array(b.gyr) for b in blocks]).reshape(-1, 3), imu.gyr)
    t = [generic_times(b.count, b.t_ns, b.t0_ns, b.t_span_ns, b.t_residual_ns) for b in blocks]  # docs/schemas.md
    assert np.array_equal(np.concatenate(t), imu.t_ns)
    # the twins decode with Foxglove's published schemas (field numbers identical to ours)
    clouds = got["/derived/viewer/markers/vicon"]
    assert clouds[0][0] == "foxglove.PointCloud"
    cloud = PointCloud.FromString(clouds[0][2].SerializeToString())
    assert [fld.name for fld in cloud.fields] == ["x", "y", "z"] and cloud.point_stride == 12
    assert [fld.type for fld in cloud.fields] == [cloud.fields[0].FLOAT32] * 3
    assert np.array_equal(np.frombuffer(cloud.data, "<f4").reshape(-1, 3), markers.pos[0].astype(np.float32))
    assert cloud.timestamp.ToNanoseconds() == clouds[0][1]  # in-message stamp = log time = one axis
    frames = got["/derived/viewer/orientation/wrist"]
    tf = FrameTransform.FromString(frames[10][2].SerializeToString())
    assert (tf.parent_frame_id, tf.child_frame_id) == ("world", "wrist")
    assert np.allclose([tf.rotation.w, tf.rotation.x, tf.rotation.y, tf.rotation.z], q[10 * K])
    # trajectories: one foxglove.PosesInFrame per repetition, its path at 10 Hz, on the aligned axis
    from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame

    paths = got["/derived/viewer/trajectory/zupt"]
    assert [schema for schema, _, _ in paths] == ["foxglove.PosesInFrame"] * 2
    second = PosesInFrame.FromString(paths[1][2].SerializeToString())
    with TrialReader(path) as tr:
        xyz = tr.read("/derived/trajectory/zupt").values
    got_xyz = np.array([[p.position.x, p.position.y, p.position.z] for p in second.poses])
    assert np.array_equal(got_xyz, xyz[800:1800:10])
    assert paths[1][1] == START_NS + int(reference_to_device(np.int64(8 * 10**9), ALIGNMENT)) - DEV0
    ros = got["/derived/viewer/imu/wrist"]
    assert ros[0][0] == "sensor_msgs/msg/Imu"
    m = ros[3][2]
    gyr3 = lowpass_at(imu.gyr, np.arange(0, len(imu.t_ns), K), K, imu.t_ns)[3]  # the 4th twin sample, low-passed
    assert [m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] == gyr3.tolist()
    assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == ros[3][1]


def test_realigning_moves_the_viewer_twins_but_never_the_raw_channels(processed, tmp_path):
    import shutil

    path, _, markers, _, _ = processed
    copy = tmp_path / "t.mcap"
    shutil.copy(path, copy)
    with TrialReader(copy) as tr:
        raw_before = {t: tr.compute_channel_hash(t) for t in ("/imu/wrist", "/markers/vicon")}
    moved = {**ALIGNMENT, "offset_ns": ALIGNMENT["offset_ns"] - 250_000_000}  # Vicon 0.25 s later
    append_derived(copy, [], run={"step": "align", "algorithm": "test"}, metadata={"imulog.alignment": moved})
    with TrialReader(copy) as tr:
        assert {t: tr.compute_channel_hash(t) for t in raw_before} == raw_before
        ch = tr.channel("/derived/viewer/markers/vicon")
        first = min(
            ci.message_start_time for ci in tr.summary.chunk_indexes if ch.channel_id in ci.message_index_offsets
        )
    expected = START_NS + int(reference_to_device(np.int64(markers.t_ns[0]), moved)) - DEV0
    assert first == expected == START_NS - LAG_NS + 250_000_000


def test_real_broad_recording_keeps_imu_and_optical_together(shared_data, tmp_path):
    """BROAD: IMU and optical share one clock in the file, so they share one origin on the axis."""
    from imulog.converters.registry import convert_file

    rec = convert_file(shared_data / "broad/02_undisturbed_slow_rotation_B.hdf5")
    path = write_trial(tmp_path / "broad.mcap", rec, attach_sources=False)
    with TrialReader(path) as tr:
        timeline = tr.metadata["imulog.timeline"]
        assert timeline["clocks"] == "shared"
        imu, optical = tr.channel("/imu/" + rec.imus[0].name), tr.channel(rec.poses[0].topic)
        firsts = {}
        for c in (imu, optical):
            firsts[c.topic] = min(
                ci.message_start_time for ci in tr.summary.chunk_indexes if c.channel_id in ci.message_index_offsets
            )
    # same distance on the axis as in the file
    assert firsts[imu.topic] - firsts[optical.topic] == int(rec.imus[0].t_ns[0]) - int(rec.poses[0].t_ns[0])
    ents = _rerun_entities(path)
    assert _column(ents["/derived/viewer" + rec.poses[0].topic], "Transform3D:translation")
    assert _column(ents["/derived/viewer/imu/" + rec.imus[0].name], "Scalars:scalars")


def test_processed_r2g_trial_imu_and_vicon_share_one_window_in_rerun(processed_r2g):
    """recordings/sim's R2G trial (orientation, align, phases): its IMU clock starts 26 min after the Vicon
    clock's zero; with log time = payload time Rerun's loader showed them 26 min apart (the demo: 46 min)."""
    with TrialReader(processed_r2g) as tr:
        imu_t, vicon_t = tr.read("/imu/wrist").t_ns, tr.read("/markers/vicon").t_ns
    assert (imu_t[0] - vicon_t[0]) / 60e9 > 20  # the payload keeps the clocks as recorded
    topics = ["^/imu/wrist$", "^/markers/vicon$", "^/derived/viewer/(imu|markers|orientation|axes)/"]
    reader = rr_chunk.McapReader(processed_r2g, include_topic_regex=topics)
    spans: dict[str, tuple[int, int]] = {}
    for chunk in reader.stream():
        rb = chunk.to_record_batch()
        if "message_log_time" not in rb.schema.names or not rb.num_rows:
            continue
        t = rb.column("message_log_time").to_numpy().astype("datetime64[ns]").astype(np.int64)
        lo, hi = spans.get(str(chunk.entity_path), (2**63 - 1, -(2**63)))
        spans[str(chunk.entity_path)] = (min(lo, int(t.min())), max(hi, int(t.max())))
    assert set(spans) == {
        "/imu/wrist",
        "/markers/vicon",
        "/derived/viewer/imu/wrist",
        "/derived/viewer/markers/vicon",
        "/derived/viewer/orientation/wrist",
        "/derived/viewer/axes/wrist",
    }
    first = min(lo for lo, _ in spans.values())
    for entity, (lo, hi) in spans.items():  # every one starts within the alignment lag (s) and ends together
        assert (lo - first) / 1e9 < 5 and (hi - lo) / 1e9 > 0.9 * (imu_t[-1] - imu_t[0]) / 1e9, entity
