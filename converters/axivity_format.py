"""The ``.cwa`` format's fixed parts, pure: the header, the block layout, checksums, sensor ranges, sample unpacking
(block times live in :mod:`imulog.converters.axivity_time`; the reader in :mod:`imulog.converters.axivity`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from imulog.converters.axivity_time import rate_from_code
from imulog.converters.errors import ConversionError

HEADER_BYTES = 1024
BLOCK_BYTES = 512
BLOCKS_PER_CHUNK = 8192  # 4 MiB of blocks per decoded batch
BLOCK_DTYPE = np.dtype(
    [
        ("magic", "<u2"),
        ("length", "<u2"),
        ("fractional", "<u2"),
        ("session", "<u4"),
        ("sequence", "<u4"),
        ("rtc", "<u4"),
        ("light", "<u2"),
        ("temperature", "<u2"),
        ("events", "u1"),
        ("battery", "u1"),
        ("rate_code", "u1"),
        ("axes_bps", "u1"),
        ("offset", "<i2"),
        ("count", "<u2"),
        ("data", "u1", (480,)),
        ("checksum", "<u2"),
    ]
)
assert BLOCK_DTYPE.itemsize == BLOCK_BYTES
MAGIC_AX = 0x5841  # b"AX"
OTHER_BLOCKS = {0x444D, 0x4255, 0x4953}  # "MD" (repeated metadata), "UB" (usage), "SI" (session info): skipped
HARDWARE = {0x00: "AX3", 0xFF: "AX3", 0x17: "AX3", 0x64: "AX6"}


@dataclass(frozen=True)
class CwaHeader:
    """The ``MD`` header's fields (rate in Hz, accelerometer range in g)."""

    hardware_type: int
    device_id: int
    session_id: int
    sensor_config: int
    rate_code: int
    firmware: int
    annotation: str

    @property
    def rate_hz(self) -> float:
        return rate_from_code(self.rate_code)

    @property
    def accel_range_g(self) -> int:
        return 16 >> (self.rate_code >> 6)

    @property
    def model(self) -> str:
        return HARDWARE.get(self.hardware_type, f"Axivity (hardware 0x{self.hardware_type:02X})")


def parse_header(path: Path, data: bytes) -> CwaHeader:
    """The 1024-byte ``MD`` header; ConversionError when it is not one."""
    if len(data) < HEADER_BYTES or data[:2] != b"MD":
        raise ConversionError(path, "not an Axivity .cwa file (no 'MD' header block)")
    h = np.frombuffer(data, dtype=np.uint8, count=HEADER_BYTES)
    device = int(h[5]) | int(h[6]) << 8
    upper = int(h[11]) | int(h[12]) << 8
    if upper != 0xFFFF:
        device |= upper << 16
    annotation = bytes(h[64:512]).rstrip(b"\xff\x00 ").decode("latin-1").strip()
    return CwaHeader(
        hardware_type=int(h[4]),
        device_id=device,
        session_id=int.from_bytes(bytes(h[7:11]), "little"),
        sensor_config=int(h[35]),
        rate_code=int(h[36]),
        firmware=int(h[41]),
        annotation=annotation,
    )


def block_word_sums(raw: np.ndarray) -> np.ndarray:
    """16-bit sum of the 256 little-endian words of each 512-byte block (0 for an intact block)."""
    words = raw.view("<u2").reshape(len(raw), BLOCK_BYTES // 2)
    return (words.sum(axis=1, dtype=np.uint64) & 0xFFFF).astype(np.uint16)


def gyro_range_dps(light: np.ndarray) -> np.ndarray:
    """Gyroscope range (deg/s, 32768 LSB) from the block's ``light`` word: 8000 / 2^m, 2000 when m = 0 (older
    firmware leaves the bits clear)."""
    m = (np.asarray(light, dtype=np.int64) >> 10) & 7
    return np.where(m == 0, 2000.0, 8000.0 / np.left_shift(1, m))


def temperature_degc(raw: np.ndarray) -> np.ndarray:
    """Block temperature in degC from its 10-bit raw value (OpenMovement: raw * 75 / 256 - 50, an MCP9700 on a
    3 V 10-bit ADC)."""
    return (np.asarray(raw, dtype=np.int64) & 0x3FF) * (75.0 / 256.0) - 50.0


def unpack_packed(data: np.ndarray, count: int) -> np.ndarray:
    """AX3 packed samples (N, 480) bytes -> (N, count, 3) int32 counts (1 g = 256)."""
    v = np.ascontiguousarray(data[:, : 4 * count]).view("<u4").astype(np.int64)
    e = v >> 30
    out = np.empty((*v.shape, 3), dtype=np.int32)
    for k in range(3):
        x = (v >> (10 * k)) & 0x3FF
        x = np.where(x >= 512, x - 1024, x)
        out[..., k] = x << e
    return out


def unpack_int16(data: np.ndarray, count: int, axes: int) -> np.ndarray:
    """Unpacked samples (N, 480) bytes -> (N, count, axes) int16."""
    return np.ascontiguousarray(data[:, : 2 * axes * count]).view("<i2").reshape(len(data), count, axes)
