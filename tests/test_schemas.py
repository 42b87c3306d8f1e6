"""The .proto sources, the generated code and the schemas embedded in trial files agree."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from google.protobuf import descriptor_pb2

from imulog.archive import codec
from imulog.archive.generate import proto_files, stale_files


def test_generated_code_matches_proto_sources():
    pytest.importorskip("grpc_tools")
    stale = stale_files()
    assert not stale, f"regenerate with 'python -m imulog.archive.generate': {stale}"


def test_generate_check_command_exits_zero(repo_root: Path):
    pytest.importorskip("grpc_tools")
    res = subprocess.run(
        [sys.executable, "-m", "imulog.archive.generate", "--check"], cwd=repo_root, capture_output=True, text=True
    )
    assert res.returncode == 0, res.stdout + res.stderr


def test_every_proto_has_generated_module_and_descriptor(repo_root: Path):
    files = proto_files(repo_root / "schemas")
    assert "imulog/ImuBlock.proto" in files and "foxglove/PoseInFrame.proto" in files
    for name in files:
        package, stem = name.split("/")
        assert (repo_root / "imulog/archive/_generated" / package / f"{stem.removesuffix('.proto')}_pb2.py").is_file()


@pytest.mark.parametrize("schema_name", sorted(codec.MESSAGE_CLASSES))
def test_embedded_descriptor_sets_are_complete(schema_name):
    fds = descriptor_pb2.FileDescriptorSet.FromString(codec.file_descriptor_set(schema_name))
    names = [f.name for f in fds.file]
    # dependencies come before their users and every import is present
    for i, f in enumerate(fds.file):
        for dep in f.dependency:
            assert dep in names[:i], (schema_name, dep)
    package, message = schema_name.split(".")
    assert any(f.package == package and any(mt.name == message for mt in f.message_type) for f in fds.file)


def test_foxglove_schemas_use_foxglove_names_and_field_numbers():
    fds = descriptor_pb2.FileDescriptorSet.FromString(codec.file_descriptor_set("foxglove.PoseInFrame"))
    by_name = {
        f"{f.package}.{m.name}": {fld.name: fld.number for fld in m.field} for f in fds.file for m in f.message_type
    }
    assert by_name["foxglove.PoseInFrame"] == {"timestamp": 1, "frame_id": 2, "pose": 3}
    assert by_name["foxglove.Pose"] == {"position": 1, "orientation": 2}
    assert by_name["foxglove.Quaternion"] == {"x": 1, "y": 2, "z": 3, "w": 4}
    assert by_name["foxglove.Vector3"] == {"x": 1, "y": 2, "z": 3}
    assert "google.protobuf.Timestamp" in by_name
    from imulog.archive._generated.foxglove import FrameTransform_pb2, PosesInFrame_pb2

    assert [f.name for f in FrameTransform_pb2.FrameTransform.DESCRIPTOR.fields] == [
        "timestamp",
        "parent_frame_id",
        "child_frame_id",
        "translation",
        "rotation",
    ]
    assert [f.name for f in PosesInFrame_pb2.PosesInFrame.DESCRIPTOR.fields] == ["timestamp", "frame_id", "poses"]


@pytest.mark.parametrize("schema_name", [s for s in sorted(codec.MESSAGE_CLASSES) if s.startswith("imulog.")])
def test_imulog_blocks_carry_schema_version(schema_name):
    fields = {f.name for f in codec.MESSAGE_CLASSES[schema_name].DESCRIPTOR.fields}
    assert "schema_version" in fields


def test_newer_schema_version_is_refused_with_a_clear_message():
    from imulog.archive._generated.imulog import SignalBlock_pb2

    msg = SignalBlock_pb2.SignalBlock(schema_version=codec.SCHEMA_VERSION + 1, columns=["a"], units=["1"], count=0)
    with pytest.raises(codec.DecodeError, match="newer than this imulog understands"):
        codec.decode("imulog.SignalBlock", "/derived/a", {}, [msg.SerializeToString()])


def test_older_block_without_version_field_still_decodes():
    """Version 0 (field absent, as a reader meets a message from before versioning) decodes."""
    from imulog.archive._generated.imulog import SignalBlock_pb2

    t = np.arange(3, dtype="<i8")
    v = np.arange(3, dtype="<f8")
    msg = SignalBlock_pb2.SignalBlock(columns=["a"], units=["1"], count=3, t_ns=t.tolist(), values=v.tolist())
    s = codec.decode("imulog.SignalBlock", "/derived/a", {}, [msg.SerializeToString()])
    assert s.values[:, 0].tolist() == [0.0, 1.0, 2.0]


# ------------------------------------------------------------------ packed repeated numbers (issue 16 item 1)


def _random_streams(rng):
    from imulog.model import AnalogStream, ImuStream, MarkerStream, PoseStream, SignalStream

    n = 230
    t = np.cumsum(rng.integers(5_000_000, 15_000_000, n)).astype(np.int64) - 10**9
    acc = rng.normal(size=(n, 3))
    acc[5] = [np.nan, -0.0, np.inf]
    valid = rng.random((n, 3)) > 0.2
    pos = np.where(valid[..., None], rng.normal(size=(n, 3, 3)), np.nan)
    q = rng.normal(size=(n, 4))
    return [
        ImuStream("wrist", t, acc=acc, gyr=rng.normal(size=(n, 3)), temperature=rng.normal(30, 1, n)),
        ImuStream("chest", t, acc=acc),
        MarkerStream("vicon", t, ["O", "", "Y"], pos, valid),
        AnalogStream("emg", t, ["a", "b"], ["V", ""], rng.normal(size=(n, 2))),
        SignalStream("/derived/x", t, ["v"], ["1"], rng.normal(size=(n, 1)), frame_id="world"),
        PoseStream("/derived/vicon/cluster_pose", t, rng.normal(size=(n, 3)), q / np.linalg.norm(q, axis=1)[:, None]),
    ]


def _as_protobuf(schema_name: str, payload: bytes):
    """The same block built field by field with protobuf's own classes (Python lists for the arrays)."""
    parsed = codec.MESSAGE_CLASSES[schema_name].FromString(payload)
    rebuilt = codec.MESSAGE_CLASSES[schema_name]()
    for fd, value in parsed.ListFields():
        if fd.is_repeated:
            getattr(rebuilt, fd.name).extend(list(value))
        else:
            setattr(rebuilt, fd.name, value)
    return parsed, rebuilt


def test_block_writer_bytes_equal_protobufs_own_serialization():
    """imulog joins numpy bytes; protobuf serializing the same numbers gives the very same bytes."""
    for stream in _random_streams(np.random.default_rng(5)):
        schema, _, _, payloads = codec.encode(stream)
        assert schema in codec.BLOCK_SCHEMAS and len(payloads) > 1
        for payload in payloads:
            parsed, rebuilt = _as_protobuf(schema, payload)
            assert rebuilt.SerializeToString() == payload, schema
        # any protobuf reader gets numbers, not bytes
        times = parsed.t_ns if len(parsed.t_ns) else parsed.t_residual_ns  # jittered times: explicit or residuals
        assert isinstance(times[0], int)


def test_packed_bool_is_one_byte_per_value_on_the_wire():
    from imulog.archive._generated.imulog import MarkerBlock_pb2

    flags = [True, False, True, True, False]
    msg = MarkerBlock_pb2.MarkerBlock(valid=flags)
    assert msg.SerializeToString() == b"\x3a\x05" + bytes([1, 0, 1, 1, 0])  # tag 7/LEN, length 5, 0/1 each


def test_unpacked_repeated_fields_from_another_writer_decode_through_protobuf():
    """Protobuf readers must accept unpacked repeated numbers: the fast scan falls back and agrees."""
    from imulog.archive import wire

    stream = _random_streams(np.random.default_rng(9))[2]  # markers: sfixed64, double and bool arrays
    schema, meta, _, payloads = codec.encode(stream)
    unpacked = []
    for payload in payloads:
        out = b""
        for number, wire_type, value in wire.scan(payload):
            if number in (5, 6, 7):  # t_ns, pos, valid: one tagged value each
                width, wt = (1, wire.WIRE_VARINT) if number == 7 else (8, wire.WIRE_I64)
                raw = bytes(value)
                out += b"".join(wire.tag(number, wt) + raw[k : k + width] for k in range(0, len(raw), width))
            elif wire_type == wire.WIRE_VARINT:
                out += wire.tag(number, wire_type) + wire.varint(value)
            else:
                out += wire.len_field(number, value) if len(value) else wire.tag(number, 2) + b"\x00"
        unpacked.append(out)
    assert unpacked[0] != payloads[0]
    a = codec.decode(schema, "/markers/vicon", meta, payloads)
    b = codec.decode(schema, "/markers/vicon", meta, unpacked)
    assert np.array_equal(a.t_ns, b.t_ns) and np.array_equal(a.valid, b.valid)
    assert np.array_equal(a.pos.view(np.uint64), b.pos.view(np.uint64))  # NaN bits too


def test_files_written_with_bytes_fields_still_read(repo_root: Path):
    """tests/data/layout_v1_bytes.mcap was written by imulog before the change (bytes fields, PoseInFrame)."""
    from imulog.archive import TrialReader, check_file

    path = repo_root / "tests/data/layout_v1_bytes.mcap"
    ref = np.load(repo_root / "tests/data/layout_v1_bytes.npz")
    assert check_file(path).ok
    with TrialReader(path) as tr:
        schemas = {c.topic: c.schema_name for c in tr.channels}
        assert schemas["/poses/optical"] == "foxglove.PoseInFrame"
        embedded = {s.name: s.data for s in tr.summary.schemas.values()}
        old = descriptor_pb2.FileDescriptorSet.FromString(embedded["imulog.ImuBlock"])
        imu_fields = {f.name: f.type for f in old.file[-1].message_type[0].field}
        assert imu_fields["acc"] == descriptor_pb2.FieldDescriptorProto.TYPE_BYTES  # really the old layout
        imu = tr.read("/imu/wrist")
        mk = tr.read("/markers/vicon")
        pose = tr.read("/poses/optical")
        sig = tr.read("/signals/x")
        an = tr.read("/analog/emg")
        ev = tr.read("/events/e")
    assert np.array_equal(imu.t_ns, ref["t"]) and np.array_equal(mk.t_ns, ref["t"] + 123)
    for got, want in ((imu.acc, "acc"), (imu.gyr, "gyr"), (imu.temperature, "temp"), (mk.pos, "pos")):
        assert np.array_equal(got.view(np.uint64), ref[want].view(np.uint64)), want
    assert np.array_equal(mk.valid, ref["valid"])
    assert np.array_equal(an.values, ref["an"]) and np.array_equal(sig.values, ref["sig"])
    assert np.array_equal(pose.position, ref["ppos"]) and np.array_equal(pose.orientation, ref["pq"])
    assert ev.labels == ["reach", "foot"]


def test_appending_to_an_old_file_keeps_its_raw_bytes(repo_root: Path, tmp_path: Path):
    import shutil

    from imulog.archive import TrialReader, append_derived, check_file
    from imulog.model import SignalStream

    path = tmp_path / "old.mcap"
    shutil.copy(repo_root / "tests/data/layout_v1_bytes.mcap", path)
    with TrialReader(path) as tr:
        before = {t: tr.compute_channel_hash(t) for t in tr.topics()}
        t = tr.read("/imu/wrist").t_ns
    append_derived(path, [SignalStream("/derived/y", t, ["v"], ["1"], np.ones(len(t)))], run={"step": "test"})
    assert check_file(path).ok
    with TrialReader(path) as tr:
        assert {t: tr.compute_channel_hash(t) for t in before} == before
        assert np.array_equal(tr.read("/derived/y", start_ns=int(t[10]), end_ns=int(t[20])).t_ns, t[10:20])


def test_generated_descriptors_equal_protoc_output(repo_root: Path, tmp_path: Path):
    """Independent of the grpcio-tools release: each generated module's descriptor is what protoc compiles."""
    grpc_tools = pytest.importorskip("grpc_tools")
    import importlib

    from grpc_tools import protoc

    include = Path(grpc_tools.__file__).parent / "_proto"
    out = tmp_path / "set.pb"
    files = proto_files(repo_root / "schemas")
    assert (
        protoc.main(["protoc", f"-I{repo_root / 'schemas'}", f"-I{include}", f"--descriptor_set_out={out}", *files])
        == 0
    )
    compiled = {f.name: f for f in descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes()).file}
    assert sorted(compiled) == files
    for name in files:
        package, stem = name.split("/")
        module = importlib.import_module(f"imulog.archive._generated.{package}.{stem.removesuffix('.proto')}_pb2")
        generated = descriptor_pb2.FileDescriptorProto.FromString(module.DESCRIPTOR.serialized_pb)
        assert _without_json_names(generated) == _without_json_names(compiled[name]), name


def _without_json_names(fd: descriptor_pb2.FileDescriptorProto) -> descriptor_pb2.FileDescriptorProto:
    """protoc adds derived json_name values to descriptor sets but not to generated code: compare without."""
    fd = descriptor_pb2.FileDescriptorProto.FromString(fd.SerializeToString())
    for message in fd.message_type:
        for f in message.field:
            f.ClearField("json_name")
    return fd


# ------------------------------------------------------------------ resolution storage (issue 28)


def test_files_written_with_float64_packed_fields_still_read(repo_root: Path):
    """tests/data/layout_v2_packed.mcap was written before issue 28 (float64 packed arrays, explicit times)."""
    from imulog.archive import TrialReader, check_file

    path = repo_root / "tests/data/layout_v2_packed.mcap"
    ref = np.load(repo_root / "tests/data/layout_v2_packed.npz")
    assert check_file(path).ok
    with TrialReader(path) as tr:
        raw = [codec.MESSAGE_CLASSES["imulog.ImuBlock"].FromString(bytes(p)) for p in tr.messages("/imu/wrist")]
        assert all(m.schema_version == 1 and len(m.t_ns) == m.count and len(m.acc) for m in raw)  # the old layout
        imu, mk, sig, an, pose = (
            tr.read(t) for t in ("/imu/wrist", "/markers/vicon", "/signals/x", "/analog/emg", "/poses/optical")
        )
    assert np.array_equal(imu.t_ns, ref["t"]) and np.array_equal(mk.t_ns, ref["t"] + 123)
    for got, want in ((imu.acc, "acc"), (imu.gyr, "gyr"), (imu.temperature, "temp"), (mk.pos, "pos")):
        assert np.array_equal(got.view(np.uint64), ref[want].view(np.uint64)), want
    assert np.array_equal(mk.valid, ref["valid"])
    assert np.array_equal(an.values, ref["an"]) and np.array_equal(sig.values, ref["sig"])
    assert np.array_equal(pose.position, ref["ppos"]) and np.array_equal(pose.orientation, ref["pq"])


def _counts_stream(rng, n=1000):
    from imulog.model import ImuStream

    t = (np.arange(n) * 10_000_000 + 7).astype(np.int64)
    raw = rng.integers(-4096, 4096, (n, 3)).astype(np.float64)
    acc = (raw / 256.0) * 9.80665  # an Axivity-style conversion: (counts / divisor) * scale
    gyr = np.round(rng.normal(size=(n, 3)) * 50, 3)  # text with 3 decimals
    temperature = rng.normal(size=n)  # neither: stays float64
    hint = {"acc": {"divisor": 256.0, "scale": 9.80665}}
    return ImuStream("w", t, acc=acc, gyr=gyr, temperature=temperature, meta={"resolution": hint})


def test_counts_and_compact_times_read_back_exactly_and_are_protobufs_own_bytes():
    rng = np.random.default_rng(11)
    s = _counts_stream(rng)
    s.acc[5, 1] = np.nan  # a gap row: its block keeps float64, the others counts
    s.t_ns[750:] += 2  # a 2-ns step inside block 7: residuals there
    schema, meta, _, payloads = codec.encode(s)
    msgs = [codec.MESSAGE_CLASSES[schema].FromString(p) for p in payloads]
    for p, m in zip(payloads, msgs, strict=True):
        assert m.SerializeToString() == p  # the bytes protobuf itself writes for these fields
    assert len(msgs[0].acc) == 3 * msgs[0].count and not msgs[0].HasField("acc_q")
    assert all(m.HasField("acc_q") and m.HasField("gyr_q") and not len(m.acc) for m in msgs[1:])
    assert list(msgs[1].acc_q.divisor) == [256.0] * 3 and list(msgs[1].gyr_q.divisor) == [1000.0] * 3
    assert all(len(m.temperature) == m.count for m in msgs)
    assert all(m.schema_version == 2 and not len(m.t_ns) for m in msgs)
    assert [len(m.t_residual_ns) > 0 for m in msgs] == [False] * 7 + [True] + [False] * 2
    back = codec.decode(schema, "/imu/w", meta, payloads)
    assert np.array_equal(back.t_ns, s.t_ns)
    assert np.array_equal(back.acc, s.acc, equal_nan=True) and np.array_equal(back.gyr, s.gyr)
    assert np.array_equal(back.temperature.view(np.uint64), s.temperature.view(np.uint64))
    old = sum(len(m.count.to_bytes(2, "little")) + 8 * m.count * 7 for m in msgs)
    assert sum(map(len, payloads)) < 0.65 * old  # int32 counts, no times: 32 of 56 bytes a sample


def test_jittered_times_are_residuals_a_gap_stays_explicit_and_a_hint_that_does_not_fit_falls_back():
    from imulog.model import ImuStream

    rng = np.random.default_rng(12)
    t = np.cumsum(rng.integers(9_000_000, 11_000_000, 300)).astype(np.int64)  # +-1 ms jitter: ms off the line
    t[250:] += 400_000_000  # a 0.4-s gap inside the third block: 134 ms or more off its line
    acc = rng.normal(size=(300, 3))
    s = ImuStream("w", t, acc=acc, meta={"resolution": {"acc": {"divisor": 256.0}}})
    schema, meta, _, payloads = codec.encode(s)
    msgs = [codec.MESSAGE_CLASSES[schema].FromString(p) for p in payloads]
    assert all(len(m.acc) == 3 * m.count for m in msgs)  # the hint does not fit: float64 values
    explicit = [len(m.t_ns) == m.count for m in msgs]
    assert explicit == [False, False, True, False]
    assert all(len(m.t_residual_ns) == m.count for m, e in zip(msgs, explicit, strict=True) if not e)
    back = codec.decode(schema, "/imu/w", meta, payloads)
    assert np.array_equal(back.t_ns, t) and np.array_equal(back.acc.view(np.uint64), acc.view(np.uint64))


def test_skdh_rule_cwa_times_are_stored_compact(tmp_path):
    """skdh's .cwa time rule steps 9.75 / 10 / 10.25 ms (up to 6 ms off a 1-s block's line): the blocks keep
    start + span + residuals, not explicit times (explicit, a converted .cwa was 1.5x the size)."""
    from imulog.archive import numbers
    from imulog.archive.block_encode import block_bounds

    t = np.cumsum(np.tile(np.r_[np.full(40, 9_750_000), np.full(80, 10_000_000), np.full(40, 10_250_000)], 10))
    tp = numbers.plan_times(t.astype(np.int64), block_bounds(t))
    assert tp.compact.all() and tp.has_resid.any()


def test_float32_precision_request_and_blocks_parsed_by_protobuf():
    from imulog.model import SignalStream

    rng = np.random.default_rng(13)
    t = (np.arange(500) * 4_000_000).astype(np.int64)
    q = rng.normal(size=(500, 4))
    s = SignalStream("/derived/x", t, list("wxyz"), ["1"] * 4, q, attrs={"precision": "float32"})
    schema, meta, _, payloads = codec.encode(s)
    msg = codec.MESSAGE_CLASSES[schema].FromString(payloads[0])
    assert len(msg.values_q.f32) == 4 * msg.count and not len(msg.values)
    # a reader that meets unpacked values (another writer) falls back to protobuf: same numbers
    slow = [codec.MESSAGE_CLASSES[schema].FromString(p).SerializeToString() for p in payloads]
    for back in (codec.decode(schema, "/derived/x", meta, payloads), codec.decode(schema, "/derived/x", meta, slow)):
        assert np.array_equal(back.values, q.astype(np.float32).astype(np.float64))
        assert np.array_equal(back.t_ns, t)


def test_varints_decode_what_protobuf_encodes():
    from imulog.archive import wire
    from imulog.archive._generated.imulog import ImuBlock_pb2

    values = np.array([0, 1, -1, 63, -64, 64, 8191, -8192, 2**40, -(2**62), 2**63 - 1, -(2**63)])
    data, lengths = wire.zigzag_varints(values)  # the time residuals (repeated sint64)
    assert ImuBlock_pb2.ImuBlock(t_residual_ns=values.tolist()).SerializeToString() == wire.len_field(12, data)
    assert lengths.sum() == len(data)
    assert np.array_equal(wire.read_zigzag_varints(data, len(values), "x"), values)
    with pytest.raises(ValueError, match="x: 13 varints"):
        wire.read_zigzag_varints(data + b"\x05", len(values), "x")
