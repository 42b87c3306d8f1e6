"""Helpers shared by the lab-system converters (Xsens, APDM, MVN, OpenSense, Motive, Qualisys, Delsys).

* :func:`read_table`: a delimited numeric block with empty/NaN cells kept as NaN (gaps), every line's field count
  checked vectorised (a truncated line is an error naming it, never silently padded) and the first non-numeric
  cell named by line and column;
* :func:`orientation_stream`: a device's own orientation estimate as ``/orientation/{name}`` (``qw,qx,qy,qz``);
* :func:`iso_start`: an absolute start time for ``imulog.trial`` (the contract: ISO-8601 and a time-zone rule).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
from imulog.converters.errors import ConversionError

from imulog.model import SignalStream

NA_CELLS = ("", "NaN", "nan", "NAN", "-NaN", "-nan", "NA", "N/A", "null")
ORIENTATION_TOPIC = "/orientation/{name}"


def line_offsets(data: bytes, n_lines: int) -> int:
    """Byte offset of line ``n_lines + 1`` (after ``n_lines`` lines); raises ValueError when the file is shorter."""
    pos = 0
    for _ in range(n_lines):
        nxt = data.find(b"\n", pos)
        if nxt == -1:
            raise ValueError("file ends inside the header")
        pos = nxt + 1
    return pos


def _line_fields(block: bytes, delimiter: str, chunk_bytes: int = 8 << 20):
    """Per line of ``block``, in slices of about ``chunk_bytes`` (memory stays bounded): (index of the slice's first
    line, fields per line, last byte before the line end, line is empty)."""
    buf = np.frombuffer(block, dtype=np.uint8)
    nl_all = np.flatnonzero(buf == 10)
    ends_all = np.concatenate([nl_all, [len(buf)]])
    starts_all = np.concatenate([[0], nl_all + 1])
    delim = ord(delimiter)
    lo = 0
    while lo < len(ends_all):
        hi = int(np.searchsorted(ends_all, ends_all[lo] + chunk_bytes, side="right"))
        hi = max(hi, lo + 1)
        starts, ends = starts_all[lo:hi], ends_all[lo:hi]
        a, b = int(starts[0]), int(ends[-1])
        part = buf[a:b]
        cr = (ends > starts) & (buf[np.maximum(ends - 1, 0)] == 13)
        ends_text = ends - cr
        pos = np.flatnonzero(part == delim) + a
        fields = np.searchsorted(pos, ends_text) - np.searchsorted(pos, starts) + 1
        last = buf[np.maximum(ends_text - 1, 0)]
        yield lo, fields, last, ends_text <= starts
        lo = hi


def read_table(
    path: Path,
    *,
    delimiter: str,
    skip_lines: int,
    names: Sequence[str],
    data: bytes | None = None,
    required: Sequence[int] = (),
    skip_columns: Sequence[int] = (),
    ragged: bool = False,
    warnings: list[str] | None = None,
) -> np.ndarray:
    """The numeric block after ``skip_lines`` lines as an (N, len(names)) float64 array; empty/``NaN`` cells -> NaN.

    ``delimiter`` is literal (a space delimiter keeps runs of spaces as empty fields). A line with another field
    count than ``len(names)`` (one trailing empty field allowed) is an error naming it, unless ``ragged`` (shorter
    lines are padded with NaN: slower channels of a Delsys export end early). ``required`` columns must be finite
    on every row; ``skip_columns`` are not parsed (text). Raises :class:`ConversionError` (file, line, column).
    With a ``warnings`` list, a final row cut short (a truncated file, see ``imulog.converters._common.final_row_cut``) is
    dropped and its one-line warning appended (pass it on as ``Recording.warnings``); without, such a row is read
    (or refused when it has too few fields). Ragged tables are not checked (their short last rows are normal).
    """
    import pandas as pd  # here, not at module top: detecting a format must not import pandas

    path = Path(path)
    data = path.read_bytes() if data is None else data
    ncols = len(names)
    try:
        start = line_offsets(data, skip_lines)
    except ValueError:
        raise ConversionError(path, "file ends inside the header", line=skip_lines) from None
    block = data[start:].rstrip(b"\r\n\x00")
    while True:  # trailing blank lines (whitespace only) are not data; trailing empty fields of a row are
        cut = block.rfind(b"\n")
        if cut < 0 or block[cut + 1 :].strip():
            break
        block = block[:cut].rstrip(b"\r\n")
    if warnings is not None and not ragged and block.strip():
        from imulog.converters._common import drop_cut_final_row

        end, cut_warning = drop_cut_final_row(path, data, delimiter, start=start, end=start + len(block))
        if cut_warning:
            block = data[start:end].rstrip(b"\r\n")
            warnings.append(cut_warning)
    first_line = skip_lines + 1
    if not block.strip():
        raise ConversionError(path, "no data rows", line=first_line)
    any_trailing = False
    for lo, fields, last, empty in _line_fields(block, delimiter):
        if np.any(empty):
            i = int(np.argmax(empty))
            raise ConversionError(path, "empty line inside the data", line=first_line + lo + i)
        trailing = (fields == ncols + 1) & (last == ord(delimiter))
        ok = (fields == ncols) | trailing | ((fields < ncols) if ragged else False)
        if not ok.all():
            i = int(np.argmax(~ok))
            what = "truncated line" if fields[i] < ncols else "too many fields"
            raise ConversionError(path, f"{what}: {int(fields[i])} fields, expected {ncols}", line=first_line + lo + i)
        any_trailing |= bool(trailing.any())
    width = ncols + 1 if any_trailing else ncols
    use = [i for i in range(ncols) if i not in set(skip_columns)]
    try:
        frame = pd.read_csv(
            io.BytesIO(block),
            sep=delimiter,
            header=None,
            names=list(range(width)),
            usecols=use,
            index_col=False,
            engine="c",
            skip_blank_lines=False,
            keep_default_na=False,
            na_values=list(NA_CELLS),
            quoting=3,
            encoding_errors="replace",
            low_memory=False,
        )
    except Exception as e:  # noqa: BLE001 - report, never a traceback
        raise ConversionError(path, f"could not parse the numeric data: {e}", line=first_line) from None
    values = np.full((len(frame), ncols), np.nan)
    for j in use:
        col = frame[j]
        if col.dtype.kind in "fiub":
            values[:, j] = col.to_numpy(dtype=np.float64)
            continue
        num = pd.to_numeric(col.astype(str).str.strip().str.strip('"'), errors="coerce")
        bad = num.isna().to_numpy() & col.notna().to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            cell = str(col.iloc[i])
            cell = cell if len(cell) <= 20 else cell[:17] + "..."
            raise ConversionError(path, f"{cell!r} is not a number", line=first_line + i, column=names[j])
        values[:, j] = num.to_numpy(dtype=np.float64)
    for j in required:
        finite = np.isfinite(values[:, j])
        if not finite.all():
            i = int(np.argmax(~finite))
            raise ConversionError(path, "missing value", line=first_line + i, column=names[j])
    return values


def orientation_stream(name: str, t_ns: np.ndarray, q_wxyz: np.ndarray, frame_id: str = "") -> SignalStream:
    """The device's own orientation estimate (sensor to its global frame), scalar first, NaN rows = gaps."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    return SignalStream(
        topic=ORIENTATION_TOPIC.format(name=name),
        t_ns=t_ns,
        columns=["qw", "qx", "qy", "qz"],
        units=["1", "1", "1", "1"],
        values=q,
        frame_id=frame_id or name,
    )


def iso_start(when: datetime) -> tuple[str, str]:
    """(``start_time``, ``time_zone``) for ``imulog.trial``: aware datetimes keep their offset, naive ones are
    device local time without a zone (the contract in docs/converters.md)."""
    if when.tzinfo is None:
        return when.isoformat(), "unknown (device local time)"
    off = when.utcoffset() or timedelta(0)
    if off == timedelta(0):
        return when.astimezone(UTC).isoformat(), "UTC"
    minutes = int(off.total_seconds() // 60)
    sign = "+" if minutes >= 0 else "-"
    return when.isoformat(), f"{sign}{abs(minutes) // 60:02d}:{abs(minutes) % 60:02d}"


def trial_start(when: datetime, source: str) -> dict[str, str]:
    """The ``imulog.trial`` entries for a start time read from a file (``start_time_source`` names where)."""
    start, zone = iso_start(when)
    return {"start_time": start, "time_zone": zone, "start_time_source": source}
