"""ActiGraph log.bin batches to streams: activity, IMU sensor data and scalar signals, with the state carried between batches."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._binary import NS_PER_S
from imulog.converters._common import G0
from imulog.converters.actigraph_format import (
    ACTIVITY,
    ACTIVITY2,
    ACTIVITY3,
    BATTERY,
    CAPSENSE,
    FILL_PIECE,
    LUX,
    MAX_GAP_S,
    SENSOR_DATA,
    SensorSchema,
    decode_sensor_samples,
    even_times_ns,
    fill_times_ns,
    unpack_12bit_yxz,
    with_gaps,
)
from imulog.converters.actigraph_records import RecordBatch
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, SignalStream


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
