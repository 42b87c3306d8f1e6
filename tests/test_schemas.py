"""The .proto sources, the generated code and the schemas embedded in trial files agree."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

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
    import numpy as np

    from imulog.archive._generated.imulog import SignalBlock_pb2

    t = np.arange(3, dtype="<i8")
    v = np.arange(3, dtype="<f8")
    msg = SignalBlock_pb2.SignalBlock(columns=["a"], units=["1"], count=3, t_ns=t.tobytes(), values=v.tobytes())
    s = codec.decode("imulog.SignalBlock", "/derived/a", {}, [msg.SerializeToString()])
    assert s.values[:, 0].tolist() == [0.0, 1.0, 2.0]


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
