"""Regenerate the Python protobuf code in ``imulog/archive/_generated`` from ``schemas/*.proto``.

Usage::

    python -m imulog.archive.generate            # rewrite imulog/archive/_generated/
    python -m imulog.archive.generate --check    # exit 1 when the generated code is stale

Needs the ``dev`` extra (``grpcio-tools``). The generated modules register their descriptors in a
private :class:`~google.protobuf.descriptor_pool.DescriptorPool` (``_generated/_pool.py``) so that
importing imulog never clashes with another package that ships the same Foxglove ``.proto`` files.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
SCHEMA_DIR = REPO_ROOT / "schemas"
GENERATED_DIR = Path(__file__).resolve().parent / "_generated"
PACKAGES = ("foxglove", "imulog")

_POOL_MODULE = '''"""Private descriptor pool for imulog's generated protobuf modules (written by imulog.archive.generate)."""

from google.protobuf import descriptor_pool, timestamp_pb2

POOL = descriptor_pool.DescriptorPool()
POOL.AddSerializedFile(timestamp_pb2.DESCRIPTOR.serialized_pb)
'''


def proto_files(schema_dir: Path = SCHEMA_DIR) -> list[str]:
    """The ``.proto`` files, relative to ``schema_dir`` (e.g. ``imulog/ImuBlock.proto``)."""
    return sorted(p.relative_to(schema_dir).as_posix() for p in schema_dir.glob("*/*.proto"))


def _postprocess(source: str) -> str:
    """Point imports at ``imulog.archive._generated`` and descriptors at the private pool.

    The runtime-version guard protoc emits is removed: the generated code only uses the descriptor
    builder API, so it runs on any protobuf >= 4.21 rather than only on runtimes as new as protoc.
    """
    source = source.replace("from google.protobuf import runtime_version as _runtime_version\n", "")
    source = re.sub(r"_runtime_version\.ValidateProtobufRuntimeVersion\(.*?\)\n", "", source, flags=re.S)
    for package in PACKAGES:
        source = re.sub(
            rf"^from {package} import ", f"from imulog.archive._generated.{package} import ", source, flags=re.M
        )
    source = source.replace(
        "from google.protobuf.internal import builder as _builder\n",
        "from google.protobuf.internal import builder as _builder\nfrom imulog.archive._generated._pool import POOL as _POOL\n",
    )
    return source.replace("_descriptor_pool.Default().AddSerializedFile(", "_POOL.AddSerializedFile(")


def generate(out_dir: Path, schema_dir: Path = SCHEMA_DIR) -> list[Path]:
    """Run protoc on every schema and write post-processed ``*_pb2.py`` modules into ``out_dir``."""
    try:
        import grpc_tools
        from grpc_tools import protoc
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise SystemExit("grpcio-tools is needed to regenerate: pip install 'imulog[dev]'") from exc
    include = Path(grpc_tools.__file__).parent / "_proto"
    with tempfile.TemporaryDirectory() as tmp:
        args = ["protoc", f"-I{schema_dir}", f"-I{include}", f"--python_out={tmp}", *proto_files(schema_dir)]
        if protoc.main(args) != 0:
            raise SystemExit(f"protoc failed on {schema_dir}")
        written = []
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "__init__.py").write_text(
            '"""Generated protobuf code: do not edit (python -m imulog.archive.generate)."""\n'
        )
        (out_dir / "_pool.py").write_text(_POOL_MODULE)
        for package in PACKAGES:
            (out_dir / package).mkdir(exist_ok=True)
            (out_dir / package / "__init__.py").write_text("")
            for path in sorted((Path(tmp) / package).glob("*_pb2.py")):
                target = out_dir / package / path.name
                target.write_text(_postprocess(path.read_text()))
                written.append(target)
    return written


def stale_files(out_dir: Path = GENERATED_DIR) -> list[str]:
    """Generated files that differ from what the current ``.proto`` sources produce."""
    with tempfile.TemporaryDirectory() as tmp:
        fresh = Path(tmp)
        generate(fresh)
        names = {p.relative_to(fresh).as_posix() for p in fresh.rglob("*.py")}
        names |= {p.relative_to(out_dir).as_posix() for p in out_dir.rglob("*.py")}
        return sorted(
            n
            for n in names
            if not (fresh / n).is_file()
            or not (out_dir / n).is_file()
            or _normalised(fresh / n) != _normalised(out_dir / n)
        )


def _normalised(path: Path) -> str:
    """File text without the protoc version line (a different grpcio-tools release is not staleness)."""
    return re.sub(r"^# Protobuf Python Version:.*$", "", path.read_text(), flags=re.M)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only report stale generated files (exit 1)")
    args = parser.parse_args(argv)
    if args.check:
        stale = stale_files()
        for name in stale:
            print(f"stale: imulog/archive/_generated/{name}")
        return 1 if stale else 0
    for path in generate(GENERATED_DIR):
        print(f"wrote {path.relative_to(REPO_ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
