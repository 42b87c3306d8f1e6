"""The C3D byte layout, independent of any reader: processor types, float formats, the parameter section.

A C3D file (c3d.org, "The C3D File Format User Guide") is 512-byte blocks: a header block, the parameter section
(block ``header[0]``; its 4-byte head holds the processor type in byte 4: 84 Intel, 85 DEC, 86 MIPS/SGI), then the
data from block ``header word 9``. The processor type fixes the byte order of every 16-bit integer (MIPS:
big-endian) and the float format (Intel and MIPS: IEEE-754, DEC: VAX-F, stored as two little-endian 16-bit words
with the sign/exponent word first and a bias that makes it 4 x the IEEE value of the same bits).

:func:`to_intel` rewrites a DEC or MIPS file as the Intel file with the same content (header words and floats,
every parameter's integers and floats, and the data: int16 or float32 as the header's scale sign says), so a
reader that supports only Intel files (ezc3d 1.x refuses MIPS) reads any of them; :func:`from_intel` is its
inverse (tests build DEC and MIPS variants with it). :func:`parameters` reads the parameter section.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import BinaryIO

import numpy as np

INTEL, DEC, MIPS = 84, 85, 86
PROCESSORS = {INTEL: "Intel", DEC: "DEC (VAX)", MIPS: "MIPS (SGI, big-endian)"}
HEADER_FLOAT_BYTES = ((12, 16), (20, 24), (304, 376))  # scale, frame rate, 18 event times
HEADER_BYTE_RANGES = ((0, 2), (376, 394), (396, 468))  # block/key bytes, event flags, event labels: no swap


class C3dLayoutError(ValueError):
    """The file's structure is broken (the message says where)."""


def vax_to_ieee(raw: np.ndarray) -> np.ndarray:
    """(N, 4) uint8 VAX-F floats as stored -> float32 values."""
    b = np.ascontiguousarray(raw.reshape(-1, 4)[:, [2, 3, 0, 1]])
    v = b.view("<f4").reshape(-1) / np.float32(4.0)
    return v.astype(np.float32)


def ieee_to_vax(values: np.ndarray) -> np.ndarray:
    """float32 values -> (N, 4) uint8 VAX-F as stored (for values within VAX range)."""
    b = (np.asarray(values, dtype="<f4").reshape(-1) * np.float32(4.0)).astype("<f4").view(np.uint8).reshape(-1, 4)
    return np.ascontiguousarray(b[:, [2, 3, 0, 1]])


def processor_type(data: bytes) -> int:
    """The processor type byte of the parameter section; C3dLayoutError when the file is too short."""
    if len(data) < 512 or data[1] != 0x50:
        raise C3dLayoutError("not a C3D file (byte 2 of the header is not 0x50)")
    start = (max(data[0], 1) - 1) * 512
    if len(data) < start + 4:
        raise C3dLayoutError(f"file ends before the parameter section (block {data[0]})")
    return data[start + 3]


def _floats_in(proc: int) -> Callable[[np.ndarray], np.ndarray]:
    """Stored 4-byte floats of ``proc`` -> float32."""
    if proc == DEC:
        return vax_to_ieee
    dt = ">f4" if proc == MIPS else "<f4"
    return lambda raw: np.ascontiguousarray(raw).view(dt).reshape(-1).astype(np.float32)


def _floats_out(proc: int) -> Callable[[np.ndarray], np.ndarray]:
    """float32 -> stored 4-byte floats of ``proc``."""
    if proc == DEC:
        return ieee_to_vax
    dt = ">f4" if proc == MIPS else "<f4"
    return lambda v: np.asarray(v, dtype=dt).view(np.uint8).reshape(-1, 4)


def _i16(proc: int) -> str:
    return ">i2" if proc == MIPS else "<i2"


def _convert(data: bytes, src: int, dst: int) -> bytes:
    """The file rewritten from processor ``src`` to ``dst`` (header, parameters, data)."""
    out = bytearray(data)
    buf = np.frombuffer(data, dtype=np.uint8)
    fin, fout = _floats_in(src), _floats_out(dst)
    si, di = _i16(src), _i16(dst)

    def ints(lo: int, hi: int) -> None:
        n = (hi - lo) // 2
        out[lo : lo + 2 * n] = np.frombuffer(data, dtype=si, count=n, offset=lo).astype(di).tobytes()

    def floats(lo: int, hi: int) -> None:
        n = (hi - lo) // 4
        out[lo : lo + 4 * n] = fout(fin(buf[lo : lo + 4 * n].reshape(-1, 4))).tobytes()

    # header: 16-bit words, with floats and byte fields where the format puts them
    marks = sorted([(a, b, "f") for a, b in HEADER_FLOAT_BYTES] + [(a, b, "b") for a, b in HEADER_BYTE_RANGES])
    pos = 0
    for a, b, kind in marks:
        if pos < a:
            ints(pos, a)
        if kind == "f":
            floats(a, b)
        pos = b
    ints(pos, 512)
    scale = float(fin(buf[12:16].reshape(1, 4))[0])
    # parameters
    p = (data[0] - 1) * 512
    out[p + 3] = dst
    pos = p + 4
    end = p + 512 * max(data[p + 2], 1)
    while pos + 2 <= min(end, len(data)):
        nchar = struct.unpack_from("b", data, pos)[0]
        gid = struct.unpack_from("b", data, pos + 1)[0]
        if nchar == 0:
            break
        name_end = pos + 2 + abs(nchar)
        if name_end + 2 > len(data):
            raise C3dLayoutError(f"parameter section ends inside a record at byte {pos}")
        (nxt,) = struct.unpack_from(si[0] + "h", data, name_end)
        ints(name_end, name_end + 2)
        body = name_end + 2
        if gid > 0:  # a parameter: type, dims, data
            if body + 2 > len(data):
                raise C3dLayoutError(f"parameter section ends inside a record at byte {pos}")
            ptype = struct.unpack_from("b", data, body)[0]
            ndim = data[body + 1]
            dims = list(data[body + 2 : body + 2 + ndim])
            start = body + 2 + ndim
            count = int(np.prod(dims)) if ndim else 1
            size = count * abs(ptype)
            if start + size > len(data):
                raise C3dLayoutError(f"parameter at byte {pos} runs past the end of the file")
            if ptype == 2:
                ints(start, start + size)
            elif ptype == 4:
                floats(start, start + size)
            elif ptype not in (1, -1):
                raise C3dLayoutError(f"parameter at byte {pos}: unknown data type {ptype}")
        if nxt <= 0:
            break
        pos = name_end + nxt
    # data
    d = (struct.unpack_from(si[0] + "H", data, 16)[0] - 1) * 512
    if 0 < d < len(data):
        (floats if scale < 0 else ints)(d, len(data))
    return bytes(out)


def to_intel(data: bytes) -> bytes:
    """``data`` (any processor type) as an Intel C3D; unchanged when it is one."""
    proc = processor_type(data)
    if proc == INTEL:
        return data
    if proc not in PROCESSORS:
        raise C3dLayoutError(f"unknown processor type {proc} (84 Intel, 85 DEC, 86 MIPS)")
    return _convert(data, proc, INTEL)


def from_intel(data: bytes, proc: int) -> bytes:
    """An Intel C3D rewritten for processor ``proc`` (DEC or MIPS)."""
    if processor_type(data) != INTEL:
        raise C3dLayoutError("not an Intel C3D")
    return _convert(data, INTEL, proc)


def parameters(data: bytes) -> dict[str, list | str]:
    """``GROUP:NAME`` -> values of an Intel C3D's parameters (numbers as a flat list, characters as a string)."""
    if processor_type(data) != INTEL:
        data = to_intel(data)
    p = (data[0] - 1) * 512
    pos, groups, raw = p + 4, {}, []
    while pos + 2 <= len(data):
        nchar, gid = struct.unpack_from("bb", data, pos)
        if nchar == 0:
            break
        name = data[pos + 2 : pos + 2 + abs(nchar)].decode("latin-1").strip().upper()
        (nxt,) = struct.unpack_from("<h", data, pos + 2 + abs(nchar))
        body = pos + 4 + abs(nchar)
        if gid < 0:
            groups[-gid] = name
        elif body + 2 <= len(data):
            ptype, ndim = struct.unpack_from("bB", data, body)
            dims = list(data[body + 2 : body + 2 + ndim])
            start = body + 2 + ndim
            count = int(np.prod(dims)) if ndim else 1
            chunk = data[start : start + count * abs(ptype)]
            if len(chunk) < count * abs(ptype):
                raise C3dLayoutError(f"parameter {name} at byte {pos} runs past the end of the file")
            if ptype == -1:
                value: list | str = chunk.decode("latin-1")
            elif ptype in (1, 2, 4):
                value = np.frombuffer(chunk, dtype={1: "u1", 2: "<i2", 4: "<f4"}[ptype]).tolist()
            else:
                value = []
            raw.append((gid, name, value))
        if nxt <= 0:
            break
        pos = pos + 2 + abs(nchar) + nxt
    return {f"{groups.get(g, str(g))}:{n}": v for g, n, v in raw}


def header_frames(data: bytes) -> tuple[int, int]:
    """(first frame, last frame) of an Intel header (16-bit words 4 and 5)."""
    return struct.unpack_from("<HH", data, 6)


def read_prefix(f: BinaryIO) -> bytes:
    """The header and parameter section of an open C3D file (everything before the data, as stored): the first
    512-byte block, then up to the data start (header word 9) or the parameter section's declared end, whichever is
    later, or the end of the file; the data is not read. C3dLayoutError when it is not a C3D file."""
    f.seek(0)
    head = f.read(512)
    if len(head) < 512 or head[1] != 0x50:
        raise C3dLayoutError("not a C3D file (byte 2 of the header is not 0x50)")
    p = (max(head[0], 1) - 1) * 512
    f.seek(p)
    phead = f.read(4)
    if len(phead) < 4:
        raise C3dLayoutError(f"file ends before the parameter section (block {head[0]})")
    (data_block,) = struct.unpack_from(">H" if phead[3] == MIPS else "<H", head, 16)
    end = max(p + 512 * max(phead[2], 1), (data_block - 1) * 512)
    f.seek(0)
    return f.read(end)


def data_words(raw: bytes, proc: int, is_float: bool) -> np.ndarray:
    """Data words stored by processor ``proc`` (a whole number of words from the data section) as float32 (a float
    file, POINT:SCALE < 0) or int16 values in the machine's byte order: what :func:`to_intel` makes of them."""
    if is_float:
        return _floats_in(proc)(np.frombuffer(raw, dtype=np.uint8).reshape(-1, 4))
    return np.frombuffer(raw, dtype=_i16(proc)).astype(np.int16)
