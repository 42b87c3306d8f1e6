"""ActiGraph ``.gt3x`` recordings (GT3X+, wGT3X, GT9X Link, ...): a ZIP of ``info.txt`` and ``log.bin``, or of
``info.txt`` and the older NEO/MRA ``activity.bin``.

``info.txt``: ``Key: Value`` lines; ``Start Date`` etc. are .NET ticks (100 ns since 0001-01-01) of the device's
**local** time; ``TimeZone`` (``-05:00:00``) gives its UTC offset when ActiLife recorded one.

``log.bin``: records ``0x1E, type u8, timestamp u32 (local seconds since 1970), size u16, payload, checksum u8``
(checksum = one's complement of the XOR of header and payload; zero bytes between records are allowed). Read here:

* ACTIVITY2 (0x1A): one second of primary accelerometer samples, int16 LE X,Y,Z / ``ACCEL_SCALE`` (LSB/g) ->
  ``/imu/<name>``; a 1-byte payload is a USB connection event (ignored). ACTIVITY (0x00): the same, 12-bit packed
  in Y,X,Z order; ACTIVITY3 (0x1B): 12-bit packed in X,Y,Z order (as ActiGraph's pygt3x reads both).
* SENSOR_SCHEMA (0x18) + SENSOR_DATA (0x19): the built-in IMU (accelerometer g, gyroscope deg/s, magnetometer uT,
  temperature degC = value / scale + IMU_TEMP_OFFSET) with the columns, bit offsets, endianness and scales the
  schema declares -> ``/imu/<name>_imu``; the n samples of a record are spread evenly over its second.
* BATTERY (0x02, mV), LUX (0x05), CAPSENSE (0x0D: signal, reference, state, bursts) -> ``/signals/<name>_*``.
* PARAMETERS (0x15) and METADATA (0x06, JSON) -> ``imulog.device.<name>``. Other records are skipped.

Idle sleep: the device writes no ACTIVITY2 record while asleep (ActiLife fills those seconds with the last sample).
Here those seconds are NaN samples on the sample grid (the project's gap rule, :mod:`imulog.process.gaps`), never
zeros or copies, from ``Start Date`` to ``Last Sample Time``; a long sleep comes as separate pieces of at most
``FILL_PIECE`` samples. Their count and length are in the device record (``idle_sleep_gaps``, ``idle_sleep_s``,
``recording_end``). Seconds without a SENSOR_DATA record between two of them are NaN IMU samples likewise.

``activity.bin`` (NEO/MRA, firmware <= 2.5): a continuous stream of 12-bit two's-complement samples in Y,X,Z order
(4.5 bytes per sample, big-endian nibbles), 341 LSB/g, starting at ``Start Date`` at ``Sample Rate``.

``t_ns`` counts from ``Start Date`` (the trial's ``start_time``, with the ``TimeZone`` offset when known). Every
record checksum is verified: a damaged record stops with the file and record index. ``log.bin`` is read from the ZIP
in bounded batches (:func:`iter_chunks`), so memory does not grow with the recording.
"""

from __future__ import annotations

import json
import re
import struct
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from imulog.converters._binary import NS_PER_S, concat_chunks, iso_from_epoch_ns, time_zone_label, with_fills
from imulog.converters._common import G0, sanitize_name
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.bounds import BoundedStream, RatioLimit, check_epoch_ns, fill_budget
from imulog.converters.errors import ConversionError, excerpt

from imulog.model import ImuStream, Recording, SignalStream

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


# ---------------------------------------------------------------------------------------------- record reading
@dataclass
class RecordBatch:
    """Complete records found in ``buf``: types, timestamps (s), payload offsets and sizes; ``first`` = index."""

    buf: bytes
    first: int
    byte0: int
    types: np.ndarray
    seconds: np.ndarray
    starts: np.ndarray
    sizes: np.ndarray

    def payload(self, i: int) -> bytes:
        s = int(self.starts[i])
        return self.buf[s : s + int(self.sizes[i])]


_NONZERO = re.compile(rb"[^\x00]")


def iter_record_batches(stream: IO[bytes], path: Path, batch_bytes: int = BATCH_BYTES) -> Iterator[RecordBatch]:
    """Split ``log.bin`` into batches of complete, checksum-verified records with bounded reads."""
    leftover = b""
    index = 0
    byte0 = 0
    eof = False
    while not eof:
        data = stream.read(batch_bytes)
        eof = not data
        buf = leftover + data
        pos = 0
        heads: list[int] = []
        types: list[int] = []
        secs: list[int] = []
        sizes: list[int] = []
        n = len(buf)
        while pos < n:
            b = buf[pos]
            if b != SEPARATOR:
                if b == 0:  # zero padding: skip the whole run at once (a member of zeros is scanned at C speed)
                    m = _NONZERO.search(buf, pos)
                    pos = m.start() if m else n
                    continue
                raise ConversionError(
                    path, f"log.bin record {index + len(heads)} (byte {byte0 + pos}): no record separator (0x{b:02X})"
                )
            if pos + 8 > n:
                break
            typ, sec, size = struct.unpack_from("<BIH", buf, pos + 1)
            if pos + 9 + size > n:
                break
            heads.append(pos)
            types.append(typ)
            secs.append(sec)
            sizes.append(size)
            pos += 9 + size
        if eof and pos < n:
            raise ConversionError(
                path,
                f"log.bin record {index + len(heads)} (byte {byte0 + pos}): truncated ({n - pos} bytes at the end)",
            )
        if heads:
            h = np.asarray(heads, dtype=np.int64)
            arr = np.frombuffer(buf, dtype=np.uint8, count=pos)
            xor = np.bitwise_xor.reduceat(arr, h)  # header ^ payload ^ checksum (^ zero padding) == 0xFF
            bad = np.nonzero(xor != 0xFF)[0]
            if len(bad):
                i = int(bad[0])
                raise ConversionError(
                    path,
                    f"log.bin record {index + i} (byte {byte0 + heads[i]}, type 0x{types[i]:02X}): checksum mismatch "
                    "(the record is damaged)",
                )
            yield RecordBatch(
                buf=buf,
                first=index,
                byte0=byte0,
                types=np.asarray(types, dtype=np.int64),
                seconds=np.asarray(secs, dtype=np.int64),
                starts=h + 8,
                sizes=np.asarray(sizes, dtype=np.int64),
            )
        index += len(heads)
        leftover = buf[pos:]
        byte0 += pos


# ------------------------------------------------------------------------------------------------- conversion
@dataclass
class _State:
    """What carries over between batches of one log.bin."""

    origin_ns: int
    rate_hz: float
    accel_scale: float
    name: str
    meta: dict[str, Any]
    schemas: dict[int, SensorSchema] = field(default_factory=dict)
    last_activity_s: int | None = None
    last_sensor_s: int | None = None
    gaps: int = 0
    gap_s: int = 0
    end_ns: int | None = None  # info.txt Last Sample Time (never Stop Date): the device recorded until then
    imu_rate_hz: int | None = None  # samples per SENSOR_DATA record (median of the first batch)
    fill_left: int = 0  # NaN samples still allowed for idle sleep (bounds.fill_budget of the file)
    rate_checked: bool = False  # Sample Rate compared with the samples per ACTIVITY2 record
    warnings: list[str] = field(default_factory=list)

    def spend_fill(self, path: Path, n: int, what: str) -> None:
        """Count ``n`` NaN samples against the file's fill budget; ConversionError naming ``what`` beyond it."""
        self.fill_left -= int(n)
        if self.fill_left < 0:
            raise ConversionError(
                path,
                f"{what}: idle sleep would add more NaN samples than a file of this size can describe "
                "(a damaged time stamp or Sample Rate)",
            )

    def idle_sleep(self) -> dict[str, int]:
        """Idle-sleep counts so far, including the tail between the last ACTIVITY record and the recording's end."""
        gaps, total = self.gaps, self.gap_s
        if self.end_ns is not None and self.last_activity_s is not None:
            tail = self.end_ns // NS_PER_S - (self.last_activity_s + 1)
            if 0 < tail <= MAX_GAP_S:
                gaps, total = gaps + 1, total + int(tail)
        return {"idle_sleep_gaps": gaps, "idle_sleep_s": total}


def _concat_payloads(batch: RecordBatch, idx: np.ndarray, skip: int = 0) -> bytes:
    return b"".join(batch.buf[int(batch.starts[i]) + skip : int(batch.starts[i] + batch.sizes[i])] for i in idx)


def _check_order(path: Path, batch: RecordBatch, idx: np.ndarray, last: int | None, what: str) -> None:
    secs = batch.seconds[idx]
    prev = np.concatenate([[last if last is not None else secs[0] - 1], secs[:-1]])
    bad = np.nonzero(secs <= prev)[0]
    if len(bad):
        i = int(idx[bad[0]])
        raise ConversionError(
            path, f"log.bin record {batch.first + i}: {what} time stamp does not increase ({int(batch.seconds[i])})"
        )


def _check_gaps(path: Path, batch: RecordBatch, idx: np.ndarray, jump: np.ndarray, what: str) -> None:
    long = np.nonzero(jump > MAX_GAP_S)[0]
    if len(long):
        i = int(idx[long[0]])
        raise ConversionError(
            path,
            f"log.bin record {batch.first + i}: {what} resumes {int(jump[long[0]]) / 86400:.0f} days after the "
            "previous one (or after Start Date): a device clock or file problem, not idle sleep",
        )


def _activity(path: Path, batch: RecordBatch, st: _State) -> list[ImuStream]:
    """The batch's primary-accelerometer samples, idle-sleep seconds as NaN samples (one or more pieces)."""
    is_act2 = (batch.types == ACTIVITY2) & (batch.sizes > 1)
    is_act = ((batch.types == ACTIVITY) | (batch.types == ACTIVITY3)) & (batch.sizes > 1)  # 1 byte: USB event
    idx = np.nonzero(is_act2 | is_act)[0]
    if len(idx) == 0:
        return []
    _check_order(path, batch, idx, st.last_activity_s, "activity")
    counts, parts = [], []
    for i in idx:
        payload = batch.payload(int(i))
        if batch.types[i] == ACTIVITY2:
            if len(payload) % 6:
                raise ConversionError(
                    path, f"log.bin record {batch.first + int(i)}: ACTIVITY2 payload of {len(payload)} bytes"
                )
            xyz = np.frombuffer(payload, dtype="<i2").reshape(-1, 3)
        else:
            xyz = unpack_12bit_yxz(payload, "xyz" if batch.types[i] == ACTIVITY3 else "yxz")
        parts.append(xyz)
        counts.append(len(xyz))
    secs = batch.seconds[idx]
    first_prev = st.last_activity_s if st.last_activity_s is not None else st.origin_ns // NS_PER_S - 1
    prev = np.concatenate([[first_prev], secs[:-1]])
    jump = np.maximum(secs - prev - 1, 0)
    _check_gaps(path, batch, idx, jump, "ACTIVITY")
    counts_a = np.asarray(counts, dtype=np.int64)
    if not st.rate_checked and is_act2[idx].any():
        _check_rate(path, st, counts_a[is_act2[idx]])
    st.spend_fill(path, int(jump.sum()) * round(st.rate_hz), f"log.bin record {batch.first + int(idx[0])}")
    st.gaps += int(np.count_nonzero(jump))
    st.gap_s += int(jump.sum())
    st.last_activity_s = int(secs[-1])
    t = even_times_ns(secs, counts_a, np.maximum(st.rate_hz, counts_a)) - st.origin_ns
    acc = np.concatenate(parts).astype(np.float64) / st.accel_scale * G0
    first = np.cumsum(counts_a) - counts_a
    pieces = with_gaps(t, {"acc": acc}, first, prev + 1, jump, round(st.rate_hz), st.origin_ns)
    meta = {**st.meta, "resolution": {"acc": {"divisor": st.accel_scale, "scale": G0}}}  # counts / LSB per g * g
    return [ImuStream(name=st.name, t_ns=pt, acc=pv["acc"], meta=dict(meta)) for pt, pv in pieces]


def _check_rate(path: Path, st: _State, counts: np.ndarray) -> None:
    """The payload wins: ``Sample Rate`` is replaced by the samples per full ACTIVITY2 record (one second) when
    they differ by more than 1 %, with a warning."""
    st.rate_checked = True
    payload = float(np.median(counts))
    if payload > 0 and abs(payload - st.rate_hz) > 0.01 * payload:
        st.warnings.append(
            f"{path.name}: info.txt Sample Rate {st.rate_hz:g} Hz disagrees with the {payload:g} samples per "
            f"one-second ACTIVITY2 record; the records' {payload:g} Hz is used"
        )
        st.meta["declared_rate_hz"] = st.rate_hz
        st.rate_hz = payload
        st.meta["rate_hz"] = payload


def _activity_tail(st: _State) -> list[ImuStream]:
    """NaN samples for an idle sleep that lasted until the recording's end (no record follows it)."""
    if st.end_ns is None or st.last_activity_s is None:
        return []
    first_s = st.last_activity_s + 1
    seconds = st.end_ns // NS_PER_S - first_s
    if seconds <= 0 or seconds > MAX_GAP_S:  # an implausible Last Sample Time adds nothing
        return []
    n_all = seconds * round(st.rate_hz)
    if n_all > st.fill_left:  # an end time the file's bytes cannot back: said, not filled
        st.warnings.append(
            f"Last Sample Time is {seconds} s after the last sample: more idle sleep than a file of this size can "
            "describe, so no NaN samples were added after the last record"
        )
        return []
    st.fill_left -= n_all
    out = []
    for a in range(0, n_all, FILL_PIECE):
        m = min(FILL_PIECE, n_all - a)
        t = fill_times_ns(first_s, a + m, round(st.rate_hz))[a:] - st.origin_ns
        out.append(ImuStream(name=st.name, t_ns=t, acc=np.full((m, 3), np.nan), meta=dict(st.meta)))
    return out


def _sensor(path: Path, batch: RecordBatch, st: _State) -> list[ImuStream]:
    """The batch's IMU samples; seconds without a SENSOR_DATA record between two records become NaN samples."""
    idx = np.nonzero(batch.types == SENSOR_DATA)[0]
    if len(idx) == 0:
        return []
    _check_order(path, batch, idx, st.last_sensor_s, "SENSOR_DATA")
    secs = batch.seconds[idx]
    prev = np.concatenate([[st.last_sensor_s if st.last_sensor_s is not None else secs[0] - 1], secs[:-1]])
    jump = np.maximum(secs - prev - 1, 0)
    _check_gaps(path, batch, idx, jump, "SENSOR_DATA")
    st.last_sensor_s = int(secs[-1])
    schema_ids = [struct.unpack_from("<h", batch.buf, int(batch.starts[i]))[0] for i in idx]
    if len(set(schema_ids)) != 1:
        raise ConversionError(path, f"log.bin record {batch.first + int(idx[0])}: several sensor schemas interleaved")
    schema = st.schemas.get(schema_ids[0])
    if schema is None:
        raise ConversionError(
            path, f"log.bin record {batch.first + int(idx[0])}: SENSOR_DATA before its SENSOR_SCHEMA {schema_ids[0]}"
        )
    bps = schema.bytes_per_sample
    body = batch.sizes[idx] - 2
    bad = np.nonzero(body % bps)[0]
    if len(bad):
        i = int(idx[bad[0]])
        raise ConversionError(
            path, f"log.bin record {batch.first + i}: SENSOR_DATA of {int(batch.sizes[i])} bytes is not whole samples"
        )
    counts = body // bps
    raw = np.frombuffer(_concat_payloads(batch, idx, skip=2), dtype=np.uint8).reshape(-1, bps)
    cols = decode_sensor_samples(schema, raw)
    t = even_times_ns(batch.seconds[idx], counts, np.maximum(counts, 1))

    def trio(prefix: str) -> np.ndarray | None:
        names = [f"{prefix} {a}" for a in "XYZ"]
        return np.column_stack([cols[n] for n in names]) if all(n in cols for n in names) else None

    acc, gyr, mag = trio("Accelerometer"), trio("Gyroscope"), trio("Magnetometer")
    temp = cols.get("Temperature")
    if temp is not None:
        temp = temp + float(st.meta.get("imu_temp_offset", 21.0))
    rate = int(np.median(counts))
    if st.imu_rate_hz is None:
        st.imu_rate_hz = rate
    meta = {**st.meta, "rate_hz": float(st.imu_rate_hz), "columns": [c.label for c in schema.columns if c.label]}
    meta["resolution"] = _sensor_resolution(schema, float(st.meta.get("imu_temp_offset", 21.0)))
    values = {
        "acc": None if acc is None else acc * G0,
        "gyr": None if gyr is None else np.radians(gyr),
        "mag": mag,
        "temperature": temp,
    }
    first = np.cumsum(counts) - counts
    pieces = with_gaps(t - st.origin_ns, values, first, prev + 1, jump, st.imu_rate_hz, st.origin_ns)
    return [ImuStream(name=f"{st.name}_imu", t_ns=pt, meta=dict(meta), **pv) for pt, pv in pieces]


def _sensor_resolution(schema: SensorSchema, temp_offset: float) -> dict[str, dict[str, Any]]:
    """How the SI values of :func:`_sensor` follow from the SENSOR_DATA counts: ``(counts / column scale) *
    unit factor (+ offset)`` per axis, as :mod:`imulog.archive.numbers` stores them (checked value by value)."""
    scales = {c.label: c.scale for c in schema.columns if c.label and c.scale}
    out: dict[str, dict[str, Any]] = {}
    for name, prefix, factor in (
        ("acc", "Accelerometer", G0),
        ("gyr", "Gyroscope", np.pi / 180),
        ("mag", "Magnetometer", 1.0),
    ):
        div = [scales.get(f"{prefix} {a}") for a in "XYZ"]
        if all(div):
            out[name] = {"divisor": div, "scale": factor}
    if scales.get("Temperature"):
        out["temperature"] = {"divisor": scales["Temperature"], "offset": temp_offset}
    return out


def _scalar_signals(batch: RecordBatch, st: _State) -> list[SignalStream]:
    out = []
    specs = [
        (BATTERY, "battery", "<u2", ["battery"], ["V"], 1e-3),
        (LUX, "lux", "<u2", ["lux"], ["lux"], 1.0),
        (
            CAPSENSE,
            "capsense",
            "<u2,<u2,u1,u1",
            ["signal", "reference", "state", "bursts"],
            ["counts"] * 2 + ["1"] * 2,
            1.0,
        ),
    ]
    for typ, suffix, fmt, columns, units, scale in specs:
        idx = np.nonzero(batch.types == typ)[0]
        dt = (
            np.dtype(fmt)
            if "," not in fmt
            else np.dtype([(c, f) for c, f in zip(columns, fmt.split(","), strict=True)])
        )
        idx = idx[batch.sizes[idx] >= dt.itemsize]
        if len(idx) == 0:
            continue
        rows = np.frombuffer(b"".join(batch.payload(int(i))[: dt.itemsize] for i in idx), dtype=dt)
        values = (
            np.column_stack([rows[c].astype(np.float64) for c in columns])
            if rows.dtype.names
            else rows.astype(np.float64)[:, None] * scale
        )
        t = batch.seconds[idx] * NS_PER_S - st.origin_ns
        keep = np.concatenate([[True], np.diff(t) > 0])  # a repeated second keeps its first record
        out.append(
            SignalStream(
                topic=f"/signals/{st.name}_{suffix}", t_ns=t[keep], columns=columns, units=units, values=values[keep]
            )
        )
    return out


class _StoredMember:
    """Bounded reader over a stored (uncompressed) ZIP member's bytes: the record checksums verify every byte, so a
    damaged byte is reported with its record (zipfile would only say the member's CRC is wrong, at its end)."""

    def __init__(self, path: Path, info: zipfile.ZipInfo):
        self._f = open(path, "rb")  # noqa: SIM115 - closed by __exit__/close
        self._f.seek(info.header_offset)
        local = self._f.read(30)
        if len(local) < 30 or local[:4] != b"PK\x03\x04":
            self._f.close()
            raise ConversionError(path, f"damaged ZIP: no local header for {info.filename}")
        name_len, extra_len = struct.unpack_from("<HH", local, 26)
        self._f.seek(info.header_offset + 30 + name_len + extra_len)
        self._left = info.file_size

    def read(self, n: int = -1) -> bytes:
        n = self._left if n < 0 else min(n, self._left)
        data = self._f.read(n)
        self._left -= len(data)
        return data

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> _StoredMember:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _open_member(path: Path, z: zipfile.ZipFile, name: str) -> IO[bytes] | _StoredMember | BoundedStream:
    info = z.getinfo(name)
    if info.compress_type == zipfile.ZIP_STORED and not info.flag_bits & 0x1:
        return _StoredMember(path, info)
    return BoundedStream(z.open(name), RatioLimit(path, name, info.compress_size))


def _open_gt3x(path: Path) -> tuple[zipfile.ZipFile, dict[str, str]]:
    try:
        z = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as e:
        raise ConversionError(path, f"not a readable .gt3x (ZIP) file: {e}") from None
    names = set(z.namelist())
    if "info.txt" not in names:
        z.close()
        raise ConversionError(path, "no info.txt inside: not an ActiGraph .gt3x")
    try:
        member = z.getinfo("info.txt")
        if member.file_size > MAX_INFO_BYTES:  # a few hundred bytes in real files
            raise ConversionError(path, f"info.txt of {member.file_size} bytes: not an ActiGraph info.txt (damaged?)")
        with BoundedStream(z.open(member), RatioLimit(path, "info.txt", member.compress_size)) as f:
            text = f.read(MAX_INFO_BYTES + 1)
        info = parse_info(path, text.decode("utf-8-sig", "replace"))
    except (zipfile.BadZipFile, OSError, EOFError) as e:
        z.close()
        raise ConversionError(path, f"info.txt cannot be read: {e}") from None
    except ConversionError:
        z.close()
        raise
    return z, info


def _base_state(path: Path, info: dict[str, str], options: ConvertOptions) -> tuple[_State, int | None]:
    serial = info["Serial Number"]
    names = {str(k).upper(): v for k, v in (options.extra.get("names") or {}).items()}
    name = sanitize_name(names.get(serial.upper(), serial))
    try:
        rate = float(info.get("Sample Rate", "nan"))
        start_ticks = int(info["Start Date"])
    except (KeyError, ValueError):
        raise ConversionError(path, "info.txt needs a numeric 'Sample Rate' and 'Start Date'") from None
    if not 0 < rate < float("inf"):
        raise ConversionError(path, f"info.txt: bad Sample Rate {excerpt(info.get('Sample Rate'))!r}")
    start_ns = check_epoch_ns(path, "info.txt Start Date", ticks_to_epoch_ns(start_ticks))
    scale_text = info.get("Acceleration Scale")
    default_scale = NEO_SCALE if serial[:3].upper() in ("NEO", "CLE", "MRA") else 256.0
    scale = float(scale_text) if scale_text else default_scale
    offset = parse_offset_s(info.get("TimeZone"))
    meta: dict[str, Any] = {
        "format": "actigraph-gt3x",
        "model": f"ActiGraph {info.get('Device Type', '')}".strip(),
        "serial": serial,
        "firmware": info.get("Firmware", ""),
        "rate_hz": rate,
        "accel_scale_lsb_per_g": scale,
        "time_base": "ns from start_time (info.txt Start Date, device local time)",
        "source": path.name,
    }
    for key in ("Acceleration Min", "Acceleration Max", "Limb", "Subject Name", "Board Revision", "TimeZone"):
        if key in info:
            meta[sanitize_name(key)] = info[key]
    st = _State(origin_ns=start_ns, rate_hz=rate, accel_scale=scale, name=name, meta=meta)
    st.fill_left = fill_budget(path)
    # Last Sample Time only: Stop Date is when recording was to stop, not evidence that it went on until then
    text = info.get("Last Sample Time", "").strip()
    if text.isdigit() and 0 < int(text) < 10**19:
        end_ns = ticks_to_epoch_ns(int(text))
        if start_ns <= end_ns <= start_ns + MAX_RECORDING_S * NS_PER_S:
            st.end_ns = end_ns
            meta["recording_end"] = iso_from_epoch_ns(st.end_ns, offset)
    return st, offset


def _trial(st: _State, offset: int | None) -> dict[str, Any]:
    return {"start_time": iso_from_epoch_ns(st.origin_ns, offset), "time_zone": time_zone_label(offset)}


def _iter_log(path: Path, z: zipfile.ZipFile, st: _State, offset: int | None) -> Iterator[Recording]:
    trial = _trial(st, offset)
    found = False
    with _open_member(path, z, "log.bin") as stream:
        for batch in iter_record_batches(stream, path):
            for i in np.nonzero(batch.types == PARAMETERS)[0]:
                params = parse_parameters(batch.payload(int(i)))
                st.meta.update(params)
                if params.get("accel_scale"):
                    st.accel_scale = float(params["accel_scale"])
                    st.meta["accel_scale_lsb_per_g"] = st.accel_scale
            for i in np.nonzero(batch.types == METADATA)[0]:
                try:
                    doc = json.loads(batch.payload(int(i)).decode("utf-8", "replace"))
                except ValueError:
                    continue
                if isinstance(doc, dict) and doc.get("MetadataType"):
                    kind = sanitize_name(str(doc["MetadataType"]))
                    st.meta[f"metadata_{kind}"] = {k: v for k, v in doc.items() if k not in ("JSON", "Parsed")}
            for i in np.nonzero(batch.types == SENSOR_SCHEMA)[0]:
                schema = parse_schema(path, batch.payload(int(i)), batch.first + int(i))
                st.schemas[schema.ident] = schema
            acts, sens = _activity(path, batch, st), _sensor(path, batch, st)
            signals = _scalar_signals(batch, st)
            if not acts and not sens and not signals:
                continue
            found = found or bool(acts or sens)
            first = [p[0] for p in (acts, sens) if p]
            later = [*acts[1:], *sens[1:]]  # NaN pieces of long gaps (each stream's pieces stay in time order)
            for i, imus in enumerate([first, *[[p] for p in later]]):
                yield _piece(path, st, trial, imus, signals if i == 0 else [])
    tail = _activity_tail(st)
    for piece in tail:
        yield _piece(path, st, trial, [piece], [])
    if st.warnings and found:  # said after the last piece (e.g. an end time the bytes cannot back)
        yield _piece(path, st, trial, [], [])
    if not found:
        raise ConversionError(path, "log.bin holds no ACTIVITY, ACTIVITY2, ACTIVITY3 or SENSOR_DATA samples")


def _piece(
    path: Path, st: _State, trial: dict[str, Any], imus: list[ImuStream], signals: list[SignalStream]
) -> Recording:
    """One piece of a log.bin with the device records as known so far (idle-sleep counts included)."""
    sleep = st.idle_sleep()
    st.meta.update(sleep)
    for s in imus:
        s.meta.update(sleep)
    rec = Recording(imus=imus, signals=signals, sources=[str(path)], warnings=list(st.warnings))
    st.warnings.clear()
    rec.metadata[f"imulog.device.{st.name}"] = dict(st.meta)
    imu_stream = next((s for s in imus if s.name == f"{st.name}_imu"), None)
    if imu_stream is not None:
        imu_meta = {k: v for k, v in imu_stream.meta.items() if k != "accel_scale_lsb_per_g"}
        rec.metadata[f"imulog.device.{st.name}_imu"] = {**imu_meta, "model": f"{st.meta['model']} IMU"}
    rec.metadata["imulog.trial"] = dict(trial)
    return rec


def _iter_activity_bin(path: Path, z: zipfile.ZipFile, st: _State, offset: int | None) -> Iterator[Recording]:
    """NEO/MRA activity.bin: 9 bytes per two samples, read in bounded batches."""
    st.meta["format"] = "actigraph-gt3x (NEO activity.bin)"
    if st.rate_hz > MAX_RATE_HZ:  # the only time base of activity.bin: nothing in the payload can correct it
        raise ConversionError(path, f"info.txt: Sample Rate {st.rate_hz:g} Hz is beyond any ActiGraph's (at most 100)")
    trial = _trial(st, offset)
    step = 9 * (BATCH_BYTES // 9)
    spacing = NS_PER_S / st.rate_hz
    done = 0
    with _open_member(path, z, "activity.bin") as stream:
        while True:
            data = stream.read(step)
            if not data:
                break
            xyz = unpack_12bit_yxz(data)  # batches are whole sample pairs; an odd last sample ends on a nibble
            if len(xyz) == 0:
                break
            k = np.arange(done, done + len(xyz), dtype=np.float64)
            done += len(xyz)
            imu = ImuStream(
                name=st.name,
                t_ns=np.round(k * spacing).astype(np.int64),
                acc=xyz / st.accel_scale * G0,
                meta={**st.meta, "resolution": {"acc": {"divisor": st.accel_scale, "scale": G0}}},
            )
            rec = Recording(imus=[imu], sources=[str(path)])
            rec.metadata[f"imulog.device.{st.name}"] = dict(st.meta)
            rec.metadata["imulog.trial"] = dict(trial)
            yield rec
    if done == 0:
        raise ConversionError(path, "activity.bin holds no samples")


def iter_chunks(path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
    """Decode a .gt3x batch by batch (same streams in every chunk, times from the trial's start_time)."""
    path = Path(path)
    z, info = _open_gt3x(path)
    with z:
        st, offset = _base_state(path, info, options or ConvertOptions())
        names = set(z.namelist())
        try:
            if "log.bin" in names:
                yield from _iter_log(path, z, st, offset)
            elif "activity.bin" in names:
                yield from _iter_activity_bin(path, z, st, offset)
            else:
                raise ConversionError(path, "neither log.bin nor activity.bin inside the .gt3x")
        except (zipfile.BadZipFile, EOFError, OSError) as e:  # e.g. a CRC error of the ZIP member
            raise ConversionError(path, f"damaged ZIP content: {e}") from None


def read_gt3x(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole .gt3x as one Recording (assembled from :func:`iter_chunks`)."""
    return concat_chunks(iter_chunks(path, options))


class ActiGraphConverter(Converter):
    name = "actigraph"
    description = "ActiGraph .gt3x (log.bin: ACTIVITY2 accel + IMU gyro/mag/temp, battery; NEO activity.bin)"
    extensions = (".gt3x",)
    example = "imulog convert ../shared/data/devices/actigraph_gt3x/example.gt3x -o gt3x.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        if head[:4] != b"PK\x03\x04":
            return 0.0
        try:
            with zipfile.ZipFile(path) as z:
                names = set(z.namelist())
        except (zipfile.BadZipFile, OSError):
            return 0.5 if Path(path).suffix.lower() == ".gt3x" else 0.0  # damaged: convert() says what is wrong
        if "info.txt" in names and names & {"log.bin", "activity.bin"}:
            return 0.95
        return 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_gt3x(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Bounded-memory pieces for the streaming convert (see the module's :func:`iter_chunks`)."""
        return iter_chunks(Path(path), options)


CONVERTER = ActiGraphConverter()
