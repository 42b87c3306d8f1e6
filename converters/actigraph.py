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
import struct
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np
from imulog.converters._binary import NS_PER_S, concat_chunks, iso_from_epoch_ns, time_zone_label
from imulog.converters._common import G0, sanitize_name
from imulog.converters.actigraph_decode import (
    _activity,
    _activity_tail,
    _scalar_signals,
    _sensor,
    _State,
)
from imulog.converters.actigraph_format import (
    ACTIVITY,
    ACTIVITY2,
    ACTIVITY3,
    BATCH_BYTES,
    BATTERY,
    CAPSENSE,
    FILL_PIECE,
    FLOAT_PARAMETERS,
    INLINE_FILL,
    LUX,
    MAX_GAP_S,
    MAX_INFO_BYTES,
    MAX_RATE_HZ,
    MAX_RECORDING_S,
    METADATA,
    NEO_SCALE,
    PARAMETER_NAMES,
    PARAMETERS,
    SENSOR_DATA,
    SENSOR_SCHEMA,
    SEPARATOR,
    SIGNED_PARAMETERS,
    TICKS_AT_1970,
    TICKS_PER_S,
    SensorColumn,
    SensorSchema,
    decode_sensor_samples,
    even_times_ns,
    fill_times_ns,
    parse_info,
    parse_offset_s,
    parse_parameters,
    parse_schema,
    ssp_decode,
    ticks_to_epoch_ns,
    unpack_12bit_yxz,
    with_gaps,
)
from imulog.converters.actigraph_records import RecordBatch, iter_record_batches
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.bounds import BoundedStream, RatioLimit, check_epoch_ns, fill_budget
from imulog.converters.errors import ConversionError, excerpt

from imulog.model import ImuStream, Recording, SignalStream

__all__ = [
    "ActiGraphConverter",
    "ACTIVITY",
    "ACTIVITY2",
    "ACTIVITY3",
    "BATCH_BYTES",
    "BATTERY",
    "CAPSENSE",
    "CONVERTER",
    "decode_sensor_samples",
    "even_times_ns",
    "FILL_PIECE",
    "fill_times_ns",
    "FLOAT_PARAMETERS",
    "INLINE_FILL",
    "iter_chunks",
    "iter_record_batches",
    "LUX",
    "MAX_GAP_S",
    "MAX_INFO_BYTES",
    "MAX_RATE_HZ",
    "MAX_RECORDING_S",
    "METADATA",
    "NEO_SCALE",
    "PARAMETER_NAMES",
    "PARAMETERS",
    "parse_info",
    "parse_offset_s",
    "parse_parameters",
    "parse_schema",
    "read_gt3x",
    "RecordBatch",
    "SENSOR_DATA",
    "SENSOR_SCHEMA",
    "SensorColumn",
    "SensorSchema",
    "SEPARATOR",
    "SIGNED_PARAMETERS",
    "ssp_decode",
    "TICKS_AT_1970",
    "TICKS_PER_S",
    "ticks_to_epoch_ns",
    "unpack_12bit_yxz",
    "with_gaps",
]


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
