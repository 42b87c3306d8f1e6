"""The archive's fast paths give exactly the bytes of the plain ones (issue 17).

Viewer twins built as numpy rows equal protobuf's own serializer message by message; chunks written from
rows equal chunks written from a list of payloads; compression on worker threads gives the same file as
compression inline; an append copied by the kernel equals one copied through Python buffers, and both
refuse a damaged data section.
"""

from __future__ import annotations

import io
import os

import numpy as np
import pytest

from imulog.archive import _builder, append_derived, wire, write_trial
from imulog.archive._builder import McapBuilder
from imulog.archive._generated.foxglove import FrameTransform_pb2, PackedElementField_pb2, PointCloud_pb2
from imulog.archive.errors import ArchiveCorruptError
from imulog.archive.timeline import IDENTITY
from imulog.archive.twin_frames import _frame_samples
from imulog.archive.twin_record import set_stamp
from imulog.archive.twins import axes_twin, decimation, frame_twin, marker_twin
from imulog.archive.writer import payload_hash, rows_hash
from imulog.model import ImuStream, MarkerStream, Recording, SignalStream


def _times(n: int) -> np.ndarray:
    t = np.arange(n, dtype=np.int64) * 20_000_000 + 946_684_800 * 10**9
    t[:6] = [0, 1, 999_999_999, 10**9, 2**40, 2**40 + 5]  # zero seconds, zero nanos, one- to many-byte varints
    return t


def test_varint_rows_equal_varint():
    values = np.array([0, 1, 127, 128, 300, 2**31, 2**35, 2**56, 2**63 - 1, -1, 999_999_999])
    rows, mask = wire.varint_rows(values)
    for v, r, keep in zip(values.tolist(), rows, mask, strict=True):
        assert r[keep].tobytes() == wire.varint(v), v


def test_frame_twin_rows_equal_protobuf():
    rng = np.random.default_rng(0)
    n = 1500
    t = _times(n)
    q = rng.normal(size=(n, 4))
    q[3] = 0.0  # every field zero: left out, as protobuf does
    q[4, 1] = -0.0  # kept: protobuf compares bits
    q[7] = np.nan  # dropped sample
    stream = SignalStream("/derived/orientation/w", t, ["qw", "qx", "qy", "qz"], ["1"] * 4, q)
    origin = (t, rng.normal(size=(n, 3)))
    twin = frame_twin(stream, IDENTITY, parent="world", child="w", clock="w", origin=origin)
    keep, qq, pp = _frame_samples(stream, None, origin)
    msg = FrameTransform_pb2.FrameTransform(parent_frame_id="world", child_frame_id="w")
    want, times = [], []
    for k, stamp in enumerate(IDENTITY(t[keep]).tolist()):
        if not (np.isfinite(qq[k]).all() and np.isfinite(pp[k]).all()):
            continue
        set_stamp(msg, stamp)
        msg.translation.x, msg.translation.y, msg.translation.z = pp[k].tolist()
        msg.rotation.w, msg.rotation.x, msg.rotation.y, msg.rotation.z = qq[k].tolist()
        want.append(msg.SerializeToString())
        times.append(stamp)
    assert twin.payload_list() == want
    assert np.asarray(twin.log_times).tolist() == times
    assert rows_hash(twin.rows, twin.mask) == payload_hash(want)


def test_marker_and_axes_twin_rows_equal_protobuf():
    rng = np.random.default_rng(1)
    n, m = 900, 5
    t = _times(n)
    pos = rng.normal(size=(n, m, 3))
    valid = rng.random((n, m)) > 0.3
    pos[10, 2] = np.nan
    valid[12] = False  # no valid marker: the data field is left out
    stream = MarkerStream("vicon", t, [f"M{i}" for i in range(m)], pos, valid)
    twin = marker_twin(stream, IDENTITY)
    fld = PackedElementField_pb2.PackedElementField
    fields = [fld(name=axis, offset=4 * k, type=fld.FLOAT32) for k, axis in enumerate("xyz")]
    msg = PointCloud_pb2.PointCloud(frame_id=stream.frame_id, point_stride=12, fields=fields)
    msg.pose.position.SetInParent()
    msg.pose.orientation.w = 1.0
    ok = valid & np.isfinite(pos).all(axis=2)
    want = []
    keep = decimation(t)
    for i, stamp in zip(keep.tolist(), IDENTITY(t[keep]).tolist(), strict=True):
        set_stamp(msg, stamp)
        msg.data = np.ascontiguousarray(pos[i][ok[i]], dtype="<f4").tobytes()
        want.append(msg.SerializeToString())
    assert twin.payload_list() == want

    q = np.tile([1.0, 0, 0, 0], (n, 1))
    axes = axes_twin(
        SignalStream("/derived/orientation/w", t, ["qw", "qx", "qy", "qz"], ["1"] * 4, q), IDENTITY, clock="w"
    )
    got = axes.payload_list()
    for stamp, payload in zip(np.asarray(axes.log_times).tolist(), got, strict=True):
        cloud = PointCloud_pb2.PointCloud.FromString(payload)
        assert cloud.timestamp.seconds * 10**9 + cloud.timestamp.nanos == stamp
        cloud.ClearField("timestamp")
        assert len(cloud.data) == 36 * 16 and cloud.frame_id == "w"
    assert len({p[p.index(b"\x12") :] for p in got[3:]}) == 1  # the same points every time


@pytest.mark.parametrize("masked", [False, True])
def test_message_rows_write_the_bytes_of_add_messages(monkeypatch, masked):
    monkeypatch.setattr(_builder, "CHUNK_TARGET_BYTES", 5_000)  # many chunks
    rng = np.random.default_rng(2)
    n, w = 700, 40
    rows = rng.integers(0, 256, (n, w), dtype=np.uint8)
    mask = rng.random((n, w)) > 0.4 if masked else None
    times = np.cumsum(rng.integers(1, 10**6, n)).astype(np.uint64)
    payloads = wire.row_messages(rows, mask)

    def build(fill) -> bytes:
        buf = io.BytesIO()
        b = McapBuilder.new(buf, "test")
        fill(b)
        b.finish()
        return buf.getvalue()

    a = build(lambda b: b.add_messages(0, times.tolist(), payloads))
    b = build(lambda b: b.add_message_rows(0, times, rows, mask))
    assert a == b and len(a) > 30_000
    assert rows_hash(rows, mask, block=64) == payload_hash(payloads)


def _imu(n: int = 30_000) -> ImuStream:
    rng = np.random.default_rng(3)
    t = np.arange(n, dtype=np.int64) * 10_000_000
    return ImuStream("wrist", t, acc=rng.normal(size=(n, 3)), gyr=rng.normal(size=(n, 3)))


def test_worker_threads_write_the_same_file(tmp_path, monkeypatch):
    imu = _imu()
    write_trial(tmp_path / "threads.mcap", Recording(imus=[imu]))
    monkeypatch.setattr(_builder, "PIPELINE", False)
    write_trial(tmp_path / "inline.mcap", Recording(imus=[imu]))
    assert (tmp_path / "threads.mcap").read_bytes() == (tmp_path / "inline.mcap").read_bytes()


def _derived(imu: ImuStream) -> SignalStream:
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(imu), 1))
    return SignalStream("/derived/orientation/wrist", imu.t_ns, ["qw", "qx", "qy", "qz"], ["1"] * 4, q)


def test_append_writes_in_place(tmp_path):
    """An append writes into the trial itself: same file (inode), the old data section's bytes unchanged, no
    journal left, the result passes doctor and reads back."""
    from imulog.archive.doctor import check_file
    from imulog.archive.reader import TrialReader

    imu = _imu()
    path = tmp_path / "t.mcap"
    write_trial(path, Recording(imus=[imu]))
    before = path.read_bytes()
    with TrialReader(path) as tr:
        data_end = tr.summary.data_end_offset
    inode = os.stat(path).st_ino
    append_derived(path, [_derived(imu)], run={"step": "t", "algorithm": "none", "params": {}})
    after = path.read_bytes()
    assert os.stat(path).st_ino == inode
    assert after[:data_end] == before[:data_end] and len(after) > len(before)
    assert not list(tmp_path.glob(".t.mcap.*"))
    assert check_file(path).ok
    with TrialReader(path) as tr:
        assert np.array_equal(tr.read("/derived/orientation/wrist").values, _derived(imu).values)


def test_append_refuses_a_damaged_data_section(tmp_path):
    path = tmp_path / "t.mcap"
    imu = _imu()
    write_trial(path, Recording(imus=[imu]))
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside a compressed chunk: only the data-section CRC can tell
    path.write_bytes(bytes(data))
    with pytest.raises(ArchiveCorruptError, match="data section CRC mismatch"):
        append_derived(path, [_derived(imu)], run={"step": "t", "algorithm": "none", "params": {}})
    assert path.read_bytes() == bytes(data)  # the append went in place and was undone
    assert not list(tmp_path.glob(".t.mcap.*"))


def test_data_section_crc_keeps_resident_memory_small(tmp_path):
    """The append's CRC pass maps the trial; its pages are handed back as it goes (a week's trial is GBs)."""
    import subprocess
    import sys
    import zlib

    big = tmp_path / "big.bin"
    block = np.random.default_rng(1).integers(0, 256, 1 << 20, dtype=np.uint8).tobytes()
    with open(big, "wb") as f:
        for _ in range(256):  # 256 MiB
            f.write(block)
    probe = (
        "import sys\n"
        "from imulog.archive.append_output import _crc_of\n"
        "def hwm():\n"
        "    return next(int(x.split()[1]) for x in open('/proc/self/status') if x.startswith('VmHWM'))\n"
        "before = hwm()\n"
        "with open(sys.argv[1], 'rb') as f:\n"
        "    crc = _crc_of(f, 256 << 20)\n"
        "print(crc, hwm() - before)\n"
    )
    out = subprocess.run([sys.executable, "-c", probe, str(big)], capture_output=True, text=True, check=True)
    crc, grown_kb = map(int, out.stdout.split())
    assert crc == zlib.crc32(block * 256)
    assert grown_kb < 64 * 1024  # a fraction of the 256 MiB read


def test_a_reader_open_during_an_append_keeps_reading(tmp_path):
    """A trial opened before an in-place append reads the same samples after it (its summary points only below
    the old DataEnd, and no byte there is written); a reader opened afterwards sees the new channel too."""
    from imulog.archive.reader import TrialReader

    imu = _imu()
    path = tmp_path / "t.mcap"
    write_trial(path, Recording(imus=[imu]))
    with TrialReader(path) as before:
        topic = before.topics()[0]
        append_derived(path, [_derived(imu)], run={"step": "t", "algorithm": "none", "params": {}})
        assert np.array_equal(before.read(topic).acc, imu.acc)
        assert "/derived/orientation/wrist" not in before.topics()
    with TrialReader(path) as after:
        assert "/derived/orientation/wrist" in after.topics()
