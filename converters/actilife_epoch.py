"""ActiLife epoch (activity count) CSV exports: counts per epoch and axis, steps, lux, inclinometer.

Same 10-line banner as the raw export (see :mod:`imulog.converters.actilife_csv`) with ``Epoch Period (hh:mm:ss)``
other than ``00:00:00`` and no ``at N Hz``. Then, as ActiLife writes it (and GGIRread's ``readActiGraphCount``
reads it), either a names row::

    Date,Time,Axis1,Axis2,Axis3,Steps,Lux,Inclinometer Off,Inclinometer Standing,Inclinometer Sitting,
    Inclinometer Lying,Vector Magnitude

(``Date``/``Time`` optional, any subset of the rest) or no names row, the columns then being in ActiLife's fixed
order ``Axis1, Axis2, Axis3, Steps, Lux, Inclinometer Off, Standing, Sitting, Lying`` (as many as there are).
Axis1 is the vertical axis (the device's Y), Axis2 horizontal (X), Axis3 perpendicular (Z).

Each row is one epoch: it becomes one sample of the signal stream ``/signals/<serial>_counts`` at the epoch's
start (``Start Date``/``Start Time`` + row x epoch, or the row's ``Date``/``Time``), with the epoch length in the
device metadata (``epoch_s``). Counts are ActiGraph's device-specific activity counts (unit ``counts``), steps
``steps``, lux ``lx``, inclinometer columns ``s`` of the epoch in that posture (ActiLife writes seconds).

Memory: in pieces of at most 2 MiB of text (:data:`EPOCH_PIECE_BYTES`; :func:`iter_epoch_csv`, called by the ActiLife CSV converter's
``iter_chunks``), the whole-file reading being the one-piece case: the banner (or the first row) gives the start,
epoch times are checked across pieces, and the warnings come at the end (in pieces, in a last piece without epochs:
the reader does not look a piece ahead, which held two pieces' text and values at once). A week of 60 s epochs is only
10,080 rows; of 1 s epochs 604,800 (about 25 MB of text).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path

import numpy as np
from imulog.converters._binary import UNKNOWN_ZONE
from imulog.converters._common import TableSpec, sanitize_name
from imulog.converters._pieces import NumericPiece, iter_numeric, text_column
from imulog.converters.errors import ConversionError

from imulog.model import Recording, SignalStream

BANNER_LINES = 10
ORDER = (
    "Axis1",
    "Axis2",
    "Axis3",
    "Steps",
    "Lux",
    "Inclinometer Off",
    "Inclinometer Standing",
    "Inclinometer Sitting",
    "Inclinometer Lying",
)
UNITS = {"axis1": "counts", "axis2": "counts", "axis3": "counts", "vector_magnitude": "counts", "vm": "counts"}
UNITS |= {"steps": "steps", "lux": "lx", "activity": "counts"}
TIME_NAMES = {"date", "time", "timestamp"}


_DATE_TOKENS = {"yyyy": "%Y", "yy": "%y", "MM": "%m", "M": "%m", "dd": "%d", "d": "%d"}

# Pieces of an epoch export, at most (bytes of text). Each epoch row (about 45 bytes) is one archive message, and
# the archive writer holds about 1.3 kB per message of a piece while it encodes it: 16 MiB pieces of 1-s epochs
# peaked at 0.7-1.2 GB; 2 MiB pieces of about 45,000 epochs keep that near 60 MB.
EPOCH_PIECE_BYTES = 2 * 1024 * 1024


def strptime_format(fmt: str) -> str:
    """ActiLife's (.NET) ``date format`` -> strptime: ``M/d/yyyy`` -> ``%m/%d/%Y``, ``dd.MM.yyyy`` -> ``%d.%m.%Y``."""
    return re.sub(r"yyyy|yy|MM|M|dd|d", lambda m: _DATE_TOKENS[m.group(0)], fmt)


def epoch_seconds(text: str) -> float:
    """``00:00:15`` -> 15.0 (s)."""
    h, m, s = (int(p) for p in text.split(":"))
    return float(h * 3600 + m * 60 + s)


def _unit(column: str) -> str:
    key = sanitize_name(column)
    if key.startswith("inclinometer"):
        return "s"
    return UNITS.get(key, "")


def _is_names_row(cells: list[str]) -> bool:
    return any(re.search(r"[A-Za-z]", c) for c in cells)


def _parse_dates(path: Path, date: list[str], time: list[str] | None, fmt: str, first_line: int) -> np.ndarray:
    """Date (banner ``date format``) and time cells -> datetime64[ns] per row."""
    import pandas as pd

    py_fmt = strptime_format(fmt)
    text = pd.Series(date) if time is None else pd.Series(date) + " " + pd.Series(time)
    first_bad = None
    for f in (f"{py_fmt} %H:%M:%S", "ISO8601") if time is not None else ("ISO8601",):
        parsed = pd.to_datetime(text, format=f, errors="coerce")
        if getattr(parsed.dt, "tz", None) is not None:  # the Link's "...Z" stamps: its wall clock, kept as written
            parsed = parsed.dt.tz_localize(None)
        if not parsed.isna().any():
            return parsed.to_numpy().astype("datetime64[ns]")
        if first_bad is None:  # the first cell the declared format does not read
            first_bad = int(np.argmax(parsed.isna().to_numpy()))
    unread = np.nonzero(pd.to_datetime(text, format="mixed", errors="coerce").isna().to_numpy())[0]
    bad = int(unread[0]) if len(unread) else first_bad  # a cell pandas reads in some format: the declared one's
    raise ConversionError(
        path, f"{text.iloc[bad][:30]!r} is not a date/time in format {fmt}", line=first_line + bad, column="Date"
    )


def read_epoch_csv(
    path: Path, lines: list[str], banner: dict, options: object = None, *, banner_lines: int = BANNER_LINES
) -> Recording:
    """An ActiLife epoch CSV (``banner`` from :func:`imulog.converters.actilife_csv.parse_banner`) as epoch signals:
    :func:`iter_epoch_csv` as one piece.

    ``banner_lines`` 0: an export without the banner (``banner`` then comes from :func:`bannerless_banner`)."""
    (rec,) = iter_epoch_csv(path, lines, banner, options, banner_lines=banner_lines, piece_bytes=None)
    return rec


def iter_epoch_csv(
    path: Path,
    lines: list[str],
    banner: dict,
    options: object = None,
    *,
    banner_lines: int = BANNER_LINES,
    piece_bytes: int | None = None,
) -> Iterator[Recording]:
    """The epoch export in pieces of about ``piece_bytes`` of text (None: one piece), rows read by
    :func:`~imulog.converters._pieces.iter_numeric` and their Date/Time cells by ``text_column``. The start is the
    banner's, or the first row's time (first piece); epoch times are checked to increase across pieces; the warnings
    (a start that disagrees, uneven epochs, a cut final row, no banner or names row) come with the one piece, or in
    pieces in a last piece without epochs."""
    BANNER_LINES = banner_lines  # noqa: N806 - the banner's length in this file
    if piece_bytes is not None:
        piece_bytes = min(piece_bytes, EPOCH_PIECE_BYTES)

    epoch_s = epoch_seconds(banner["epoch"])
    if epoch_s <= 0:
        raise ConversionError(path, f"Epoch Period {banner['epoch']} is not an epoch length", line=5)
    if len(lines) <= BANNER_LINES:
        raise ConversionError(path, "no epochs after the banner", line=BANNER_LINES + 1)
    first = [c.strip().strip('"').strip() for c in lines[BANNER_LINES].split(",")]
    while first and not first[-1]:
        first.pop()
    has_names = _is_names_row(first)
    skip = BANNER_LINES + (1 if has_names else 0)
    if has_names:
        names = first
    else:
        if len(first) > len(ORDER):
            raise ConversionError(
                path,
                f"{len(first)} columns without a names row: ActiLife's order names only {len(ORDER)} "
                "(export with column headers, or pass a mapping file)",
                line=BANNER_LINES + 1,
            )
        names = list(ORDER[: len(first)])
    if any(n.lower().startswith(("accelerometer", "gyroscope")) for n in names):
        raise ConversionError(
            path,
            f"epoch export (Epoch Period {banner['epoch']}) whose names row holds raw sample columns "
            f"({names[0]}, ...): banner and data disagree; a raw export has Epoch Period 00:00:00",
            line=5 if BANNER_LINES else 1,
        )
    lower = [n.lower() for n in names]
    time_idx = [i for i, n in enumerate(lower) if n in TIME_NAMES]
    value_idx = [i for i in range(len(names)) if i not in time_idx]
    if not value_idx:
        raise ConversionError(path, "names row has no count columns", line=BANNER_LINES + 1)
    if time_idx and "timestamp" not in lower and "date" not in lower:
        raise ConversionError(path, "a 'Time' column without a 'Date' column", line=skip)
    start = None if banner["start"] is None else np.datetime64(banner["start"], "ns")
    if not time_idx and start is None:
        raise ConversionError(
            path,
            f"Start Date/Time {banner.get('start_text', '')!r} does not match date format {banner['date_format']}",
            line=4,
        )
    serial = banner["serial"]
    name = sanitize_name(f"{serial}_counts" if serial else "actigraph_counts")
    columns = [sanitize_name(names[i]) for i in value_idx]
    meta = {
        "format": "actilife-csv (epoch counts)",
        "model": banner["device"],
        "serial": serial,
        "epoch_s": epoch_s,
        "columns": dict(zip(columns, [names[i] for i in value_idx], strict=True)),
        "column_source": "names row" if has_names else "no names row: ActiLife's column order " + ", ".join(ORDER),
        "time_base": "ns from start_time (banner Start Date/Time, device local time); one sample per epoch start",
        "source": path.name,
    }
    spec = TableSpec(path=path, delimiter=",", skip_lines=skip, names=names, ignore=set(time_idx))
    cut: list[str] = []  # a cut final row
    warnings: list[str] = []
    uneven = False
    before: int | None = None
    done = 0
    # no look-ahead to learn which piece is last (it held the next piece's text and values while this one was
    # built and written): in pieces, the warnings only the end knows come in a last piece without epochs
    for k, piece in enumerate(iter_numeric(spec, piece_bytes)):
        values = piece.values if piece.values.ndim == 2 else piece.values[:, None]
        n = len(values)
        if k == 0 and n == 0:
            raise ConversionError(path, "no epochs after the banner", line=skip + 1)
        cut.extend(piece.warnings)
        if time_idx:
            stamps = _piece_stamps(path, piece, time_idx, lower, banner["date_format"])
            if k == 0 and (start is None or stamps[0] != start):  # the rows' own times date the epochs
                if start is not None:
                    warnings.append(
                        f"{path.name}: banner start {banner['start']} disagrees with the first epoch's time "
                        f"{str(stamps[0])[:19]}; the rows' times are used"
                    )
                elif BANNER_LINES:
                    warnings.append(
                        f"{path.name}: banner Start Date/Time {banner.get('start_text', '')!r} does not match its "
                        f"date format {banner['date_format']}; the start is the first epoch's time {str(stamps[0])[:19]}"
                    )
                start = stamps[0]
            t_ns = (stamps - start).astype(np.int64)
            d = np.diff(t_ns if before is None else np.concatenate([[before], t_ns]))
            if len(d) and (d <= 0).any():
                i = int(np.nonzero(d <= 0)[0][0]) + (1 if before is None else 0)
                raise ConversionError(path, "epoch time does not increase", line=piece.first_line + i, column="Date")
            uneven = uneven or bool(len(d) and not np.allclose(d, epoch_s * 1e9))
        else:
            t_ns = np.arange(done, done + n, dtype=np.int64) * np.int64(round(epoch_s * 1e9))
        done += n
        if n:
            before = int(t_ns[-1])
        rec = _epochs(path, name, columns, [_unit(names[i]) for i in value_idx], t_ns, values[:, value_idx])
        if k == 0:
            rec.metadata[f"imulog.device.{name}"] = dict(meta)
            rec.metadata["imulog.trial"] = {
                "start_time": datetime.fromisoformat(str(start)[:26]).isoformat(timespec="milliseconds"),
                "time_zone": UNKNOWN_ZONE,
            }
        if piece_bytes is None:  # the one piece is the last
            rec.warnings = [
                *cut,
                *warnings,
                *_end_warnings(path, epoch_s, uneven, BANNER_LINES, has_names, banner, names),
            ]
        yield rec
        del rec, piece, values  # not held while the next piece is read and parsed
    if piece_bytes is not None:
        end = [*cut, *warnings, *_end_warnings(path, epoch_s, uneven, BANNER_LINES, has_names, banner, names)]
        if end:
            last = _epochs(path, name, columns, [_unit(names[i]) for i in value_idx], np.zeros(0, np.int64), None)
            last.warnings = end
            yield last


def _epochs(path: Path, name: str, columns: list[str], units: list[str], t_ns: np.ndarray, values) -> Recording:
    """A piece: the epochs' signal stream (``values`` None: no epoch)."""
    values = np.zeros((0, len(columns))) if values is None else values
    rec = Recording(sources=[str(path)])
    rec.signals.append(SignalStream(topic=f"/signals/{name}", t_ns=t_ns, columns=columns, units=units, values=values))
    return rec


def _end_warnings(
    path: Path, epoch_s: float, uneven: bool, banner_lines: int, has_names: bool, banner: dict, names: list[str]
) -> list[str]:
    """What only the end of the file shows (uneven epochs) and what the file lacks, one line each."""
    out = []
    if uneven:
        out.append(f"{path.name}: epoch times are not {epoch_s:g} s apart everywhere (gaps or a changed epoch)")
    if not banner_lines:
        out.append(
            f"{path.name}: no ActiLife banner: start and epoch ({epoch_s:g} s) from the first rows, dates "
            f"read as {banner['date_format']}, serial unknown"
        )
    if not has_names:
        out.append(f"{path.name}: no names row; {len(names)} columns taken in ActiLife's order ({', '.join(names)})")
    return out


def _piece_stamps(path: Path, piece: NumericPiece, time_idx: list[int], lower: list[str], fmt: str) -> np.ndarray:
    """The piece's epoch times (datetime64[ns]) from its Timestamp, or Date and Time, cells."""
    by_name = {lower[i]: text_column(piece, i).str.strip().tolist() for i in time_idx}
    if "timestamp" in by_name:
        return _parse_dates(path, by_name["timestamp"], None, fmt, piece.first_line)
    return _parse_dates(path, by_name["date"], by_name.get("time"), fmt, piece.first_line)


BANNERLESS_FORMATS = ("M/d/yyyy", "d/M/yyyy", "yyyy-MM-dd", "d.M.yyyy", "d-M-yyyy")


def is_bannerless(lines: list[str]) -> bool:
    """An epoch export without its banner: a names row with ``Axis1`` (and usually ``Date``, ``Time``) first."""
    if not lines:
        return False
    cells = [c.strip().strip('"').strip().lower() for c in lines[0].split(",")]
    return "axis1" in cells and all(c in TIME_NAMES or c.replace(" ", "_") in _KNOWN for c in cells if c)


_KNOWN = {sanitize_name(n) for n in ORDER} | {"vector_magnitude", "vm", "activity"}


def bannerless_banner(path: Path, lines: list[str]) -> dict:
    """The banner fields an export without banner implies: start and epoch from its first Date/Time rows, the date
    format the first of :data:`BANNERLESS_FORMATS` under which they parse and step evenly (said in a warning)."""
    cells = [c.strip().strip('"').strip().lower() for c in lines[0].split(",")]
    if "date" not in cells or "time" not in cells:
        raise ConversionError(
            path,
            "ActiLife epoch export without its banner and without Date/Time columns: the epoch length and start "
            "are unknown (export with the header, or with Date and Time columns)",
            line=1,
        )
    di, ti = cells.index("date"), cells.index("time")
    rows = [[c.strip().strip('"') for c in ln.split(",")] for ln in lines[1:4] if ln.strip()]
    if len(rows) < 2:
        raise ConversionError(path, "fewer than two epochs: the epoch length is unknown", line=2)

    for fmt in BANNERLESS_FORMATS:
        try:
            times = [datetime.strptime(f"{r[di]} {r[ti]}", f"{strptime_format(fmt)} %H:%M:%S") for r in rows]
        except (ValueError, IndexError):
            continue
        steps = {(b - a).total_seconds() for a, b in zip(times, times[1:], strict=False)}
        if len(steps) == 1 and (step := steps.pop()) > 0:
            h, rem = divmod(int(step), 3600)
            return {
                "epoch": f"{h:02d}:{rem // 60:02d}:{rem % 60:02d}",
                "start": times[0],
                "serial": "",
                "device": "ActiGraph (no banner)",
                "date_format": fmt,
            }
    raise ConversionError(path, f"Date/Time {rows[0][di]!r} {rows[0][ti]!r} in no known date format", line=2)
