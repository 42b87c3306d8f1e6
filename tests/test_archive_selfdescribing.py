"""A trial decodes with only `mcap` + `protobuf` and the schemas embedded in the file: no imulog import."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_archive_helpers import assert_bit_identical, synthetic_recording

from imulog.archive import write_trial

# Runs in a fresh interpreter where importing imulog (or converters) fails.
DECODER = r"""
import importlib.abc, json, struct, sys

class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("imulog", "converters"):
            raise ImportError(f"{name} is blocked in this test")
        return None

sys.meta_path.insert(0, Block())
try:
    import imulog  # noqa: F401
except ImportError:
    pass
else:
    raise SystemExit("imulog is importable: the test would prove nothing")

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.json_format import MessageToDict
from mcap.reader import make_reader

from google.protobuf.descriptor import FieldDescriptor as FD

PACK = {FD.TYPE_SFIXED64: "q", FD.TYPE_DOUBLE: "d", FD.TYPE_BOOL: "?"}
classes = {}
out = {}
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, validate_crcs=True)
    for schema, channel, message in reader.iter_messages():
        if channel.topic.startswith("/derived/viewer/"):  # viewer twins: tests/test_interop_viewers.py
            continue
        assert schema.encoding == "protobuf" and channel.message_encoding == "protobuf"
        if schema.id not in classes:
            fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
            pool = descriptor_pool.DescriptorPool()
            for fd in fds.file:
                pool.Add(fd)
            classes[schema.id] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
        msg = classes[schema.id].FromString(message.data)
        d = out.setdefault(channel.topic, {"schema": schema.name, "messages": []})
        if schema.name == "foxglove.PoseInFrame":
            p, q = msg.pose.position, msg.pose.orientation
            t = msg.timestamp.seconds * 10**9 + msg.timestamp.nanos
            d["messages"].append({"t": t, "v": struct.pack("<7d", p.x, p.y, p.z, q.w, q.x, q.y, q.z).hex()})
        elif schema.name == "imulog.IntervalEvent":
            d["messages"].append(MessageToDict(msg, preserving_proto_field_name=True))
        else:  # packed repeated numbers arrive as Python numbers: pack them back to compare bit for bit
            fields = {}
            for fd, value in msg.ListFields():
                if fd.type == FD.TYPE_MESSAGE and fd.name.endswith("_q"):  # schema_version 2: imulog.Numbers
                    width = len(value.shift or value.divisor or value.scale or value.offset or [0])
                    if value.f32:
                        vals = list(value.f32)
                    elif value.decimals:  # each value's own decimals: counts / 10**decimals, then scale, offset
                        vals = []
                        for i, (c, d) in enumerate(zip(value.counts, value.decimals)):
                            v = float(c) / 10.0**d
                            if value.scale:
                                v *= value.scale[i % len(value.scale)]
                            if value.offset:
                                v += value.offset[i % len(value.offset)]
                            vals.append(v)
                    else:  # ((counts + shift) / divisor) * scale + offset, per column; absent steps skipped
                        vals = []
                        for i, c in enumerate(value.counts):
                            v, k = float(c), i % width
                            if value.shift:
                                v += value.shift[k]
                            if value.divisor:
                                v /= value.divisor[k]
                            if value.scale:
                                v *= value.scale[k]
                            if value.offset:
                                v += value.offset[k]
                            vals.append(v)
                    fields[fd.name[:-2]] = struct.pack(f"<{len(vals)}d", *vals).hex()
                    continue
                fmt = PACK.get(fd.type) if fd.is_repeated else None
                if fmt:
                    value = struct.pack(f"<{len(value)}{fmt}", *value)
                fields[fd.name] = value.hex() if isinstance(value, bytes) else (list(value) if fd.is_repeated else value)
            if msg.count and not len(msg.t_ns):  # schema_version 2: start + span spread evenly (+ residuals)
                n, res = msg.count, list(msg.t_residual_ns) or [0] * msg.count
                den = max(n - 1, 1)
                t = [msg.t0_ns + (2 * k * msg.t_span_ns + den) // (2 * den) + res[k] for k in range(n)]
                fields["t_ns"] = struct.pack(f"<{n}q", *t).hex()
            d["messages"].append(fields)
json.dump(out, sys.stdout)
"""


@pytest.fixture(scope="module")
def decoded(tmp_path_factory) -> tuple[dict, object]:
    import json

    rec = synthetic_recording(np.random.default_rng(7))
    path = write_trial(tmp_path_factory.mktemp("selfdesc") / "trial.mcap", rec)
    res = subprocess.run([sys.executable, "-c", DECODER, str(path)], capture_output=True, text=True, cwd="/")
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout), rec


def _cat(messages: list[dict], field: str, dtype: str) -> np.ndarray:
    return np.frombuffer(bytes.fromhex("".join(m.get(field, "") for m in messages)), dtype=dtype)


def test_every_channel_decodes_without_imulog(decoded):
    out, rec = decoded
    non_empty = {s.topic for s in rec.streams() if len(s)}
    assert set(out) == non_empty  # empty channels have no messages to decode


def test_imu_block_arrays_are_bit_identical(decoded):
    out, rec = decoded
    imu = rec.imus[0]
    msgs = out["/imu/wrist"]["messages"]
    assert out["/imu/wrist"]["schema"] == "imulog.ImuBlock"
    assert all(m["schema_version"] in (1, 2) for m in msgs)  # 2: a block using the fields of issue 28
    assert all(m["schema_version"] == 2 for m in msgs if {"t0_ns", "t_span_ns", "t_residual_ns"} & set(m))
    assert sum(m["count"] for m in msgs) == len(imu)
    assert_bit_identical(_cat(msgs, "t_ns", "<i8"), imu.t_ns, "t_ns")
    for f in ("acc", "gyr", "mag"):
        assert_bit_identical(_cat(msgs, f, "<f8").reshape(-1, 3), getattr(imu, f), f)
    assert_bit_identical(_cat(msgs, "temperature", "<f8"), imu.temperature, "temperature")
    chest = out["/imu/chest"]["messages"]
    assert "gyr" not in chest[0] and "acc" in chest[0]  # absent sensors stay absent


def test_marker_analog_signal_blocks_are_bit_identical(decoded):
    out, rec = decoded
    mk = rec.markers[0]
    msgs = out["/markers/vicon"]["messages"]
    assert msgs[0]["labels"] == ["O", "X", "Y", "A"]
    assert_bit_identical(_cat(msgs, "t_ns", "<i8"), mk.t_ns, "marker t")
    assert_bit_identical(_cat(msgs, "pos", "<f8").reshape(-1, 4, 3), mk.pos, "pos")
    assert np.array_equal(_cat(msgs, "valid", "u1").reshape(-1, 4).astype(bool), mk.valid)
    an = rec.analogs[0]
    msgs = out["/analog/emg"]["messages"]
    assert msgs[0]["channel_names"] == ["biceps", "triceps"] and msgs[0]["units"] == ["V", "mV"]
    assert_bit_identical(_cat(msgs, "values", "<f8").reshape(-1, 2), an.values, "analog")
    sig = rec.signals[0]
    msgs = out[sig.topic]["messages"]
    assert msgs[0]["columns"] == sig.columns
    assert_bit_identical(_cat(msgs, "values", "<f8").reshape(-1, 4), sig.values, "signal")


def test_intervals_and_pose_blocks(decoded):
    out, rec = decoded
    ev = rec.events[0]
    msgs = out["/events/c3d"]["messages"]
    assert [int(m.get("start_ns", 0)) for m in msgs] == ev.start_ns.tolist()
    assert [int(m.get("end_ns", 0)) for m in msgs] == ev.end_ns.tolist()
    assert [m.get("label", "") for m in msgs] == ev.labels
    assert [int(m.get("task_index", 0)) for m in msgs] == ev.task_index.tolist()
    ps = rec.poses[0]
    msgs = out["/poses/cluster"]["messages"]
    assert out["/poses/cluster"]["schema"] == "imulog.PoseBlock"
    assert_bit_identical(_cat(msgs, "t_ns", "<i8"), ps.t_ns, "pose t")
    assert_bit_identical(_cat(msgs, "position", "<f8").reshape(-1, 3), ps.position, "position")
    assert_bit_identical(_cat(msgs, "orientation", "<f8").reshape(-1, 4), ps.orientation, "orientation")


def test_mcap_protobuf_support_decoder_reads_it_too(tmp_path: Path):
    pytest.importorskip("mcap_protobuf")
    pytest.importorskip("mcap_ros2")
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    rec = synthetic_recording(np.random.default_rng(3))
    path = write_trial(tmp_path / "t.mcap", rec)
    counts: dict[str, int] = {}
    with open(path, "rb") as f:
        for _, channel, _, msg in make_reader(
            f, decoder_factories=[DecoderFactory(), Ros2DecoderFactory()]
        ).iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + (msg.count if hasattr(msg, "count") else 1)
    assert counts["/imu/wrist"] == len(rec.imus[0])
    assert counts["/poses/cluster"] == len(rec.poses[0])
    assert counts["/events/c3d"] == len(rec.events[0])
