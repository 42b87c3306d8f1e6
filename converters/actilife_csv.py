"""ActiLife CSV exports of ActiGraph raw data (the ``RAW`` accelerometer file and the ``IMU`` file).

Layout: a 10-line banner, then a names row, then one row per sample::

    ------------ Data File Created By ActiGraph GT3X+ ActiLife v6.13.3 Firmware v1.7.2 date format M/d/yyyy at 90 Hz ...
    Serial Number: TAS1E31150129
    Start Time 08:58:00
    Start Date 2/14/2019
    Epoch Period (hh:mm:ss) 00:00:00
    Download Time 09:03:03
    Download Date 2/14/2019
    Current Memory Address: 0
    Current Battery Voltage: 4.15     Mode = 12
    --------------------------------------------------
    Accelerometer X,Accelerometer Y,Accelerometer Z            (RAW: no time column)
    Timestamp,Accelerometer X,...,Temperature,Gyroscope X,...,Magnetometer X,...   (IMU file)

Banner lines may carry padding commas. Units as ActiLife writes them: accelerometer g, gyroscope deg/s, magnetometer
uT, temperature degC. Time: the ``Timestamp`` column (local ISO time) when present, else ``Start Date`` +
``Start Time`` + row / rate (the banner's ``at N Hz``). The start is local time without a zone. Streams are named as
the .gt3x converter names them: ``/imu/<serial>`` (RAW), ``/imu/<serial>_imu`` (IMU file). Epoch (count) exports
(``Epoch Period`` other than 00:00:00) are read by :mod:`imulog.converters.actilife_epoch` as epoch signals.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path

import numpy as np
from imulog.converters import _pieces
from imulog.converters._binary import UNKNOWN_ZONE
from imulog.converters._common import G0, TableSpec, head_lines, sanitize_name, text_head_lines
from imulog.converters._pieces import NumericPiece, iter_numeric, text_column
from imulog.converters.actilife_epoch import (
    EPOCH_PIECE_BYTES,
    bannerless_banner,
    is_bannerless,
    iter_epoch_csv,
    strptime_format,
)
from imulog.converters.base import Converter, ConvertOptions, export_source
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording, SignalStream

BANNER_LINES = 10
BANNER_START = "------------ Data File Created By ActiGraph"
# ActiLife's banner, and the Actigraph Link's epoch export: "------------ Data Table File Created By Actigraph Link"
BANNER = re.compile(r"^-+ Data (?:Table )?File Created By ActiGraph", re.IGNORECASE)
TRIOS = {"acc": "Accelerometer", "gyr": "Gyroscope", "mag": "Magnetometer"}


def _field(path: Path, lines: list[str], pattern: str, what: str, line_hint: int) -> re.Match:
    for line in lines[:BANNER_LINES]:
        m = re.search(pattern, line)
        if m:
            return m
    raise ConversionError(path, f"ActiLife banner has no {what}", line=line_hint)


def parse_banner(path: Path, lines: list[str]) -> dict:
    """Rate (Hz), serial, device line, local start (datetime), date format and epoch period from the banner."""
    if len(lines) < BANNER_LINES + 1 or not BANNER.match(lines[0]):
        raise ConversionError(path, "not an ActiLife CSV export (no 'Data File Created By ActiGraph' banner)", line=1)
    epoch = _field(path, lines, r"Epoch Period \(hh:mm:ss\)\s+(\d{2}:\d{2}:\d{2})", "Epoch Period", 5).group(1)
    rate_m = re.search(r" at (\d+(?:\.\d+)?) Hz", lines[0])
    if rate_m is None and epoch == "00:00:00":
        raise ConversionError(path, "ActiLife banner of a raw export has no 'at N Hz'", line=1)
    rate = float(rate_m.group(1)) if rate_m else None
    fmt = _field(path, lines, r"date format (\S+)", "'date format'", 1).group(1)
    serial = _field(path, lines, r"Serial Number:\s*([^,\s]+)", "Serial Number", 2).group(1)
    start_time = _field(path, lines, r"Start Time\s+(\d{1,2}:\d{2}:\d{2})", "Start Time", 3).group(1)
    start_date = _field(path, lines, r"Start Date\s+([\d/.\-]+)", "Start Date", 4).group(1)
    py_fmt = strptime_format(fmt)
    try:
        start = datetime.strptime(f"{start_date} {start_time}", f"{py_fmt} %H:%M:%S")
    except ValueError:
        if epoch == "00:00:00":
            raise ConversionError(path, f"Start Date {start_date!r} does not match date format {fmt}", line=4) from None
        start = None  # an epoch export may still date itself by its rows (the Link writes M-d-yyyy under dd/MM/yyyy)
    device = re.search(r"Created By (.+?) ActiLife", lines[0])
    return {
        "rate_hz": rate,
        "serial": serial,
        "start": start,
        "epoch": epoch,
        "device": device.group(1).strip() if device else "ActiGraph",
        "date_format": fmt,
        "start_text": f"{start_date} {start_time}",
    }


def _check_complete(path: Path) -> None:
    """ActiLife ends every row with a line break: a file that does not was cut inside its last row."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        f.seek(max(0, size - 1))
        last = f.read(1)
    if last not in (b"\n", b"\r"):
        with open(path, "rb") as f:
            lines = sum(block.count(b"\n") for block in iter(lambda: f.read(1 << 20), b"")) + 1
        raise ConversionError(
            path,
            "the file ends inside a row (truncated copy?); if the row is complete, end it with a line break",
            line=lines,
        )


def read_actilife_csv(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole export: :func:`iter_actilife_csv` as one piece."""
    (rec,) = iter_actilife_csv(path, options, piece_bytes=None)
    return rec


def iter_actilife_csv(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = None
) -> Iterator[Recording]:
    """A raw (RAW or IMU) export in pieces of about ``piece_bytes`` of text (None: one piece), read by
    :func:`~imulog.converters._pieces.iter_numeric`; epoch (count) exports likewise
    (:func:`~imulog.converters.actilife_epoch.iter_epoch_csv`)."""
    options = options or ConvertOptions()
    path = Path(path)
    lines = head_lines(path, max_lines=BANNER_LINES + 2)
    if is_bannerless(lines):
        yield from iter_epoch_csv(
            path, lines, bannerless_banner(path, lines), options, banner_lines=0, piece_bytes=piece_bytes
        )
        return
    banner = parse_banner(path, lines)
    if banner["epoch"] != "00:00:00":
        yield from iter_epoch_csv(path, lines, banner, options, piece_bytes=piece_bytes)
        return
    names_row = [c.strip() for c in lines[BANNER_LINES].split(",")]
    while names_row and not names_row[-1]:
        names_row.pop()
    has_time = bool(names_row) and names_row[0].lower() == "timestamp"
    cols = names_row[1:] if has_time else names_row
    if not cols or f"{TRIOS['acc']} X" not in cols:
        raise ConversionError(path, "names row has no 'Accelerometer X' column", line=BANNER_LINES + 1)
    spec_names = (["Timestamp"] if has_time else []) + cols
    spec = TableSpec(
        path=path,
        delimiter=",",
        skip_lines=BANNER_LINES + 1,
        names=spec_names,
        ignore={0} if has_time else set(),
    )
    _check_complete(path)
    serial = banner["serial"]
    names_map = {str(k).upper(): v for k, v in (options.extra.get("names") or {}).items()}
    base = sanitize_name(names_map.get(serial.upper(), serial))
    index = {c: i for i, c in enumerate(cols)}
    is_imu = all(f"{TRIOS['gyr']} {a}" in index for a in "XYZ") or "IMU" in banner["device"]
    name = f"{base}_imu" if is_imu else base
    meta = {
        "format": "actilife-csv",
        "model": banner["device"],
        "serial": serial,
        "rate_hz": banner["rate_hz"],
        "units": "accelerometer g, gyroscope deg/s, magnetometer uT, temperature degC (ActiLife)",
        "time_base": "ns from start_time (banner Start Date/Time, device local time)",
        "source": path.name,
    }
    first_row, before = 0, None
    for piece in iter_numeric(spec, piece_bytes):
        values = piece.values
        if has_time:
            values = values[:, 1:]
            t_ns = _stamps_ns(path, piece, banner["start"])
            d = np.diff(t_ns if before is None else np.concatenate([[before], t_ns]))
            bad = np.flatnonzero(d <= 0)
            if len(bad):
                row = int(bad[0]) + (1 if before is None else 0)
                raise ConversionError(
                    path, "time stamp does not increase", line=piece.first_line + row, column="Timestamp"
                )
            before = int(t_ns[-1]) if len(t_ns) else before
        else:
            rows = np.arange(first_row, first_row + len(values))
            t_ns = np.round(rows * (1e9 / banner["rate_hz"])).astype(np.int64)
        first_row += len(values)
        yield _recording(path, name, cols, index, values, t_ns, meta, banner, piece.warnings)


def _stamps_ns(path: Path, piece: NumericPiece, start: datetime) -> np.ndarray:
    """The piece's ``Timestamp`` cells (local ISO time) as ns from the banner's start; one line naming a bad cell."""
    import pandas as pd  # here, not at module top: detecting a format must not import pandas

    stamps = text_column(piece, 0)
    try:
        t_abs = pd.to_datetime(stamps, format="ISO8601").to_numpy().astype("datetime64[ns]")
    except (ValueError, TypeError):
        bad = next((i for i, s in enumerate(stamps) if pd.isna(pd.to_datetime(s, errors="coerce"))), 0)
        raise ConversionError(
            path,
            f"{str(stamps.iloc[bad])[:30]!r} is not a time stamp",
            line=piece.first_line + bad,
            column="Timestamp",
        ) from None
    return (t_abs - np.datetime64(start, "ns")).astype(np.int64)


def _recording(
    path: Path,
    name: str,
    cols: list[str],
    index: dict[str, int],
    values: np.ndarray,
    t_ns: np.ndarray,
    meta: dict,
    banner: dict,
    warnings: list[str],
) -> Recording:
    """The IMU stream (SI units) and the other columns of one piece's ``values``."""

    def trio(prefix: str) -> np.ndarray | None:
        names = [f"{prefix} {a}" for a in "XYZ"]
        return values[:, [index[n] for n in names]] if all(n in index for n in names) else None

    acc, gyr, mag = trio(TRIOS["acc"]), trio(TRIOS["gyr"]), trio(TRIOS["mag"])
    temp = values[:, index["Temperature"]] if "Temperature" in index else None
    rec = Recording(sources=[str(path)], warnings=list(warnings))
    rec.imus.append(
        ImuStream(
            name=name,
            t_ns=t_ns,
            acc=None if acc is None else acc * G0,
            gyr=None if gyr is None else np.radians(gyr),
            mag=mag,
            temperature=temp,
            meta=dict(meta),
        )
    )
    known = {f"{p} {a}" for p in TRIOS.values() for a in "XYZ"} | {"Temperature"}
    extra = [c for c in cols if c not in known]
    if extra:
        rec.signals.append(
            SignalStream(
                topic=f"/signals/{name}",
                t_ns=t_ns,
                columns=[sanitize_name(c) for c in extra],
                units=[""] * len(extra),
                values=values[:, [index[c] for c in extra]],
            )
        )
    rec.metadata[f"imulog.device.{name}"] = dict(meta)
    rec.metadata["imulog.trial"] = {
        "start_time": banner["start"].isoformat(timespec="milliseconds"),
        "time_zone": UNKNOWN_ZONE,
    }
    return rec


class ActiLifeCsvConverter(Converter):
    name = "actilife-csv"
    description = (
        "ActiLife CSV export of ActiGraph data (RAW accel or IMU file: g, deg/s, uT; epoch count file: counts, "
        "steps, lux, inclinometer per epoch)"
    )
    extensions = (".csv",)
    example = "imulog convert ../shared/data/devices/actigraph_gt3x/example-IMU.csv -o actilife.mcap"
    #: an epoch export is one archive message per row: a 15-MB file of 1-s epochs converted whole peaked at 0.7 GB
    stream_min_bytes = EPOCH_PIECE_BYTES

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 2)
        if lines and BANNER.match(lines[0]):
            return 0.97
        return 0.8 if lines and is_bannerless(lines) else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def export_of(self, path: Path) -> Path | None:
        """``X.gt3x`` beside ActiLife's exports of it, ``XRAW.csv`` (raw accelerometer) and ``X-IMU.csv`` (the
        IMU file), as ActiLife names them; else None."""
        return export_source(path, r"(.+?)(?:RAW|-IMU)", ".gt3x")

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_actilife_csv(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Raw exports in pieces of about 16 MB of text (see :func:`iter_actilife_csv`)."""
        return iter_actilife_csv(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = ActiLifeCsvConverter()
