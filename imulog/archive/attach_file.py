"""An original file attached to a trial block by block (a week's ``.cwa`` is 770 MB: never held at once)."""

from __future__ import annotations

import hashlib
import mimetypes
import struct
import zlib
from pathlib import Path

from imulog.archive import _mcap as m
from imulog.archive._builder import McapBuilder
from imulog.archive.errors import ArchiveError
from imulog.archive.packing import pack

STREAM_PACK_MAX = 64 << 20  # originals up to this size are read whole and packed; larger ones streamed as they are


def write_attachment_from_file(builder: McapBuilder, src: Path, block: int = 1 << 20) -> str:
    """An MCAP Attachment record of the file ``src``, written block by block; returns the file's SHA-256."""
    size = src.stat().st_size
    media_type = mimetypes.guess_type(src.name)[0] or "application/octet-stream"
    mtime = max(src.stat().st_mtime_ns, 0)
    if size <= STREAM_PACK_MAX:  # small enough to hold: zstd-packed when it pays (imulog.archive.packing)
        data = src.read_bytes()
        stored, stored_type = pack(data, media_type)
        builder.add_attachment(src.name, stored_type, stored, log_time=mtime, create_time=mtime)
        return hashlib.sha256(data).hexdigest()
    head = struct.pack("<QQ", mtime, mtime) + m._s(src.name) + m._s(media_type) + struct.pack("<Q", size)
    body_len = len(head) + size + 4
    offset = builder.offset
    builder.write(struct.pack("<BQ", m.Op.ATTACHMENT, body_len))
    builder.write(head)
    crc = zlib.crc32(head)
    digest = hashlib.sha256()
    done = 0
    with open(src, "rb") as f:
        while data := f.read(block):
            builder.write(data)
            crc = zlib.crc32(data, crc)
            digest.update(data)
            done += len(data)
    if done != size:
        raise ArchiveError(f"{src}: the file changed size while it was attached ({size} -> {done} bytes)")
    builder.write(struct.pack("<I", crc))
    builder.attachment_indexes.append(
        m.AttachmentIndexRec(offset, builder.offset - offset, mtime, mtime, size, src.name, media_type)
    )
    return digest.hexdigest()
