"""Fast numeric tables from delimited text (pyarrow, pandas) with errors naming file, line and column."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._final_row import drop_cut_final_row, file_tail, final_row_cut
from imulog.converters._source import read_source
from imulog.converters.errors import ConversionError


# ------------------------------------------------------------------------------------- numeric tables
@dataclass
class TableSpec:
    """Where the numeric block of a delimited file is and what each column may contain.

    ``skip_lines`` lines precede the data (the first data line is line ``skip_lines + 1``). ``ncols`` is the
    number of fields per data row; ``names`` their names for messages; ``optional`` columns may be empty
    (NaN); ``ignore`` columns are not checked at all (e.g. padding); ``nrows`` limits the block.
    """

    path: Path
    delimiter: str
    skip_lines: int
    names: Sequence[str]
    optional: set[int] = field(default_factory=set)
    ignore: set[int] = field(default_factory=set)
    nrows: int | None = None
    allow_trailing_blank: bool = True
    byte_range: tuple[int, int] | None = None  # (start, end) of the block when already known
    check_final_row: bool = True  # drop a cut final row (see drop_cut_final_row) instead of storing it
    short_rows_are_errors: bool = True  # a row with fewer fields is damage (else its missing cells are gaps)
    in_memory: bool = False  # ``data`` is one piece of the file (``skip_lines`` lines before it): parse only it
    warnings: list[str] = field(default_factory=list)  # filled by read_numeric: one line per dropped row


def _data_range(spec: TableSpec, data: bytes) -> tuple[int, int]:
    """Byte range of the numeric block: after ``skip_lines`` lines, ``nrows`` lines long, trailing blanks trimmed."""
    if spec.byte_range is not None:
        pos, end = spec.byte_range
        while end > pos and data[end - 1] in b" \t\r\n" and (spec.allow_trailing_blank or not spec.in_memory):
            end -= 1
        return pos, end
    pos = 0
    for _ in range(spec.skip_lines):
        nxt = data.find(b"\n", pos)
        if nxt == -1:
            raise ConversionError(spec.path, "file ends inside the header", line=spec.skip_lines)
        pos = nxt + 1
    end = len(data)
    if spec.nrows is not None:
        stop = pos
        for _ in range(spec.nrows):
            nxt = data.find(b"\n", stop)
            if nxt == -1:
                stop = len(data)
                break
            stop = nxt + 1
        end = stop
    if spec.allow_trailing_blank:
        while end > pos and data[end - 1] in b" \t\r\n":
            end -= 1
    return pos, end


NA_CELLS = ["", "NaN", "nan", "NAN", "-NaN", "-nan"]  # gaps: empty or NaN cells


ARROW_BLOCK_BYTES = 4 << 20  # pyarrow parses blocks of this size in parallel


def read_numeric(spec: TableSpec, data: bytes | None = None) -> np.ndarray:
    """Parse the numeric block fast and validate it vectorised.

    Returns an (N, ncols) float64 array, NaN only in ``optional``/``ignore`` columns (ignored columns are not
    parsed). The block is parsed by pyarrow's multithreaded CSV reader from the file's bytes in memory (read
    once, see :func:`read_source`); a block that reader does not take as plainly numeric (other spellings,
    ragged or blank rows, whitespace-delimited tables) goes to the pandas C parser, which accepts exactly what
    it accepted before. On any problem a careful line-by-line pass finds the first offending line and raises
    :class:`ConversionError` naming file, line and column. ``data``: the file's bytes when already read.
    """
    ncols = len(spec.names)
    if spec.check_final_row:
        spec, data = _without_cut_final_row(spec, data)
    nrows = spec.nrows
    if spec.byte_range is not None:
        if data is None:
            data = read_source(spec.path)
        start, end = _data_range(spec, data)
        if end <= start:
            raise ConversionError(spec.path, "no data rows", line=spec.skip_lines + 1)
        tail = data[end:].strip(b" \t\r\n") if len(data) - end < 4096 else b"x"
        nrows = None if not tail else data.count(b"\n", start, end) + 1
    used = [i for i in range(ncols) if i not in spec.ignore]
    values = None
    if spec.delimiter != " ":
        if data is None:
            data = read_source(spec.path)
        values = _parse_arrow(spec, data, nrows, used)
    if values is None:
        values = _parse_pandas(spec, data, nrows, used)
    if spec.allow_trailing_blank and nrows is None:
        n = len(values)
        while n > 0 and np.isnan(values[n - 1, used]).all():
            n -= 1
        values = values[:n]
    return _validate(spec, values, data)


def _parse_pandas(spec: TableSpec, data: bytes | None, nrows: int | None, used: list[int]) -> np.ndarray:
    """The block parsed by the pandas C engine straight from the file (any parser problem located and raised)."""
    ncols = len(spec.names)
    source: Any = spec.path
    if spec.in_memory:  # a piece of the file: pandas reads that piece, not the file
        assert data is not None and spec.byte_range is not None
        import io

        start, end = _data_range(spec, data)
        source = io.BytesIO(memoryview(data)[start:end])
    kwargs: dict[str, Any] = dict(
        sep=r"\s+" if spec.delimiter == " " else spec.delimiter,
        header=None,
        skiprows=0 if spec.in_memory else spec.skip_lines,
        nrows=None if spec.in_memory else nrows,
        engine="c",
        skip_blank_lines=False,
        keep_default_na=False,
        na_values=NA_CELLS,
        quoting=3,  # QUOTE_NONE: numbers are never quoted in these exports
        encoding_errors="replace",  # non-UTF-8 bytes become non-numeric cells, reported by the careful pass
    )
    if len(used) != ncols:
        kwargs["usecols"] = used
    import pandas as pd  # here, not at module top: `imulog convert --help` must not pay ~0.5 s for pandas

    try:
        # no dtype= here: pandas' own numeric inference is about 2x faster than a forced float64 cast
        frame = pd.read_csv(source, **kwargs)
    except Exception:  # noqa: BLE001 - any parser failure is located precisely below
        locate_problem(spec, data=_block(spec, data))
        raise ConversionError(spec.path, "could not parse the numeric data") from None
    if frame.shape[1] != len(used) or any(dt.kind not in "fiub" for dt in frame.dtypes):
        locate_problem(spec, data=_block(spec, data))
        raise ConversionError(spec.path, f"could not parse the numeric data ({ncols} numeric fields per row expected)")
    part = frame.to_numpy(dtype=np.float64, copy=False)
    if len(used) == ncols:
        return part
    values = np.full((len(part), ncols), np.nan)
    values[:, used] = part
    return values


def _fill_column(out: np.ndarray, chunk: Any) -> None:
    """Copy a float64 pyarrow array into ``out`` once, its nulls (empty cells: gaps) as NaN."""
    validity, buffer = chunk.buffers()[:2]
    out[:] = np.frombuffer(buffer, dtype=np.float64, count=len(chunk), offset=chunk.offset * 8)
    if chunk.null_count:
        bits = np.unpackbits(np.frombuffer(validity, dtype=np.uint8), bitorder="little")
        out[bits[chunk.offset : chunk.offset + len(chunk)] == 0] = np.nan


def _parse_arrow(spec: TableSpec, data: bytes, nrows: int | None, used: list[int]) -> np.ndarray | None:
    """The block parsed by ``pyarrow.csv`` (threads, no copy of the bytes) into an (N, ncols) column-major array,
    or None when the pandas path must decide: a first row of another width, a header region whose line count
    pandas could read differently (a lone CR), a row of another width or a blank row inside the block, a cell
    that is not a plain number, a NaN or infinity spelled otherwise than :data:`NA_CELLS` (pandas refuses
    ``Nan``), or ``-0`` in a whole-number column (pandas reads those as integers: +0).
    """
    ncols = len(spec.names)
    if not used:
        return None  # pyarrow reads an empty include_columns as every column: pandas decides
    try:
        trim = spec.allow_trailing_blank if spec.in_memory else spec.byte_range is not None or nrows is None
        lo, hi = _data_range(replace(spec, allow_trailing_blank=trim), data)
    except ConversionError:
        return None
    if hi <= lo or data.count(b"\r", 0, lo) != data.count(b"\r\n", 0, lo):
        return None
    first_end = data.find(b"\n", lo, hi)
    first = data[lo : first_end if first_end != -1 else hi].rstrip(b"\r")
    if first.count(spec.delimiter.encode()) + 1 != ncols:
        return None
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:  # pragma: no cover - pyarrow is a base dependency
        return None
    names = [f"c{i}" for i in range(ncols)]
    try:
        table = pacsv.read_csv(
            pa.py_buffer(memoryview(data)[lo:hi]),
            read_options=pacsv.ReadOptions(column_names=names, block_size=ARROW_BLOCK_BYTES),
            parse_options=pacsv.ParseOptions(
                delimiter=spec.delimiter,
                quote_char=False,
                double_quote=False,
                escape_char=False,
                newlines_in_values=False,
                ignore_empty_lines=False,
            ),
            convert_options=pacsv.ConvertOptions(
                column_types={names[i]: pa.float64() for i in used},
                include_columns=[names[i] for i in used],
                null_values=NA_CELLS,
                strings_can_be_null=False,
                quoted_strings_can_be_null=False,
            ),
        )
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError, ValueError):
        return None
    if nrows is not None and table.num_rows != nrows:
        return None
    values = np.empty((table.num_rows, ncols), dtype=np.float64, order="F")
    for i in range(ncols):
        if i not in spec.ignore:
            continue
        values[:, i] = np.nan
    for i, column in zip(used, table.columns, strict=True):
        row = 0
        for chunk in column.chunks:
            _fill_column(values[row : row + len(chunk), i], chunk)
            row += len(chunk)
        col = values[:, i]
        if len(col) - np.count_nonzero(np.isfinite(col)) != column.null_count:
            return None  # a NaN or infinity from a cell itself (nulls are the gaps)
        zeros = col == 0
        if zeros.any() and np.signbit(col[zeros]).any():
            finite = col[np.isfinite(col)]
            if np.array_equal(finite, np.round(finite)):
                return None
    return values


def _without_cut_final_row(spec: TableSpec, data: bytes | None) -> tuple[TableSpec, bytes | None]:
    """``spec`` limited so that a cut final row is not parsed (its warning added to ``spec.warnings``).

    Only the file's last 64 KiB are read unless the last row is cut (then the whole file, to number the line).
    """
    if spec.nrows is not None and spec.byte_range is None:
        return spec, data  # a block bounded by a row count does not end the file
    if data is None:
        tail, offset = file_tail(spec.path)
        if offset > 0 and final_row_cut(tail, spec.delimiter, at_eof=True) is None:
            return spec, data
        data = tail if offset == 0 else spec.path.read_bytes()
    start, end = _data_range(replace(spec, allow_trailing_blank=False), data)
    new_end, warning = drop_cut_final_row(spec.path, data, spec.delimiter, start=start, end=end)
    if warning is None:
        return spec, data
    spec.warnings.append(warning)
    if spec.byte_range is not None:
        return replace(spec, byte_range=(spec.byte_range[0], new_end)), data
    return replace(spec, nrows=data.count(b"\n", start, new_end)), data


def _block(spec: TableSpec, data: bytes | None) -> bytes:
    if data is None:
        data = spec.path.read_bytes()
    start, end = _data_range(spec, data)
    return data[start:end]


def _validate(spec: TableSpec, values: np.ndarray, data: bytes | None) -> np.ndarray:
    ncols = len(spec.names)
    if len(values) == 0:
        raise ConversionError(spec.path, "no data rows", line=spec.skip_lines + 1)
    check = [i for i in range(ncols) if i not in spec.optional and i not in spec.ignore]
    sub = values[:, check] if len(check) != ncols else values
    finite = np.isfinite(sub).all(axis=1)
    if not finite.all():
        locate_problem(spec, data=_block(spec, data))
        bad_row = int(np.nonzero(~finite)[0][0])
        raise ConversionError(spec.path, "missing or non-finite value", line=spec.skip_lines + bad_row + 1)
    if spec.short_rows_are_errors and len(check) != ncols and np.isnan(values).any():
        _check_field_counts(spec, data)
    return values


def _check_field_counts(spec: TableSpec, data: bytes | None) -> None:
    """Rows with fewer fields than the header: the parser fills them with NaN, but a short row is damage, not a gap
    (an empty cell is a gap). Vectorised (delimiter counts per line); space-delimited tables use the careful pass."""
    block = _block(spec, data)
    if spec.delimiter == " ":
        locate_problem(spec, data=block)
        return
    raw = np.frombuffer(block, dtype=np.uint8)
    ends = np.flatnonzero(raw == 10)
    # delimiters before each line end: one int64 per delimiter, not a running count per byte (8 bytes per byte of text)
    delims = np.flatnonzero(raw == ord(spec.delimiter))
    at_end = np.concatenate([np.searchsorted(delims, ends), [len(delims)]])
    fields = np.diff(np.concatenate([[0], at_end])) + 1
    short = np.flatnonzero(fields < len(spec.names))
    if len(short) and block.split(b"\n")[short[0]].strip(b" \t\r"):
        i = int(short[0])
        raise ConversionError(
            spec.path,
            f"truncated line: {int(fields[i])} fields, expected {len(spec.names)}",
            line=spec.skip_lines + i + 1,
        )


_INCOMPLETE_HINT = " (every sample must be complete: delete the row to record a gap in time)"


def locate_problem(spec: TableSpec, nrows: int | None = None, *, data: bytes | None = None) -> None:
    """Careful pass over the data lines: raise ConversionError for the first bad line (returns if none).

    ``data`` is the numeric block alone (its first line is line ``skip_lines + 1``); else the file is read.
    """
    ncols = len(spec.names)
    if data is None:
        raw_all = spec.path.read_bytes()
        start, end = _data_range(spec, raw_all)
        data = raw_all[start:end]
    lines = data.split(b"\n")
    for lineno, raw in enumerate(lines, start=spec.skip_lines + 1):
        text = raw.decode("latin-1").rstrip("\r")
        if not text.strip():
            raise ConversionError(spec.path, "empty line inside the data", line=lineno)
        cells = text.split() if spec.delimiter == " " else text.split(spec.delimiter)
        if len(cells) < ncols:
            raise ConversionError(spec.path, f"truncated line: {len(cells)} fields, expected {ncols}", line=lineno)
        if len(cells) > ncols:
            raise ConversionError(spec.path, f"{len(cells)} fields, expected {ncols}", line=lineno)
        for i, cell in enumerate(cells):
            if i in spec.ignore:
                continue
            c = cell.strip()
            if "_" in c:
                raise ConversionError(spec.path, f"{c[:20]!r} is not a number", line=lineno, column=spec.names[i])
            if c == "":
                if i in spec.optional:
                    continue
                raise ConversionError(spec.path, f"empty cell{_INCOMPLETE_HINT}", line=lineno, column=spec.names[i])
            try:
                v = float(c)
            except ValueError:
                shown = c if len(c) <= 20 else c[:17] + "..."
                raise ConversionError(
                    spec.path, f"{shown!r} is not a number", line=lineno, column=spec.names[i]
                ) from None
            if not math.isfinite(v) and i not in spec.optional:
                raise ConversionError(
                    spec.path, f"non-finite value {c!r}{_INCOMPLETE_HINT}", line=lineno, column=spec.names[i]
                )
