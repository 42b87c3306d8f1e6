"""NilsPod (Portabiles) ``.bin`` sessions, and the ``_data.csv`` + ``_header.json`` pair that NilsPodLib writes.

Binary layout (NilsPodLib ``header.py``/``dataset.py``, firmware 0.14 and later): byte 0 is the header size ``H``;
bytes 1..H-1 hold, in order: sample size, two bytes of enabled-sensor flags (gyro 0x02, acc 0x01, mag 0x04, baro
0x08, analog 0x10, ecg 0x20, ppg 0x40, temperature 0x80; samples carry them in the order gyro, acc, mag, baro,
analog, ecg, ppg, temperature), sampling-rate code (1: 1024 Hz ... 10: 102.4 Hz ... 160: 6.4 Hz), session
termination, sync role, sync distance (x 100 ms), acc range (g), gyro range (x 125 deg/s), sensor position,
operation mode, 3 bytes of custom metadata, Unix start and stop (uint32 LE), sample count, sync indices, MAC
address, sync address and channel, hardware version (2 bytes) and the firmware version (last 3 bytes). Then
fixed-size little-endian samples: int16 x3 gyro, acc, mag; int16 baro; uint16 x3 analog; int32 ecg, ppg; int16
temperature; uint32 counter last.

Units as NilsPodLib's factory calibration: acc raw / (2^16 / range / 2 / 9.81) m/s^2 (NilsPodLib's g = 9.81),
gyro raw / (2^16 / range / 2) deg/s (-> rad/s), baro (raw + 101325) / 100 mbar, temperature raw / 512 + 23 degC;
mag, analog, ecg and ppg stay raw counts (``/signals/<name>``). Time: the counter (samples since the device's
midnight) over the rate, ``t_ns`` from the first sample; ``start_time`` = midnight of ``utc_start``'s day + counter
/ rate, in UTC (the sensor clock is set to UTC by its app; NilsPodLib warns it may not be). A counter step above 1
is missing samples (a gap), a step <= 0 is an error naming the sample.

Memory: a ``.bin`` session in pieces of samples read from the file (:func:`iter_bin`), NilsPodLib's CSV export in
pieces of text (:func:`iter_csv`); the whole file is the one-piece case. In pieces, a first pass over the counters
(the ``t`` column) gives the missing-sample count that the first piece declares as the IMU's meta.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._lab import trial_start
from imulog.converters.base import Converter, ConvertOptions, export_source
from imulog.converters.errors import ConversionError

from imulog.model import PIECES_RECORD, ImuStream, Recording, SignalStream

SENSORS = (  # name, flag byte index (0/1), flag, channels, bytes per channel, dtype
    ("gyro", 0, 0x02, 3, 2, "<i2"),
    ("acc", 0, 0x01, 3, 2, "<i2"),
    ("mag", 0, 0x04, 3, 2, "<i2"),
    ("baro", 0, 0x08, 1, 2, "<i2"),
    ("analog", 0, 0x10, 3, 2, "<u2"),
    ("ecg", 0, 0x20, 1, 4, "<i4"),
    ("ppg", 0, 0x40, 1, 4, "<i4"),
    ("temperature", 0, 0x80, 1, 2, "<i2"),
)
RATES = {1: 1024.0, 2: 512.0, 4: 256.0, 5: 204.8, 10: 102.4, 20: 51.2, 40: 25.6, 80: 12.8, 160: 6.4}
TERMINATION = {0x10: "no memory", 0x20: "BLE", 0x40: "dock", 0x80: "low battery"}
SYNC_ROLE = {0: "disabled", 1: "slave", 2: "master"}
GRAV = 9.81  # NilsPodLib's factory calibration
MIN_FIRMWARE = (0, 14, 0)


def parse_header(path: Path, data: bytes) -> dict:
    """The session header as NilsPodLib's ``Header`` fields (see the module docstring)."""
    if len(data) < 1 or data[0] < 49:
        raise ConversionError(path, "not a NilsPod session (header size byte < 49)")
    size = data[0]
    if len(data) < size:
        raise ConversionError(path, f"file ends inside the {size}-byte NilsPod header")
    h = np.frombuffer(data, dtype=np.uint8, count=size)[1:].astype(np.int64)
    version = tuple(int(x) for x in h[-3:])
    if version < MIN_FIRMWARE:
        raise ConversionError(
            path,
            f"NilsPod firmware v{'.'.join(map(str, version))}: the header layout before v0.14 is not supported; "
            "convert it with NilsPodLib (legacy_support='resolve') and export a CSV",
        )

    def le(lo: int, hi: int) -> int:
        return int(sum(int(v) << (8 * i) for i, v in enumerate(h[lo:hi])))

    if int(h[3]) not in RATES:
        raise ConversionError(path, f"header: unknown sampling-rate code {int(h[3])}")
    enabled = [s[0] for s in SENSORS if int(h[1 + s[1]]) & s[2]]
    return {
        "sample_size": int(h[0]),
        "enabled_sensors": enabled,
        "sampling_rate_hz": RATES[int(h[3])],
        "session_termination": next((v for k, v in TERMINATION.items() if int(h[4]) & k), "unknown"),
        "sync_role": SYNC_ROLE.get(int(h[5]), str(int(h[5]))),
        "sync_distance_ms": float(h[6] * 100),
        "acc_range_g": float(h[7]),
        "gyro_range_dps": float(h[8] * 125),
        "utc_start": le(14, 18),
        "utc_stop": le(18, 22),
        "n_samples": le(22, 26),
        "sync_index_start": le(26, 30),
        "sync_index_stop": le(30, 34),
        "mac_address": ":".join(f"{int(x):02x}" for x in h[34:40][::-1]),
        "version_hardware": "".join(str(int(x)) for x in h[46:48]),
        "version_firmware": "v{}.{}.{}".format(*version),
        "header_size": size,
    }


def _units(sensor: str, raw: np.ndarray, hdr: dict) -> np.ndarray:
    """NilsPodLib's factory calibration of one sensor's raw values."""
    if sensor == "acc":
        return raw / (2**16 / hdr["acc_range_g"] / 2 / GRAV)
    if sensor == "gyro":
        return raw / (2**16 / hdr["gyro_range_dps"] / 2)
    if sensor == "baro":
        return (raw + 101325) / 100.0
    if sensor == "temperature":
        return raw * 2.0**-9 + 23
    return raw


def read_bin(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole session: :func:`iter_bin` as one piece."""
    (rec,) = iter_bin(path, options, samples_per_piece=None)
    return rec


#: samples per piece of a ``.bin`` session converted piece by piece (about 30 MB of samples at 30 bytes each)
PIECE_SAMPLES = 1 << 20


def iter_bin(
    path: Path, options: ConvertOptions | None = None, samples_per_piece: int | None = PIECE_SAMPLES
) -> Iterator[Recording]:
    """The session in pieces of ``samples_per_piece`` fixed-size samples read from the file (None: one piece);
    the counter is checked across pieces, and the missing-sample count is the last piece's (the whole session's)."""
    path = Path(path)
    with open(path, "rb") as f:
        hdr = parse_header(path, f.read(256))
        size = hdr["sample_size"]
        widths = {s[0]: s[3] * s[4] for s in SENSORS}
        need = sum(widths[s] for s in hdr["enabled_sensors"]) + 4
        if size != need:
            raise ConversionError(path, f"header: sample size {size} bytes, the enabled sensors need {need}")
        n, rest = divmod(os.fstat(f.fileno()).st_size - hdr["header_size"], size)
        warnings = []
        if rest:
            warnings.append(f"{path.name}: {rest} bytes after the last whole sample (a cut sample); ignored")
        if n != hdr["n_samples"]:
            warnings.append(f"{path.name}: header says {hdr['n_samples']} samples, the file holds {n}; read them")
        if n == 0:
            raise ConversionError(path, "no samples after the header")
        step = n if samples_per_piece is None else samples_per_piece
        declared = None
        if step < n:  # pieces: the counters first (the missing-sample count goes into the first piece's meta)
            f.seek(hdr["header_size"])
            counters = (_read_rows(f, min(step, n - i), size)[:, -4:] for i in range(0, n, step))
            declared = _declare_counters(path, hdr, hdr["enabled_sensors"], (_counter(c) for c in counters))
        f.seek(hdr["header_size"])
        carry = _Counter()
        for first in range(0, n, step):
            k = min(step, n - first)
            rows = _read_rows(f, k, size)
            values: dict[str, np.ndarray] = {}
            pos = 0
            for name, _, _, ch, width, dt in SENSORS:
                if name in hdr["enabled_sensors"]:
                    raw = np.ascontiguousarray(rows[:, pos : pos + ch * width]).view(dt).reshape(k, ch)
                    values[name] = _units(name, raw.astype(np.float64), hdr)
                    pos += ch * width
            counter = _counter(rows[:, pos : pos + 4])
            rec = _recording(path, hdr, counter, values, warnings if first == 0 else [], carry, last=first + k == n)
            if declared is not None and first == 0:
                rec.metadata[PIECES_RECORD] = declared
            yield rec


def _read_rows(f: Any, k: int, size: int) -> np.ndarray:
    return np.frombuffer(f.read(k * size), dtype=np.uint8, count=k * size).reshape(k, size)


def _counter(raw: np.ndarray) -> np.ndarray:
    """The uint32 sample counters of rows' last four bytes, as int64."""
    return np.ascontiguousarray(raw).view("<u4").reshape(len(raw)).astype(np.int64)


def _declare_counters(path: Path, hdr: dict, sensors: list[str], counters: Iterator[np.ndarray]) -> dict:
    """The declaration of a session from its counters read piece by piece: the samples they skip (as
    :func:`_recording` counts them) and the last sample's time."""
    first = last = None
    missing = 0
    for c in counters:
        full = c if last is None else np.concatenate([[last], c])
        missing += int((np.diff(full) - 1).sum())
        first = int(c[0]) if first is None else first
        last = int(c[-1])
    span = int(np.round((np.array([last], np.int64) - first) * (1e9 / float(hdr["sampling_rate_hz"])))[0])
    return _declaration(hdr, sensors, _meta(path, hdr, missing), span)


def _resolution(hdr: dict) -> dict:
    """How the IMU fields are stored: the int16 words with the divisions and factors of :func:`_units` (NilsPodLib's
    CSV holds the same quotients, printed in full), which the archive checks value by value
    (:mod:`imulog.archive.numbers`); without the ranges, the text's decimals x pi/180 for the gyroscope."""
    res: dict = {"gyr": {"scale": np.pi / 180}, "temperature": {"scale": 2.0**-9, "offset": 23.0}}
    if hdr.get("acc_range_g"):
        res["acc"] = {"divisor": 2**16 / hdr["acc_range_g"] / 2 / GRAV}
    if hdr.get("gyro_range_dps"):
        res["gyr"] = {"divisor": 2**16 / hdr["gyro_range_dps"] / 2, "scale": np.pi / 180}
    return res


class _Counter:
    """The sample counter across pieces: the first value, the last one, how many samples it skipped and where."""

    def __init__(self) -> None:
        self.first: int | None = None
        self.last: int | None = None
        self.seen = 0  # samples before this piece
        self.missing = 0
        self.places = 0


def _name(hdr: dict) -> str:
    """The device's stream name: ``nilspod_`` and the last two bytes of its MAC address."""
    return "nilspod_" + ("".join(hdr.get("mac_address", "")[-5:].split(":")) or "nilspod")


def _meta(path: Path, hdr: dict, missing: int) -> dict:
    """The device record (and the IMU stream's meta) of a session with ``missing`` samples skipped in all."""
    rate = float(hdr["sampling_rate_hz"])
    return {
        "format": "nilspod",
        "model": f"NilsPod (hardware {hdr.get('version_hardware', '?')})",
        "serial": hdr.get("mac_address", ""),
        "firmware": hdr.get("version_firmware", ""),
        "rate_hz": rate,
        "acc_range_g": hdr.get("acc_range_g"),
        "gyro_range_dps": hdr.get("gyro_range_dps"),
        "sync_role": hdr.get("sync_role"),
        "session_termination": hdr.get("session_termination"),
        "missing_samples": missing,
        "units": "NilsPodLib factory calibration (acc with g = 9.81)",
        "source": path.name,
        "resolution": _resolution(hdr),
    }


def _declaration(hdr: dict, sensors: list[str], meta: dict, span_ns: int) -> dict:
    """What the first piece declares (:data:`imulog.model.PIECES_RECORD`): every stream from 0 to ``span_ns`` and
    the IMU's final meta (its missing-sample count is known only after every counter was read)."""
    name = _name(hdr)
    topics = [f"/imu/{name}"] if {"acc", "gyro"} & set(sensors) else []
    topics += [f"/signals/{name}"] if {"mag", "baro", "analog", "ecg", "ppg"} & set(sensors) else []
    return {"spans": dict.fromkeys(topics, [0, span_ns]), "meta": {t: meta for t in topics if t.startswith("/imu/")}}


def _recording(
    path: Path,
    hdr: dict,
    counter: np.ndarray,
    values: dict,
    warnings: list[str],
    carry: _Counter | None = None,
    last: bool = True,
) -> Recording:
    """The Recording of decoded NilsPod values (shared by the binary and the CSV + JSON reader); ``carry``: the
    counter so far when this is a later piece of the session, ``last``: whether it is the session's last."""
    carry = _Counter() if carry is None else carry
    rate = float(hdr["sampling_rate_hz"])
    full = counter if carry.last is None else np.concatenate([[carry.last], counter])
    step = np.diff(full)
    if (step <= 0).any():
        j = int(np.argmax(step <= 0)) + 1
        i = j + carry.seen - (0 if carry.last is None else 1)
        raise ConversionError(path, f"sample {i}: the counter does not increase ({full[j - 1]} -> {full[j]})")
    carry.missing += int((step - 1).sum())
    carry.places += int((step > 1).sum())
    missing = carry.missing
    if missing and last:
        warnings.append(f"{path.name}: the counter skips {missing} samples in {carry.places} places (gaps)")
    if carry.first is None:
        carry.first = int(counter[0])
    carry.last, carry.seen = int(counter[-1]), carry.seen + len(counter)
    t_ns = np.round((counter - carry.first) * (1e9 / rate)).astype(np.int64)
    name = _name(hdr)
    meta = _meta(path, hdr, missing)
    rec = Recording(sources=[str(path)], warnings=warnings)
    imu = {
        "acc": values.get("acc"),
        "gyr": np.radians(values["gyro"]) if "gyro" in values else None,
        "temperature": values["temperature"][:, 0] if "temperature" in values else None,
    }
    if imu["acc"] is not None or imu["gyr"] is not None:
        rec.imus.append(ImuStream(name=name, t_ns=t_ns, meta=meta, **imu))
    cols, units, vals = [], [], []
    for key, labels, unit in (
        ("mag", ["mag_x", "mag_y", "mag_z"], "counts"),
        ("baro", ["baro"], "mbar"),
        ("analog", ["analog_0", "analog_1", "analog_2"], "counts"),
        ("ecg", ["ecg"], "counts"),
        ("ppg", ["ppg"], "counts"),
    ):
        if key in values:
            cols += labels
            units += [unit] * len(labels)
            vals.append(values[key])
    if cols:
        rec.signals.append(SignalStream(f"/signals/{name}", t_ns, cols, units, np.column_stack(vals)))
    if not rec.streams():
        raise ConversionError(path, "no sensor enabled")
    start = hdr.get("utc_start")
    if start:
        midnight = datetime.fromtimestamp(int(start), tz=UTC).replace(hour=0, minute=0, second=0)
        when = midnight + timedelta(seconds=float(carry.first) / rate)
        rec.metadata["imulog.trial"] = trial_start(when, "NilsPod header utc_start (midnight) + counter / rate")
    rec.metadata[f"imulog.device.{name}"] = meta
    return rec


CSV_SENSORS = {
    "gyro": ["gyr_x", "gyr_y", "gyr_z"],
    "acc": ["acc_x", "acc_y", "acc_z"],
    "mag": ["mag_x", "mag_y", "mag_z"],
    "baro": ["baro"],
    "analog": ["analog_0", "analog_1", "analog_2"],
    "ecg": ["ecg"],
    "ppg": ["ppg"],
    "temperature": ["temp"],
}


def header_json_for(path: Path) -> Path | None:
    """``X_header.json`` beside ``X_data.csv`` (NilsPodLib's names), else None."""
    m = re.match(r"(.*)_data$", Path(path).stem)
    if not m:
        return None
    p = Path(path).with_name(f"{m.group(1)}_header.json")
    return p if p.is_file() else None


def read_csv(path: Path, options: ConvertOptions | None = None) -> Recording:
    """NilsPodLib's ``data_as_csv`` export whole: :func:`iter_csv` as one piece."""
    from imulog.converters._binary import concat_chunks

    return concat_chunks(iter_csv(path, options, piece_bytes=None))


def iter_csv(path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = None) -> Iterator[Recording]:
    """NilsPodLib's ``data_as_csv`` export (``t`` in s from the first sample, columns as its legends) and the
    ``_header.json`` it writes beside it (rate, ranges, start), in pieces of about ``piece_bytes`` of text (None:
    one piece); in pieces, a first pass over the ``t`` column gives the missing-sample count the first declares."""
    from imulog.converters._pieces import hand_over, iter_table

    path = Path(path)
    hj = header_json_for(path)
    if hj is None:
        raise ConversionError(path, "a NilsPodLib CSV needs its <name>_header.json beside it (rate, start time)")
    try:
        hdr = json.loads(hj.read_text())
    except (OSError, ValueError) as e:
        raise ConversionError(hj, f"not a NilsPodLib header JSON: {e}") from None
    if "sampling_rate_hz" not in hdr:
        raise ConversionError(hj, "no 'sampling_rate_hz'")
    with open(path, encoding="utf-8", errors="replace") as f:
        names = [c.strip() for c in f.readline().strip().split(",")]
    if not names or names[0] != "t":
        raise ConversionError(path, "the first column must be 't'", line=1)
    rate = float(hdr["sampling_rate_hz"])
    sensors = [sensor for sensor, cols in CSV_SENSORS.items() if all(c in names for c in cols)]
    table = {"delimiter": ",", "skip_lines": 1, "names": names, "required": [0], "piece_bytes": piece_bytes}
    declared = None
    total = None  # rows in the file (the first pass counts them): the piece that reaches it is the last
    if piece_bytes is not None:
        others = list(range(1, len(names)))
        rows = [0]

        def times() -> Iterator[np.ndarray]:
            # counts the rows the second pass reads: a cut final row is dropped here too (its warning comes from there)
            for v, _ in iter_table(path, **table, skip_columns=others, warnings=[]):
                rows[0] += len(v)
                yield np.round(v[:, 0] * rate).astype(np.int64)

        declared = _declare_counters(path, hdr, sensors, times())
        total = rows[0]
    carry = _Counter()
    notes: list[str] = []
    for k, (values_table, _) in enumerate(iter_table(path, **table, warnings=notes)):
        # no look-ahead to learn which piece is last (it held the next piece's table and text while this one was
        # built and written): the whole file is one piece, else the first pass counted the rows
        last = total is None or carry.seen + len(values_table) >= total
        counter = np.round(values_table[:, 0] * rate).astype(np.int64)
        values = {s: values_table[:, [names.index(c) for c in CSV_SENSORS[s]]] for s in sensors}
        warnings: list[str] = []
        if last and hdr.get("n_samples") not in (None, carry.seen + len(counter)):
            warnings.append(
                f"{path.name}: header says {hdr['n_samples']} samples, the CSV holds {carry.seen + len(counter)}"
            )
        rec = _recording(path, hdr, counter, values, warnings, carry, last=last)
        rec.sources.append(str(hj))
        if "imulog.trial" in rec.metadata:  # the CSV's t starts at 0: the start is utc_start's second, as written
            rec.metadata["imulog.trial"] = trial_start(
                datetime.fromtimestamp(int(hdr["utc_start"]), tz=UTC), "NilsPodLib header JSON utc_start"
            )
        if declared is not None and k == 0:
            rec.metadata[PIECES_RECORD] = declared
        yield hand_over(notes, rec)
        del rec, values, values_table  # not held while the next piece is read and parsed


class NilsPodConverter(Converter):
    name = "nilspod"
    description = "NilsPod .bin session (fw >= 0.14) and NilsPodLib's _data.csv + _header.json: acc, gyro, baro, ..."
    extensions = (".bin", ".csv")
    example = "imulog convert ../shared/data/devices/nilspod/NilsPodX-6F13_20210109_162824.bin -o nilspod.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        p = Path(path)
        if p.suffix.lower() == ".csv":
            return 0.9 if head.startswith(b"t,") and header_json_for(p) is not None else 0.0
        if p.suffix.lower() != ".bin" or len(head) < 60 or not 49 <= head[0] <= 128:
            return 0.0
        size = head[0]
        if head[1] < 6 or head[4] not in RATES or not head[2] & 0xFF:
            return 0.0
        name_hint = p.name.lower().startswith("nilspod")
        return 0.9 if name_hint else (0.5 if (head[size - 3], head[size - 2]) >= (0, 14) else 0.0)

    def recording_key(self, path: Path) -> str | None:
        return Path(path).stem  # the .bin and NilsPodLib's _data.csv of it are two decodes, never one trial

    def export_of(self, path: Path) -> Path | None:
        """``X.bin`` beside NilsPodLib's ``X_data.csv`` (its ``data_as_csv`` export names), else None."""
        return export_source(path, r"(.*)_data", ".bin") if Path(path).suffix.lower() == ".csv" else None

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        if Path(path).suffix.lower() == ".csv":
            return read_csv(Path(path), options)
        return read_bin(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """A ``.bin`` session in pieces of :data:`PIECE_SAMPLES` samples (:func:`iter_bin`); NilsPodLib's CSV in
        pieces of :data:`imulog.converters._pieces.PIECE_BYTES` of text (:func:`iter_csv`)."""
        if Path(path).suffix.lower() == ".csv":
            from imulog.converters import _pieces

            return iter_csv(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)
        return iter_bin(Path(path), options, samples_per_piece=PIECE_SAMPLES)


CONVERTER = NilsPodConverter()
