"""Axivity AX3/AX6 CSV exports (OMGUI "Export raw CSV", ``cwa-convert -csv``, the files GGIR reads).

No header; one row per sample::

    1551178506.0100,0.828125,-0.359375,-0.375000                 (Unix time stamps, AX3)
    2019-02-26 10:55:06.010,0.828125,-0.359375,-0.375000          (formatted time stamps, AX3)
    2019-02-26 10:55:06.010,0.83,-0.36,-0.38,1.2,-3.4,0.5         (AX6: + gyroscope X, Y, Z)

Units as OMGUI writes them: accelerometer g, gyroscope deg/s. The time stamps are the device clock, which OMGUI
sets to the configuring computer's local time: the start is local time without a zone (as for ``.cwa``).
Formatted time stamps are ``YYYY-MM-DD hh:mm:ss.fff`` (OMGUI) or ISO ``T``-separated.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from imulog.converters import _pieces
from imulog.converters._binary import UNKNOWN_ZONE, iso_from_epoch_ns
from imulog.converters._common import G0, TableSpec, check_increasing, estimate_rate_hz, text_head_lines
from imulog.converters._pieces import NumericPiece, iter_numeric, text_column
from imulog.converters.base import Converter, ConvertOptions, export_source
from imulog.converters.delimited_time import StepCounts
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording

_UNIX = re.compile(r"^\d{9,10}(\.\d+)?$")
_FORMATTED = re.compile(r"^\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}:\d{2}(\.\d+)?$")
_NUMBER = re.compile(r"^[-+]?\d+(\.\d+)?([eE][-+]?\d+)?$")
MAX_G = 32.0  # AX3/AX6 ranges reach 16 g; a value beyond twice that is not an Axivity acceleration


def layout(lines: list[str]) -> tuple[str, int] | None:
    """("unix"|"formatted", number of value columns 3|6) when every line looks like an Axivity CSV row."""
    rows = [ln for ln in lines if ln.strip()]
    if len(rows) < 2:
        return None
    kind, width = None, None
    for ln in rows:
        cells = [c.strip() for c in ln.split(",")]
        if len(cells) not in (4, 7):
            return None
        k = "unix" if _UNIX.match(cells[0]) else "formatted" if _FORMATTED.match(cells[0]) else None
        if k is None or (kind and k != kind) or (width and len(cells) - 1 != width):
            return None
        if not all(_NUMBER.match(c) for c in cells[1:]):
            return None
        if any(abs(float(c)) > MAX_G for c in cells[1:4]):
            return None
        kind, width = k, len(cells) - 1
    assert kind is not None and width is not None
    return kind, width


def read_axivity_csv(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole export: :func:`iter_axivity_csv` as one piece."""
    (rec,) = iter_axivity_csv(path, options, piece_bytes=None)
    return rec


def iter_axivity_csv(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = None
) -> Iterator[Recording]:
    """The export in pieces of about ``piece_bytes`` of text (None: one piece), read by
    :func:`~imulog.converters._pieces.iter_numeric`; the rate is the median step over every piece."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(64 * 1024)
    lines = text_head_lines(head, 20) or []
    found = layout(lines[:-1] if len(lines) > 2 else lines)
    if found is None:
        raise ConversionError(path, "not an Axivity CSV export (time stamp then 3 or 6 numbers per row)", line=1)
    kind, width = found
    names = ["time"] + ["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"][:width]
    spec = TableSpec(path=path, delimiter=",", skip_lines=0, names=names, ignore={0} if kind == "formatted" else set())
    model = "AX6" if width == 6 else "AX3"
    name = "axivity"
    origin: int | None = None
    before: int | None = None
    steps = StepCounts()
    for piece in iter_numeric(spec, piece_bytes):
        values = piece.values
        epoch_ns = _epoch_ns(path, piece, kind)
        if origin is None:
            if len(epoch_ns) == 0:
                raise ConversionError(path, "no samples", line=1)
            origin = int(epoch_ns[0])
        t_ns = epoch_ns - origin
        check_increasing(path, t_ns, piece.first_line, "time", before)
        steps.add(np.diff(t_ns) if before is None else np.diff(np.concatenate([[before], t_ns])))
        before = int(t_ns[-1]) if len(t_ns) else before
        rate = steps.rate_hz() if steps.exact else estimate_rate_hz(t_ns)  # the last piece's: the whole file's
        meta = {
            "format": "axivity-csv",
            "model": model,
            "rate_hz": round(rate, 3) if rate else None,
            "time_stamps": "Unix seconds (device local clock)" if kind == "unix" else "formatted (device local clock)",
            "units": "accelerometer g, gyroscope deg/s (OMGUI)",
            "time_base": "ns from start_time (first row, device local time)",
            "source": path.name,
        }
        rec = Recording(sources=[str(path)], warnings=list(piece.warnings))
        rec.imus.append(
            ImuStream(
                name=name,
                t_ns=t_ns,
                acc=values[:, 1:4] * G0,
                gyr=np.radians(values[:, 4:7]) if width == 6 else None,
                # the text's decimals times the unit factor (imulog.archive.numbers): g and deg/s to SI, exactly
                meta={**meta, "resolution": {"acc": {"scale": G0}, "gyr": {"scale": np.pi / 180.0}}},
            )
        )
        rec.metadata[f"imulog.device.{name}"] = meta
        rec.metadata["imulog.trial"] = {"start_time": iso_from_epoch_ns(origin), "time_zone": UNKNOWN_ZONE}
        yield rec


def _epoch_ns(path: Path, piece: NumericPiece, kind: str) -> np.ndarray:
    """The piece's time stamps as ns since 1970 (device local clock); one line naming a bad formatted cell."""
    if kind == "unix":
        # float64 keeps 0.1 us at 1.5e9 s; round to whole microseconds as OMGUI writes at most 4-6 decimals
        return np.round(piece.values[:, 0] * 1e6).astype(np.int64) * 1000
    import pandas as pd

    cells = text_column(piece, 0)
    parsed = pd.to_datetime(cells.str.strip(), format="ISO8601", errors="coerce")
    if parsed.isna().any():
        bad = int(np.nonzero(parsed.isna().to_numpy())[0][0])
        raise ConversionError(
            path, f"{cells.iloc[bad][:30]!r} is not a time stamp", line=piece.first_line + bad, column="time"
        )
    return parsed.to_numpy().astype("datetime64[ns]").astype(np.int64)


class AxivityCsvConverter(Converter):
    name = "axivity-csv"
    description = "Axivity AX3/AX6 CSV export (OMGUI/GGIR: time stamp, acc g [, gyro deg/s]; no header)"
    extensions = (".csv",)
    example = "imulog convert ../shared/data/devices/axivity_csv/ax3_testfile_unix_timestamps.csv -o ax3csv.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 30)
        if not lines:
            return 0.0
        return 0.7 if layout(lines[:-1] if len(lines) > 2 else lines) else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def export_of(self, path: Path) -> Path | None:
        """``X.cwa`` beside OMGUI's raw CSV export of it, ``X.csv`` (OMGUI names the export after the ``.cwa``:
        same folder, same stem; ``CWA-DATA.CWA`` as the device writes it, too); else None."""
        return export_source(path, r"(.+)", (".cwa", ".CWA"))

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_axivity_csv(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MB of text (see :func:`iter_axivity_csv`)."""
        return iter_axivity_csv(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = AxivityCsvConverter()
