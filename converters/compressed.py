"""Any format read through ``.gz``, ``.bz2``, ``.xz`` or a single-file ``.zip`` (e.g. ``shimmer.csv.gz``).

The compressed file is recognised by its magic bytes (gzip ``1f 8b``, bzip2 ``BZh``, xz ``fd 37 7a 58 5a 00``,
zip ``PK\\x03\\x04``), decompressed piece by piece into a private temporary folder under the inner file's name (the
file name without the compression suffix, or the zip member's name), and converted by the converter that
recognises the inner file's content. The compressed file is the recording's source (its bytes are what the
archive attaches and hashes); a mapping file beside it (``trial.mapping.json`` for ``trial.csv.gz``) applies.

Bounded decompression: at most :data:`MAX_BYTES` out, and at most :data:`MAX_RATIO` times the compressed size once
past :data:`RATIO_FLOOR` bytes (a "zip bomb" is refused in bounded time and disk, naming the limit). A zip with
several files, a nested compressed file or an encrypted zip member is refused with what to do instead.
"""

from __future__ import annotations

import bz2
import gzip
import lzma
import shutil
import tempfile
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from imulog.converters import bounds
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError
from imulog.converters.mapping import sibling_mapping

from imulog.model import Recording

MAGIC = {"gzip": b"\x1f\x8b", "bzip2": b"BZh", "xz": b"\xfd7zXZ\x00", "zip": b"PK\x03\x04"}
SUFFIX = {"gzip": (".gz", ".gzip"), "bzip2": (".bz2",), "xz": (".xz",), "zip": (".zip",)}
MAX_BYTES = 16 << 30  # 16 GiB of decompressed text at most
# decompressed / compressed size, checked once past RATIO_FLOOR: the limits every container member has
# (converters/bounds.py), so an input of N bytes is converted in time and memory that grow with N
MAX_RATIO = bounds.MAX_RATIO
RATIO_FLOOR = bounds.RATIO_FLOOR
PIECE = 1 << 20


def kind_of(head: bytes) -> str | None:
    """The compression of a file from its first bytes (None when it is not compressed)."""
    return next((k for k, m in MAGIC.items() if head.startswith(m)), None)


def inner_name(path: Path, kind: str) -> str:
    """``trial.csv.gz`` -> ``trial.csv``; a name without the usual suffix keeps its stem."""
    name = Path(path).name
    for suffix in SUFFIX[kind]:
        if name.lower().endswith(suffix):
            return name[: -len(suffix)] or "data"
    return Path(name).stem or "data"


def _open(path: Path, kind: str) -> tuple[IO[bytes], str, int]:
    """(readable stream of the inner file, its name, compressed size)."""
    size = Path(path).stat().st_size
    if kind == "gzip":
        return gzip.open(path, "rb"), inner_name(path, kind), size
    if kind == "bzip2":
        return bz2.open(path, "rb"), inner_name(path, kind), size
    if kind == "xz":
        return lzma.open(path, "rb"), inner_name(path, kind), size
    try:
        zf = zipfile.ZipFile(path)
    except zipfile.BadZipFile as e:
        raise ConversionError(path, f"damaged zip file: {e}") from None
    members = [m for m in zf.infolist() if not m.is_dir() and not Path(m.filename).name.startswith((".", "__MACOSX"))]
    members = [m for m in members if "__MACOSX" not in m.filename]
    if len(members) != 1:
        names = ", ".join(Path(m.filename).name for m in members[:4])
        raise ConversionError(
            path,
            f"zip with {len(members)} files ({names}{', ...' if len(members) > 4 else ''}): only a single-file zip is "
            "read; unpack it and convert the folder",
        )
    member = members[0]
    if member.flag_bits & 0x1:
        raise ConversionError(path, f"zip member {member.filename!r} is encrypted: unpack it with its password")
    return zf.open(member), Path(member.filename).name, member.compress_size or size


def _copy_bounded(src: IO[bytes], dst: IO[bytes], path: Path, compressed: int) -> int:
    total = 0
    limit_ratio = max(RATIO_FLOOR, MAX_RATIO * compressed)
    while True:
        try:
            block = src.read(PIECE)
        except (OSError, EOFError, zlib.error, lzma.LZMAError, zipfile.BadZipFile) as e:
            raise ConversionError(path, f"damaged compressed data after {total} bytes: {e}") from None
        if not block:
            return total
        total += len(block)
        if total > MAX_BYTES:
            raise ConversionError(path, f"decompresses to more than {MAX_BYTES >> 30} GiB: refused")
        if total > limit_ratio:
            raise ConversionError(
                path,
                f"decompresses to more than {MAX_RATIO} times its size (more than {total} bytes from {compressed}): "
                "refused as a likely decompression bomb; decompress it yourself if it is genuine",
            )
        dst.write(block)


@contextmanager
def decompressed(path: Path) -> Iterator[Path]:
    """The inner file of a compressed ``path``, decompressed into a temporary folder removed afterwards."""
    path = Path(path)
    with open(path, "rb") as f:
        kind = kind_of(f.read(8))
    if kind is None:
        raise ConversionError(path, "not a gzip, bzip2, xz or zip file")
    tmp = Path(tempfile.mkdtemp(prefix="imulog-unpack-"))
    try:
        src, name, compressed = _open(path, kind)
        target = tmp / Path(name).name
        with src, open(target, "wb") as dst:
            n = _copy_bounded(src, dst, path, compressed)
        if n == 0:
            raise ConversionError(path, f"{kind} file holds an empty {name!r}")
        with open(target, "rb") as f:
            if kind_of(f.read(8)) is not None:
                raise ConversionError(path, f"{name!r} inside is itself compressed: decompress it once yourself")
        yield target
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def convert_compressed(path: Path, options: ConvertOptions | None = None) -> Recording:
    """Convert the inner file of ``path`` with the converter its content names; sources = the compressed file."""
    (rec,) = iter_compressed(path, options, whole=True)
    return rec


def iter_compressed(path: Path, options: ConvertOptions | None = None, *, whole: bool = False) -> Iterator[Recording]:
    """The inner file's recording in the pieces of its own converter (``Converter.iter_chunks``; one piece when
    it reads whole, or with ``whole``). The inner file is decompressed to disk (bounded: :data:`MAX_BYTES`), so
    memory is what the inner reader holds for one piece."""
    from dataclasses import replace

    from imulog.converters.registry import detect, get

    options = options or ConvertOptions()
    path = Path(path)
    with decompressed(path) as inner:
        if options.mapping is None:
            beside = sibling_mapping(path.with_name(inner.name))
            if beside is not None:
                options = replace(options, mapping=beside)
        try:
            conv = detect(inner)
        except ConversionError as e:
            if options.mapping is None:
                raise ConversionError(path, f"inside: {e.problem}") from None
            conv = get("delimited")  # a mapping names the columns detection could not recognise
        try:
            pieces = conv.iter_chunks(inner, options) if not whole else None
            for rec in pieces if pieces is not None else iter([conv.convert(inner, options)]):
                yield _as_container(rec, path, inner, conv.name)
        except ConversionError as e:
            where = ", ".join(
                x for x in (f"line {e.line}" if e.line else "", f"column {e.column!r}" if e.column else "") if x
            )
            raise ConversionError(
                path, f"{inner.name} ({conv.name}): {where + ': ' if where else ''}{e.problem}"
            ) from None


def _as_container(rec: Recording, path: Path, inner: Path, inner_format: str) -> Recording:
    """``rec`` as read from the compressed file ``path``: its sources, warnings and device records name it."""
    rec.sources = [str(path) if s == str(inner) else s for s in rec.sources]
    rec.warnings = [w.replace(str(inner), path.name) for w in rec.warnings]
    for key, meta in rec.metadata.items():
        if key.startswith("imulog.device.") and isinstance(meta, dict):
            meta["compression"] = {"container": path.name, "inner": inner.name, "inner_format": inner_format}
    return rec


class CompressedConverter(Converter):
    name = "compressed"
    description = "any format inside .gz, .bz2, .xz or a single-file .zip (decompressed with size and ratio limits)"
    extensions = (".gz", ".bz2", ".xz", ".zip")
    example = "imulog convert trial.csv.gz -o trial.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        kind = kind_of(head)
        if kind is None:
            return 0.0
        if kind == "zip" and Path(path).suffix.lower() != ".zip":
            return 0.0  # .xlsx, .docx, .npz, .jar are zips of their own formats
        return 0.9

    def recording_key(self, path: Path) -> str | None:
        return None

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return convert_compressed(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """The inner converter's pieces (see :func:`iter_compressed`)."""
        return iter_compressed(Path(path), options)


CONVERTER = CompressedConverter()
