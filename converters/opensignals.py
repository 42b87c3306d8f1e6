"""OpenSignals (PLUX: BITalino, biosignalsplux) text files with their JSON header.

Layout (tab-separated)::

    # OpenSignals Text File Format
    # {"00:07:80:3B:46:61": {"device": "bitalino_rev", "sampling rate": 1000, "column": ["nSeq", "I1", "I2",
    #   "O1", "O2", "A1", "A2"], "label": ["A1", "A2"], "sensor": ["EMG", "ECG"], "resolution": [4, 1, 1, 1, 1,
    #   10, 10], "date": "2017-1-20", "time": "14:40:49.587", ...}}
    # EndOfHeader
    0	0	0	0	0	507	511

One JSON object per device (several devices: their columns follow each other in header order). Every column is
kept as found (ADC counts) in ``/signals/<device>``; analog channels whose sensor has a published BITalino transfer
function are also given in physical units in ``/analog/<device>`` (PLUX datasheets, ``VCC`` = 3.3 V, ``n`` = the
channel's resolution in bits): EMG V = (ADC/2^n - 1/2) x VCC / 1009, ECG V = (ADC/2^n - 1/2) x VCC / 1100,
EDA uS = (ADC/2^n) x VCC / 0.132. Accelerometer channels need the device's own calibration (Cmin, Cmax), which the
file does not hold: they stay counts, and a warning says so. Other PLUX devices (biosignalsplux) use other gains:
their channels stay counts. Time: row / ``sampling rate`` (``nSeq`` is a 4-bit counter that only shows lost
samples: a jump other than +1 mod 16 is reported; the ``.h5`` files' uint16 copy counts up and stays at 65535,
which is not a loss); ``date`` + ``time`` (the acquiring PC's local time, with or without milliseconds) is the
start.

Memory: in pieces of text cut after whole rows (:func:`iter_opensignals`); the whole file is the one-piece case.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path

import numpy as np
from imulog.converters import _pieces
from imulog.converters._binary import UNKNOWN_ZONE
from imulog.converters._common import sanitize_name, text_head_lines
from imulog.converters._pieces import text_pieces
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import AnalogStream, Recording, SignalStream

MAGIC = "# OpenSignals Text File Format"
END = "# EndOfHeader"
VCC = 3.3  # V, BITalino supply
NSEQ_H5_MAX = 65535  # OpenSignals .h5 stores nSeq as uint16 counting up from its start and stopping at 65535
TRANSFER = {  # sensor -> (unit, function of (adc, bits))
    "EMG": ("V", lambda a, n: (a / 2.0**n - 0.5) * VCC / 1009.0),
    "ECG": ("V", lambda a, n: (a / 2.0**n - 0.5) * VCC / 1100.0),
    "EDA": ("uS", lambda a, n: (a / 2.0**n) * VCC / 0.132),
}


def parse_header(path: Path, lines: list[str]) -> tuple[list[tuple[str, dict]], int]:
    """([(device key, its header object)], number of header lines)."""
    if not lines or not lines[0].startswith(MAGIC):
        raise ConversionError(path, "not an OpenSignals text file (no '# OpenSignals Text File Format')", line=1)
    end = next((i for i, line in enumerate(lines[:10]) if line.strip() == END), None)
    if end is None or end < 2:
        raise ConversionError(path, "no '# EndOfHeader' line after the JSON header", line=2)
    try:
        doc = json.loads(lines[1].lstrip("#").strip())
    except json.JSONDecodeError as e:
        raise ConversionError(path, f"the JSON header does not parse: {e.msg} (column {e.colno})", line=2) from None
    if not isinstance(doc, dict) or not doc or not all(isinstance(v, dict) for v in doc.values()):
        raise ConversionError(path, "the JSON header is not one object per device", line=2)
    return list(doc.items()), end + 1


def _device_columns(path: Path, key: str, dev: dict) -> tuple[list[str], list[int], float]:
    cols = dev.get("column")
    rate = dev.get("sampling rate")
    if not isinstance(cols, list) or not cols:
        raise ConversionError(path, f"device {key}: no 'column' list in the header", line=2)
    if not isinstance(rate, int | float) or isinstance(rate, bool) or not 0 < rate <= 1e6:
        raise ConversionError(path, f"device {key}: 'sampling rate' {rate!r} is not a rate in Hz", line=2)
    res = dev.get("resolution") or []
    bits = [int(r) if isinstance(r, int | float) else 0 for r in res] + [0] * (len(cols) - len(res))
    return [str(c) for c in cols], bits[: len(cols)], float(rate)


def _read_block(
    path: Path, skip: int, names: list[str], data: bytes | None = None, last: bool = True
) -> tuple[np.ndarray, list[str]]:
    """The tab-separated integer block (OpenSignals ends each row with a tab); a bad cell names its line.

    ``data``: the rows of one piece of the file, after ``skip`` lines (None: the file's rows after its header);
    only the file's last row (``last``: the piece ends the file) may be cut short."""
    import io

    import pandas as pd

    try:
        df = pd.read_csv(
            path if data is None else io.BytesIO(data),
            sep="\t",
            header=None,
            skiprows=skip if data is None else 0,
            usecols=range(len(names)),
            dtype=str,
            engine="c",
            skip_blank_lines=False,
            keep_default_na=False,
        )
    except (ValueError, pd.errors.ParserError) as e:
        raise ConversionError(
            path, f"data rows do not have {len(names)} tab-separated fields: {str(e)[:120]}"
        ) from None
    except pd.errors.EmptyDataError:
        raise ConversionError(path, "no samples after the header", line=skip + 1) from None
    warnings: list[str] = []
    values = df.apply(pd.to_numeric, errors="coerce").to_numpy(dtype=np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = (int(x[0]) for x in np.nonzero(bad))
        if row == len(values) - 1 and last:  # only the last row is damaged: a copy cut short
            warnings.append(f"{path.name}: line {skip + 1 + row}: last row cut short: dropped")
            return values[:row], warnings
        cell = df.iat[row, col]
        raise ConversionError(path, f"{cell[:30]!r} is not a number", line=skip + 1 + row, column=names[col])
    return values, warnings


class _SeqCarry:
    """A device's ``nSeq`` across pieces: its last value, how many rows it jumped at and the first such line."""

    def __init__(self) -> None:
        self.last: float | None = None
        self.jumps = 0
        self.first: str | None = None  # where the first jump is: "line N" (text) or "sample N" (.h5)


def device_streams(
    rec: Recording,
    path: Path,
    key: str,
    dev: dict,
    cols: list[str],
    bits: list[int],
    rate: float,
    block: np.ndarray,
    first_line: int | None,
    fmt: str = "opensignals-txt",
    *,
    first_row: int = 0,
    seq: _SeqCarry | None = None,
    last: bool = True,
) -> None:
    """Add one device's streams (counts; BITalino physical units), metadata and start time to ``rec``.

    ``first_line``: the text line of the first sample (for the lost-sample warning), None for ``.h5``. For a piece
    of the file: ``first_row`` its first sample's index, ``seq`` the device's ``nSeq`` so far, ``last`` whether it
    ends the file (the warnings, about the whole recording, come with the last piece)."""
    if not 0 < rate <= 1e6:
        raise ConversionError(path, f"device {key}: 'sampling rate' {rate!r} is not a rate in Hz")
    seq = _SeqCarry() if seq is None else seq
    name = sanitize_name(f"opensignals_{key}")
    t_ns = np.round(np.arange(first_row, first_row + len(block)) * (1e9 / rate)).astype(np.int64)
    if "nSeq" in cols and len(block):
        col = block[:, cols.index("nSeq")]
        full = col if seq.last is None else np.concatenate([[seq.last], col])
        stuck = (full[:-1] >= NSEQ_H5_MAX) & (full[1:] >= NSEQ_H5_MAX)  # an .h5 counter stays at 65535 once there
        jumps = np.nonzero(((np.diff(full) % 16) != 1) & ~stuck)[0]
        if len(jumps) and seq.first is None:
            row = first_row + int(jumps[0]) + (0 if seq.last is None else -1)  # the row before the jump
            seq.first = f"line {first_line - first_row + 1 + row}" if first_line is not None else f"sample {row + 1}"
        seq.jumps += len(jumps)
        seq.last = float(col[-1])
    if last and seq.jumps:
        rec.warnings.append(
            f"{path.name}: device {key}: nSeq jumps at {seq.jumps} row(s) (first {seq.first}): "
            "samples were lost there; times assume none were"
        )
    rec.signals.append(
        SignalStream(
            topic=f"/signals/{name}",
            t_ns=t_ns,
            columns=[sanitize_name(c) for c in cols],
            units=["counts"] * len(cols),
            values=block,
        )
    )
    analog = [c for c in cols if c.startswith("A")]
    sensors = dev.get("sensor") or []
    labels = dev.get("label") or analog
    kind = str(dev.get("device", "")).lower()
    conv_names, conv_units, conv_vals, raw_acc = [], [], [], []
    for k, c in enumerate(analog):
        sensor = str(sensors[k]).upper() if k < len(sensors) else ""
        i = cols.index(c)
        if kind.startswith("bitalino") and sensor in TRANSFER and bits[i] > 0:
            unit, fn = TRANSFER[sensor]
            conv_names.append(sanitize_name(f"{labels[k] if k < len(labels) else c}_{sensor}"))
            conv_units.append(unit)
            conv_vals.append(fn(block[:, i], bits[i]))
        elif sensor in ("ACC", "XYZ"):
            raw_acc.append(c)
    if conv_vals:
        rec.analogs.append(
            AnalogStream(
                name=name, t_ns=t_ns, channel_names=conv_names, units=conv_units, values=np.column_stack(conv_vals)
            )
        )
    if raw_acc and last:
        rec.warnings.append(
            f"{path.name}: device {key}: accelerometer channel(s) {', '.join(raw_acc)} kept as ADC counts: the "
            "file has no calibration (Cmin/Cmax) to convert them to g"
        )
    rec.metadata[f"imulog.device.{name}"] = {
        "format": fmt,
        "model": dev.get("device", ""),
        "serial": key,
        "rate_hz": rate,
        "firmware": dev.get("firmware version"),
        "sensors": dict(zip(analog, [str(s) for s in sensors], strict=False)),
        "resolution_bits": dict(zip(cols, bits, strict=True)),
        "transfer": "PLUX BITalino datasheets (VCC 3.3 V)" if conv_vals else "none (counts)",
        "source": path.name,
    }
    if "imulog.trial" not in rec.metadata and dev.get("date") and dev.get("time"):
        start = None
        for fmt_time in ("%H:%M:%S.%f", "%H:%M:%S"):  # .h5 headers often give whole seconds
            try:
                start = datetime.strptime(f"{dev['date']} {dev['time']}", f"%Y-%m-%d {fmt_time}")
                break
            except ValueError:
                continue
        if start is None:
            if last:
                rec.warnings.append(f"{path.name}: date/time {dev['date']!r} {dev['time']!r} not understood")
            return
        rec.metadata["imulog.trial"] = {
            "start_time": start.isoformat(timespec="milliseconds"),
            "time_zone": UNKNOWN_ZONE,
            "start_time_source": "OpenSignals header date + time (acquiring PC's local time)",
        }


def read_opensignals(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file: :func:`iter_opensignals` as one piece."""
    (rec,) = iter_opensignals(path, options, piece_bytes=None)
    return rec


def iter_opensignals(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = None
) -> Iterator[Recording]:
    """The recording in pieces of about ``piece_bytes`` of text cut after whole rows (None: one piece); the
    warnings about the whole recording (lost samples, counts kept) come with the last piece."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(256 * 1024)
    lines = text_head_lines(head, 12) or []
    devices, skip = parse_header(path, lines)
    layout = [(key, dev, *_device_columns(path, key, dev)) for key, dev in devices]
    names = [f"{key}:{c}" for key, _, cols, _, _ in layout for c in cols]
    carries = {key: _SeqCarry() for key, *_ in layout}
    pieces = iter([(None, skip, 0, True)]) if piece_bytes is None else text_pieces(path, skip, piece_bytes)
    first_row = 0
    for data, lines_before, k, last in pieces:
        if data is not None and k and last and not data.strip():
            continue  # nothing but blank lines after the previous piece
        values, warnings = _read_block(path, lines_before, names, data, last)
        if first_row == 0 and len(values) == 0:
            raise ConversionError(path, "no samples after the header", line=skip + 1)
        rec = Recording(sources=[str(path)], warnings=warnings)
        offset = 0
        for key, dev, cols, bits, rate in layout:
            block = values[:, offset : offset + len(cols)]
            offset += len(cols)
            device_streams(
                rec,
                path,
                key,
                dev,
                cols,
                bits,
                rate,
                block,
                first_line=lines_before + 1,
                first_row=first_row,
                seq=carries[key],
                last=last,
            )
        first_row += len(values)
        yield rec


class OpenSignalsConverter(Converter):
    name = "opensignals"
    description = "OpenSignals/BITalino text (.txt with JSON header): counts, EMG/ECG V and EDA uS for BITalino"
    extensions = (".txt",)
    example = "imulog convert opensignals_000780.txt -o bitalino.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 3)
        if not lines or not lines[0].startswith(MAGIC) or len(lines) < 2:
            return 0.0
        try:
            doc = json.loads(lines[1].lstrip("#").strip())
        except json.JSONDecodeError:
            return 0.0
        return 0.95 if isinstance(doc, dict) else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_opensignals(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MB of text (see :func:`iter_opensignals`)."""
        return iter_opensignals(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = OpenSignalsConverter()
