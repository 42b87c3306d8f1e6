"""ActiGraph .gt3x building blocks: record types, info.txt and parameters, sensor schemas, 12-bit samples, gap fills."""

from __future__ import annotations

import re
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._binary import NS_PER_S, with_fills
from imulog.converters.errors import ConversionError

TICKS_PER_S = 10_000_000


TICKS_AT_1970 = 621_355_968_000_000_000  # .NET ticks of 1970-01-01T00:00:00


BATCH_BYTES = 8 << 20


SEPARATOR = 0x1E


ACTIVITY, BATTERY, LUX, METADATA, CAPSENSE, PARAMETERS = 0x00, 0x02, 0x05, 0x06, 0x0D, 0x15


SENSOR_SCHEMA, SENSOR_DATA, ACTIVITY2, ACTIVITY3 = 0x18, 0x19, 0x1A, 0x1B


NEO_SCALE = 341.0  # LSB/g of NEO, CLE and MRA devices


PARAMETER_NAMES = {
    (0, 6): "battery_state",
    (0, 7): "battery_voltage",
    (0, 8): "board_revision",
    (0, 9): "calibration_time",
    (0, 13): "firmware_version",
    (0, 49): "imu_accel_scale",
    (0, 50): "imu_gyro_scale",
    (0, 51): "imu_mag_scale",
    (0, 55): "accel_scale",
    (0, 57): "imu_temp_scale",
    (0, 58): "imu_temp_offset",
    (1, 10): "sample_rate",
    (1, 12): "target_start_time",
    (1, 13): "target_stop_time",
    (1, 40): "utc_offset",
    (1, 44): "sensor_configuration",
}


FLOAT_PARAMETERS = {"battery_voltage", "imu_accel_scale", "imu_gyro_scale", "imu_mag_scale", "accel_scale"}


FLOAT_PARAMETERS |= {"imu_temp_scale", "imu_temp_offset"}


SIGNED_PARAMETERS = {"utc_offset"}


# ----------------------------------------------------------------------------------------------- pure decoders
def ssp_decode(value: int) -> float:
    """ActiGraph's SSP float: 24-bit two's-complement fraction (/2^23) times 2^(signed 8-bit exponent)."""
    if value == 0x007FFFFF:
        return float("inf")
    if value == 0x00800000:
        return float("-inf")
    exponent = (value >> 24) & 0xFF
    exponent = exponent - 256 if exponent & 0x80 else exponent
    significand = value & 0x00FFFFFF
    significand = significand - (1 << 24) if significand & 0x00800000 else significand
    return significand / 8388608.0 * 2.0**exponent


def unpack_12bit_yxz(data: bytes | np.ndarray, stored_order: str = "yxz") -> np.ndarray:
    """NEO ``activity.bin`` / ACTIVITY bytes -> (N, 3) int16 counts in X, Y, Z order (stored Y, X, Z, 12 bits each;
    ``stored_order="xyz"`` for ACTIVITY3 records, stored X, Y, Z).

    Two samples take 9 bytes; an odd last sample uses 5 bytes (its last nibble is unused).
    """
    b = np.frombuffer(bytes(data), dtype=np.uint8) if not isinstance(data, np.ndarray) else data.astype(np.uint8)
    nibbles = np.empty(2 * len(b), dtype=np.int32)
    nibbles[0::2] = b >> 4
    nibbles[1::2] = b & 0x0F
    n = len(nibbles) // 9
    v = nibbles[: 9 * n].reshape(n, 3, 3)
    values = (v[:, :, 0] << 8) | (v[:, :, 1] << 4) | v[:, :, 2]
    values = np.where(values > 2047, values - 4096, values).astype(np.int16)
    return values if stored_order == "xyz" else values[:, [1, 0, 2]]


def ticks_to_epoch_ns(ticks: int) -> int:
    """.NET ticks (100 ns since 0001-01-01, wall time) -> ns since 1970 of the same wall time."""
    return (int(ticks) - TICKS_AT_1970) * 100


def parse_info(path: Path, text: str) -> dict[str, str]:
    """``info.txt`` ``Key: Value`` lines (keys as written)."""
    out: dict[str, str] = {}
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip():
            out[key.strip()] = value.strip()
    if "Serial Number" not in out:
        raise ConversionError(path, "info.txt has no 'Serial Number' line: not an ActiGraph .gt3x")
    return out


def parse_offset_s(text: str | None) -> int | None:
    """``-05:00:00`` -> -18000 s; None when absent or unreadable."""
    if not text:
        return None
    m = re.fullmatch(r"([+-])?(\d{1,2}):(\d{2})(?::(\d{2}))?", text.strip())
    if not m:
        return None
    s = int(m.group(2)) * 3600 + int(m.group(3)) * 60 + int(m.group(4) or 0)
    return -s if m.group(1) == "-" else s


def parse_parameters(payload: bytes) -> dict[str, Any]:
    """PARAMETERS payload (8-byte address/id/value triples) -> the known parameters by name."""
    out: dict[str, Any] = {}
    for k in range(0, len(payload) - 7, 8):
        space, ident, value = struct.unpack_from("<HHI", payload, k)
        name = PARAMETER_NAMES.get((space, ident))
        if name is None:
            continue
        if name in FLOAT_PARAMETERS:
            out[name] = round(ssp_decode(value), 6)
        elif name in SIGNED_PARAMETERS:
            out[name] = value - (1 << 32) if value & 0x80000000 else value
        else:
            out[name] = value
    return out


@dataclass(frozen=True)
class SensorColumn:
    label: str
    big_endian: bool
    signed: bool
    bit_offset: int
    bits: int
    scale: float


@dataclass(frozen=True)
class SensorSchema:
    ident: int
    columns: tuple[SensorColumn, ...]

    @property
    def bytes_per_sample(self) -> int:
        return max(c.bit_offset + c.bits for c in self.columns) // 8


def parse_schema(path: Path, payload: bytes, index: int) -> SensorSchema:
    """SENSOR_SCHEMA payload: id, column count, then 23 bytes per column (flags, bit offset, bits, SSP scale, label)."""
    if len(payload) < 6:
        raise ConversionError(path, f"record {index}: SENSOR_SCHEMA too short")
    ident, ncols, _ = struct.unpack_from("<hhh", payload, 0)
    if ncols <= 0 or len(payload) < 6 + 23 * ncols:
        raise ConversionError(path, f"record {index}: SENSOR_SCHEMA declares {ncols} columns in {len(payload)} bytes")
    cols = []
    for i in range(ncols):
        o = 6 + 23 * i
        flags, offset, bits, scale = struct.unpack_from("<BBBI", payload, o)
        if bits not in (8, 16) or offset % 8:
            raise ConversionError(path, f"record {index}: SENSOR_SCHEMA column {i} has {bits} bits at bit {offset}")
        label = payload[o + 7 : o + 23].decode("ascii", "replace").strip()
        cols.append(SensorColumn(label, bool(flags & 1), bool(flags & 2), offset, bits, round(ssp_decode(scale), 6)))
    return SensorSchema(ident, tuple(cols))


def decode_sensor_samples(schema: SensorSchema, raw: np.ndarray) -> dict[str, np.ndarray]:
    """(N, bytes_per_sample) uint8 -> {label: scaled float64 (N,)} for the labelled columns."""
    out = {}
    for c in schema.columns:
        if not c.label:
            continue
        b = raw[:, c.bit_offset // 8 : (c.bit_offset + c.bits) // 8].astype(np.int64)
        if c.bits == 16:
            v = (b[:, 0] << 8 | b[:, 1]) if c.big_endian else (b[:, 1] << 8 | b[:, 0])
            if c.signed:
                v = np.where(v >= 32768, v - 65536, v)
        else:
            v = b[:, 0]
            if c.signed:
                v = np.where(v >= 128, v - 256, v)
        out[c.label] = v / c.scale if c.scale else v.astype(np.float64)
    return out


def even_times_ns(seconds: np.ndarray, counts: np.ndarray, rate_hz: np.ndarray) -> np.ndarray:
    """Times of the samples of per-second records: record r's k-th sample at ``seconds[r] + k / rate_hz[r]``."""
    counts = np.asarray(counts, dtype=np.int64)
    total = int(counts.sum())
    first = np.repeat(np.cumsum(counts) - counts, counts)
    k = np.arange(total, dtype=np.int64) - first
    step = np.repeat(NS_PER_S / np.asarray(rate_hz, dtype=np.float64), counts)
    return np.repeat(seconds.astype(np.int64) * NS_PER_S, counts) + np.round(k * step).astype(np.int64)


MAX_INFO_BYTES = 4 << 20  # info.txt is read whole, so its size is bounded


MAX_RATE_HZ = 10_000.0  # ActiGraph devices sample at 30-100 Hz (IMU 100 Hz); a larger Sample Rate is damage


MAX_RECORDING_S = 366 * 86400  # a Last Sample Time further from Start Date is not used


MAX_GAP_S = 31 * 86400  # a longer silence is a clock or file problem, not idle sleep: refused


INLINE_FILL = 1 << 16  # NaN samples a gap may add to its own piece; longer gaps become pieces of their own


FILL_PIECE = 1 << 20  # samples per NaN piece of a long gap


def fill_times_ns(first_s: int, n: int, rate: int) -> np.ndarray:
    """Times of ``n`` samples at ``rate`` Hz from the whole second ``first_s`` (k-th at ``first_s + k / rate``)."""
    k = np.arange(n, dtype=np.int64)
    return (first_s + k // rate) * NS_PER_S + np.round((k % rate) * (NS_PER_S / rate)).astype(np.int64)


def with_gaps(
    t: np.ndarray,
    values: dict[str, np.ndarray | None],
    first_sample: np.ndarray,
    gap_first_s: np.ndarray,
    gap_seconds: np.ndarray,
    rate: int,
    origin_ns: int,
) -> Iterator[tuple[np.ndarray, dict[str, np.ndarray | None]]]:
    """The samples of a batch with its missing seconds as NaN samples, in time order, in bounded pieces.

    ``first_sample[r]``: index in ``t`` of record r's first sample; ``gap_seconds[r]`` whole seconds are missing
    before it, from second ``gap_first_s[r]`` (absolute, like the record time stamps); ``t`` is relative to
    ``origin_ns``. A gap of more than ``INLINE_FILL`` samples is yielded as pieces of ``FILL_PIECE`` samples.
    """
    return with_fills(
        t,
        values,
        first_sample,
        np.asarray(gap_first_s, dtype=np.int64) * NS_PER_S - origin_ns,
        np.asarray(gap_seconds, dtype=np.int64) * rate,
        NS_PER_S / rate,
        inline=INLINE_FILL,
        piece=FILL_PIECE,
    )
