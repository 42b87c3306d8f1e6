"""Shimmer CSV exports with four header rows (ShimmerCapture, Consensys "Raw/Cal in separate rows").

Layout (comma, tab or the ``sep=`` line's delimiter)::

    "sep=,"                                                        (optional)
    Shimmer_8E5E,Shimmer_8E5E,Shimmer_8E5E,...                     device (one per column)
    Timestamp,Low Noise Accelerometer X,...,Gyroscope X,...        signal names
    CAL,CAL,CAL,...                                                RAW / CAL (uncalibrated / calibrated)
    mSecs,m/(sec^2),...,deg/sec,...,local,...                      units
    12.00,0.12,...

(the one-row Consensys layout, ``"sep=;"`` then ``Shimmer_40AC_Accel_LN_X_CAL`` names and a units row, is read by
the ``delimited`` converter). The four rows are read as one names row ``Shimmer_<device>_<signal>_<CAL|RAW>`` and
one units row, then the numeric block goes through the delimited reader, so values, gaps and errors are the same.
Signal names of ShimmerCapture are given their Consensys short forms (``Low Noise Accelerometer`` -> ``Accel_LN``,
``Wide Range Accelerometer`` -> ``Accel_WR``, ``Gyroscope`` -> ``Gyro``, ``Magnetometer`` -> ``Mag``): the first
accelerometer variant is the IMU's, the other is kept in the signals. Units as Shimmer writes them (``mSecs``,
``m/(sec^2)``, ``deg/sec``, ``local`` = normalised field, ``mVolts``, ``uSiemens``...). ``RAW`` columns are ADC counts
without calibration: kept as signals, never as IMU data (export calibrated data for SI units). Time: the
calibrated ``Timestamp`` (the Shimmer's clock, ms); a ``Timestamp_Unix``/``System Timestamp`` column (host Unix ms)
dates the trial (UTC).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

from imulog.converters import _pieces
from imulog.converters._common import head_lines, is_number, read_head, split_row, text_head_lines, unit_overrides
from imulog.converters._pieces import PIECE_BYTES
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.delimited import detect_delimiter, iter_delimited
from imulog.converters.errors import ConversionError
from imulog.converters.mapping import load_mapping, sibling_mapping

from imulog.model import Recording

_SEP = re.compile(r'^\s*"?sep=(.)"?\s*$')
FLAGS = {"CAL", "RAW", "UNCAL"}
LONG_NAMES = (
    ("low noise accelerometer", "Accel_LN"),
    ("wide range accelerometer", "Accel_WR"),
    ("accelerometer", "Accel"),
    ("gyroscope", "Gyro"),
    ("magnetometer", "Mag"),
    ("system timestamp", "System_Timestamp"),
)
UNITS = {
    "msecs": "ms",
    "msec": "ms",
    "secs": "s",
    "local": "local_flux",
    "no units": "no_units",
    "mvolts": "mV",
    "volts": "V",
    "usiemens": "uS",
    "kohms": "kOhms",
    "degrees celsius": "degC",
    "deg c": "degC",
    "m/(sec^2)": "m/(s^2)",
    "deg/sec": "deg/s",
}


def header(lines: list[str]) -> tuple[int, str, list[list[str]]] | None:
    """(index of the device row, delimiter, [device, signal, flag, unit] rows) of a four-row Shimmer header."""
    start, delimiter = 0, None
    if lines and (m := _SEP.match(lines[0])):
        start, delimiter = 1, m.group(1)
    if len(lines) < start + 5:
        return None
    delimiter = delimiter or detect_delimiter(lines[start + 2])
    if delimiter is None:
        return None
    rows = [split_row(lines[start + k], delimiter) for k in range(4)]
    for r in rows:
        while r and not r[-1]:
            r.pop()  # Shimmer ends every row with a delimiter
    width = len(rows[1])
    if width < 2 or any(len(r) != width for r in rows):
        return None
    flags = {c.upper() for c in rows[2] if c}
    if not flags or not flags <= FLAGS:
        return None
    if any(is_number(c) for r in rows for c in r if c):
        return None
    return start, delimiter, rows


def signal_name(name: str) -> str:
    """ShimmerCapture's long signal name in Consensys short form, as one underscore-joined token string."""
    text = name.strip()
    for long, short in LONG_NAMES:
        if text.lower().startswith(long):
            text = short + text[len(long) :]
            break
    return re.sub(r"\s+", "_", text.strip()).strip("_")


def device_label(label: str) -> str:
    """``Shimmer_8E5E`` stays; any other device label becomes ``Shimmer_<label>`` (letters and digits only)."""
    m = re.match(r"^Shimmer_([0-9A-Za-z]+)", label.strip())
    tail = m.group(1) if m else re.sub(r"[^0-9A-Za-z]", "", label) or "device"
    return f"Shimmer_{tail}"


def normalised_lines(lines: list[str], found: tuple[int, str, list[list[str]]]) -> tuple[list[str], set[int]]:
    """The file's first lines with the four header rows as one names row and one units row (same line count:
    two blank lines stand for the device and flag rows), and the indexes of the RAW columns."""
    start, delimiter, (devices, signals, flags, units) = found
    names, unit_cells, raw = [], [], set()
    for i, sig in enumerate(signals):
        flag = flags[i].upper() or "CAL"
        names.append(f"{device_label(devices[i] or devices[0])}_{signal_name(sig)}_{flag}" if sig else "")
        u = units[i].strip()
        unit_cells.append(UNITS.get(u.lower(), u))
        if flag in ("RAW", "UNCAL"):
            raw.add(i)
    pad = [""] * (len(split_row(lines[start + 1], delimiter)) - len(names))  # a trailing delimiter stays one
    out = list(lines[:start]) + ["", "", delimiter.join(names + pad), delimiter.join(unit_cells + pad)]
    return out + list(lines[start + 4 :]), raw


def read_shimmer(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file: :func:`iter_shimmer` as one piece."""
    (rec,) = iter_shimmer(path, options, piece_bytes=None)
    return rec


def iter_shimmer(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """The recording in pieces of about ``piece_bytes`` of text (None: one piece), read by
    :func:`~imulog.converters.delimited.iter_delimited` with the four header rows as a names and a units row."""
    options = options or ConvertOptions()
    path = Path(path)
    head = read_head(path)
    lines = head_lines(path, head)
    found = header(lines)
    if found is None:
        raise ConversionError(path, "not a four-row Shimmer header (device, signal, RAW/CAL, units rows)", line=1)
    norm, raw = normalised_lines(lines, found)
    flags = found[2][2]
    mapping_path = options.mapping or sibling_mapping(path)
    pieces = iter_delimited(
        path,
        mapping=load_mapping(mapping_path) if mapping_path else None,
        rate_hz=options.rate_hz,
        head=head,
        units=unit_overrides(options.extra),
        header_lines=norm,
        raw=raw,
        fmt="shimmer-csv",
        piece_bytes=piece_bytes,
    )
    first = True
    while True:
        try:
            rec = next(pieces, None)
        except ConversionError as e:
            if "no time column" in e.problem and raw:
                raise ConversionError(
                    path,
                    "uncalibrated (RAW) Shimmer export: its Timestamp is clock ticks, not time; export calibrated "
                    "(CAL) data from Consensys/ShimmerCapture, or give --rate",
                ) from None
            raise
        if rec is None:
            return
        if first and raw and not rec.imus:
            rec.warnings.append(
                f"{path.name}: uncalibrated (RAW) Shimmer export: {len(raw)} columns kept as ADC counts in the "
                "signals, no IMU stream (export calibrated data for SI units)"
            )
        elif first and raw and len(raw) < len([f for f in flags if f]):
            rec.warnings.append(f"{path.name}: {len(raw)} RAW (uncalibrated) columns kept as counts in the signals")
        for name, meta in rec.metadata.items():
            if name.startswith("imulog.device."):
                meta["layout"] = "four header rows (device, signal, RAW/CAL, units)"
        first = False
        yield rec


class ShimmerConverter(Converter):
    name = "shimmer-csv"
    description = "Shimmer CSV with four header rows (ShimmerCapture/Consensys: device, signal, RAW/CAL, units)"
    extensions = (".csv", ".txt")
    example = "imulog convert shimmer_capture.csv -o shimmer.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 8)
        return 0.9 if lines and header(lines) else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_shimmer(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MB of text (see :func:`iter_shimmer`)."""
        return iter_shimmer(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = ShimmerConverter()
