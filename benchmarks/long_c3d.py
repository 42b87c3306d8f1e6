"""Write a long C3D (more than the 65535 frames a 16-bit count holds) frame block by frame block, in bounded memory.

The layout of the C3D guide (c3d.org): a header block, one parameter section (groups POINT, ANALOG, TRIAL), then
frames of ``4 x markers`` point words and ``ratio x channels`` analog words, float32 (``POINT:SCALE`` -1) or int16
(``integer``: ``POINT:SCALE`` > 0, analog words with ``ANALOG:OFFSET`` and ``SCALE``). The frame count goes where long
trials keep it: ``TRIAL:ACTUAL_START_FIELD`` / ``ACTUAL_END_FIELD`` (two 16-bit words, low first) and
``POINT:LONG_FRAMES`` (float), the header's and ``POINT:FRAMES``' 16-bit counts held at 65535. ezc3d 1.7 cannot
write such a file (it wraps at 65535 frames). A 4-marker cluster moves on a slow circle with a hidden stretch (residual
-1) every minute; one analog channel (EMG-like noise on a 3 Hz sine, V). Used by ``bench_convert_pieces.py --formats
c3d`` and ``tests/test_convert_c3d_pieces.py``.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

POINT_SCALE_MM = 0.1  # mm per count of the integer variant
ANALOG_SCALE_V = 1e-4  # V per count of the integer variant
ANALOG_OFFSET = 5  # counts


def _param(gid: int, name: str, ptype: int, dims: list[int], data: bytes, last: bool = False) -> bytes:
    body = struct.pack("<bB", ptype, len(dims)) + bytes(dims) + data + b"\x00"  # no description
    nxt = 0 if last else 2 + len(body)
    return struct.pack("<bb", len(name), gid) + name.encode() + struct.pack("<h", nxt) + body


def _group(gid: int, name: str) -> bytes:
    return struct.pack("<bb", len(name), -gid) + name.encode() + struct.pack("<h", 3) + b"\x00"


def _chars(gid: int, name: str, values: list[str]) -> bytes:
    width = max(len(v) for v in values)
    return _param(gid, name, -1, [width, len(values)], "".join(v.ljust(width) for v in values).encode())


def _i16(gid: int, name: str, values: list[int], last: bool = False) -> bytes:
    return _param(gid, name, 2, [len(values)], np.asarray(values, "<i2").tobytes(), last)


def _f32(gid: int, name: str, values: list[float], array: bool = False) -> bytes:
    return _param(gid, name, 4, [len(values)] if array else [], np.asarray(values, "<f4").tobytes())


def frames_at(lo: int, hi: int, *, markers: int, ratio: int, rate_hz: float, seed: int = 0) -> tuple[np.ndarray, ...]:
    """Frames ``[lo, hi)``: positions (n, markers, 3) mm, residuals (n, markers) (-1: hidden) and the analog channel
    (n x ratio,) V; the same values whichever blocks they are asked in."""
    t = np.arange(lo, hi) / rate_hz
    centre = np.column_stack([300 * np.cos(0.2 * t), 300 * np.sin(0.2 * t), 1000 + 50 * np.sin(1.1 * t)])
    offsets = np.array([[40, 0, 0], [0, 40, 0], [-40, 0, 0], [0, -40, 10]])[:markers]
    pos = np.round((centre[:, None, :] + offsets[None]) / POINT_SCALE_MM) * POINT_SCALE_MM
    res = np.ones((hi - lo, markers))
    res[(np.arange(lo, hi) % int(60 * rate_hz) < int(0.5 * rate_hz)), :1] = -1.0  # marker 0 hidden 0.5 s a minute
    ta = np.arange(lo * ratio, hi * ratio) / (rate_hz * ratio)
    rng = np.random.default_rng(seed + lo)
    emg = 0.01 * np.sin(2 * np.pi * 3 * ta) + rng.normal(0, 0.002, len(ta))
    emg = np.round(emg / ANALOG_SCALE_V) * ANALOG_SCALE_V
    return pos, res, emg


def write_long_c3d(
    path: Path,
    frames: int,
    *,
    rate_hz: float = 100.0,
    markers: int = 4,
    ratio: int = 10,
    integer: bool = False,
    block_frames: int = 100_000,
    seed: int = 0,
) -> None:
    """A C3D of ``frames`` frames at ``rate_hz`` (analog at ``ratio`` x the rate), written ``block_frames`` at a time."""
    scale = POINT_SCALE_MM if integer else -1.0
    labels = [f"cluster:m{i + 1}" for i in range(markers)]
    short = min(frames, 65535)

    def section(data_block: int) -> bytes:
        return b"".join(
            [
                _group(1, "POINT"),
                _i16(1, "USED", [markers]),
                _i16(1, "FRAMES", [short - 65536 if short > 32767 else short]),
                _f32(1, "LONG_FRAMES", [float(frames)]),
                _f32(1, "SCALE", [scale]),
                _f32(1, "RATE", [rate_hz]),
                _i16(1, "DATA_START", [data_block]),
                _chars(1, "UNITS", ["mm"]),
                _chars(1, "LABELS", labels),
                _group(2, "ANALOG"),
                _i16(2, "USED", [1]),
                _f32(2, "RATE", [rate_hz * ratio]),
                _chars(2, "LABELS", ["EMG1"]),
                _chars(2, "UNITS", ["V"]),
                _f32(2, "SCALE", [ANALOG_SCALE_V if integer else 1.0], array=True),
                _f32(2, "GEN_SCALE", [1.0]),
                _i16(2, "OFFSET", [ANALOG_OFFSET if integer else 0]),
                _group(3, "TRIAL"),
                _i16(3, "ACTUAL_START_FIELD", [1, 0]),
                _i16(3, "ACTUAL_END_FIELD", [int(np.uint16(frames & 0xFFFF).view(np.int16)), frames >> 16], last=True),
            ]
        )

    blocks = (4 + len(section(0)) + 511) // 512
    data_block = 2 + blocks
    params = (bytes([1, 0x50, blocks, 84]) + section(data_block)).ljust(blocks * 512, b"\x00")
    header = bytearray(512)
    header[0], header[1] = 2, 0x50
    struct.pack_into("<5H", header, 2, markers, ratio, 1, short, 10)
    struct.pack_into("<fHHf", header, 12, scale, data_block, ratio, rate_hz)
    with open(path, "wb") as f:
        f.write(bytes(header) + params)
        for lo in range(0, frames, block_frames):
            hi = min(lo + block_frames, frames)
            pos, res, emg = frames_at(lo, hi, markers=markers, ratio=ratio, rate_hz=rate_hz, seed=seed)
            n = hi - lo
            if integer:
                pts = np.concatenate([np.round(pos / POINT_SCALE_MM), np.where(res < 0, -1, 0x0101)[:, :, None]], 2)
                an = np.round(emg / ANALOG_SCALE_V) + ANALOG_OFFSET
                words = np.concatenate([pts.reshape(n, -1), an.reshape(n, ratio)], axis=1).astype("<i2")
            else:
                pts = np.concatenate([pos, res[:, :, None]], axis=2)
                words = np.concatenate([pts.reshape(n, -1), emg.reshape(n, ratio)], axis=1).astype("<f4")
            f.write(words.tobytes())
