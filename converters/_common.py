"""Shared helpers for text converters: units, binary detection, fast numeric tables with precise errors."""

from __future__ import annotations

import hashlib
import math
import os
import re
from collections.abc import Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters.errors import ConversionError

G0 = 9.80665  # standard gravity, m/s^2
HEAD_BYTES = 256 * 1024

# --------------------------------------------------------------------------------------------- units
# quantity -> normalised unit string -> factor to the model's SI unit (acc m/s^2, gyr rad/s, mag uT, degC, s)
UNIT_FACTORS: dict[str, dict[str, float]] = {
    "acc": {"g": G0, "mg": G0 / 1000.0, "m/s^2": 1.0, "m/s2": 1.0, "ms^-2": 1.0, "mps2": 1.0},
    "gyr": {
        "dps": math.pi / 180.0,
        "deg/s": math.pi / 180.0,
        "degrees/s": math.pi / 180.0,
        "degree/s": math.pi / 180.0,
        "°/s": math.pi / 180.0,
        "mdps": math.pi / 180.0 / 1000.0,
        "rad/s": 1.0,
        "rads^-1": 1.0,
    },
    "mag": {
        "ut": 1.0,
        "µt": 1.0,
        "μt": 1.0,
        "microtesla": 1.0,
        "mt": 1000.0,
        "nt": 0.001,
        "gauss": 100.0,
        "ga": 100.0,
        "g": 100.0,
        "mgauss": 0.1,
        "mga": 0.1,
        "mg": 0.1,
    },
    "temperature": {"degc": 1.0, "°c": 1.0, "c": 1.0, "celsius": 1.0, "degreescelsius": 1.0, "degreecelsius": 1.0},
    "time": {"s": 1e9, "sec": 1e9, "ms": 1e6, "us": 1e3, "µs": 1e3, "μs": 1e3, "ns": 1.0},
}
# magnetometer units that are normalised to the calibration field: kept as a separate signal, never as uT
NORMALISED_MAG_UNITS = {"a.u.", "au", "a.u", "arb", "local_flux", "localflux", "normalized", "normalised"}
SI_UNIT = {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT", "temperature": "degC", "time": "ns"}
QUANTITIES = ("acc", "gyr", "mag", "temperature")


LENGTH_TO_M = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
# quantities a user may give a unit for (``--unit acc=g``, ``ConvertOptions.extra["units"]``)
UNIT_QUANTITIES = ("acc", "gyr", "mag", "temperature", "time", "markers")


def check_unit(quantity: str, unit: str) -> str | None:
    """None when ``unit`` is a known unit of ``quantity`` (``markers``: a length), else the problem in one line."""
    if quantity == "markers":
        return None if unit.strip().lower() in LENGTH_TO_M else f"unknown length unit {unit!r} (use m, cm or mm)"
    if quantity not in UNIT_FACTORS:
        return f"unknown quantity {quantity!r}; use {', '.join(UNIT_QUANTITIES)}"
    if unit_factor(quantity, unit) is None and not (quantity == "mag" and normalise_unit(unit) in NORMALISED_MAG_UNITS):
        return f"unknown {quantity} unit {unit!r} (known: {', '.join(sorted(UNIT_FACTORS[quantity]))})"
    return None


def unit_overrides(extra: dict[str, Any] | None) -> dict[str, str]:
    """The user's units by quantity (``ConvertOptions.extra["units"]``, from ``--unit QUANTITY=UNIT``)."""
    units = (extra or {}).get("units") or {}
    return {str(k).lower(): str(v) for k, v in units.items()}


# the degree sign as files mangle it, before "/s" or "C": UTF-8 read as Latin-1 ("Â°", twice: "Ã‚Â°"), that text
# folded to ASCII ("A /s": EDF's dimension field is ASCII-only, so a writer transliterates "Â°/s"), "?" or U+FFFD for
# an unencodable character, and the ordinal sign "º" typed for it
_DEGREE_SIGN = re.compile(r"^(?:ã‚â°|â°|âº|º|°|\ufffd|\?|a\s+)(?=/\s*s(?:ec)?$|c$)")
# SI product/exponent spellings (EDF+ and ISO 80000): "m.s-2", "m*s^-2", "m s-2", "m/s/s"; "deg.s-1", "rad*s^-1"
_PER_S2 = re.compile(r"^(.*?)(?:[.*·]?s\^?-2|/s/s)$")
_PER_S = re.compile(r"^(.*?)[.*·]s\^?-1$")


def normalise_unit(unit: str) -> str:
    """Canonical spelling used for look-ups: ``m/(s^2)`` -> ``m/s^2``, ``Degrees Celsius`` -> ``degreescelsius``,
    ``m.s-2`` -> ``m/s^2``, ``deg.s-1`` -> ``deg/s``, a mangled degree sign (``Â°/s``, ``A /s``, ``?/s``) -> ``°/s``."""
    u = unit.strip().strip("[]()").strip().lower()
    u = _DEGREE_SIGN.sub("°", u)
    u = u.replace("²", "^2").replace("**", "^").replace(" ", "").replace("(", "").replace(")", "")
    u = u.replace("/second", "/s").replace("deg/sec", "deg/s").replace("/sec", "/s")
    if u not in ("ms-2", "ms^-2"):  # "ms-2" is metres per second squared, not milliseconds
        m = _PER_S2.match(u)
        if m and m.group(1) in ("m", "mm", "cm"):
            u = m.group(1) + "/s^2"
    else:
        u = "m/s^2"
    m = _PER_S.match(u)
    if m and m.group(1):
        u = m.group(1) + "/s"
    return u


def unit_factor(quantity: str, unit: str) -> float | None:
    """Factor from ``unit`` to the SI unit of ``quantity`` or None when the unit is unknown."""
    return UNIT_FACTORS.get(quantity, {}).get(normalise_unit(unit))


# ------------------------------------------------------------------------------------------ text input
def read_head(path: Path, n: int = HEAD_BYTES) -> bytes:
    with open(path, "rb") as f:
        return f.read(n)


_DIGESTS: dict[tuple[str, int, int], str | Future[str]] = {}  # (resolved path, size, mtime ns) -> SHA-256
_DIGESTS_KEPT = 256
BACKGROUND_HASH_BYTES = 1 << 20  # smaller sources are hashed at once

# a forked child (batch workers) gets its own worker threads; digests still being computed by the parent's never end
os.register_at_fork(after_in_child=_DIGESTS.clear)


def _stat_key(path: Path, st: os.stat_result) -> tuple[str, int, int]:
    return str(Path(path).resolve()), st.st_size, st.st_mtime_ns


def _sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def read_source(path: Path) -> bytes:
    """A source file's bytes, read once; their SHA-256 is computed from them and remembered (size and mtime
    checked) so that the conversion record does not read and hash the file a second time (:func:`known_sha256`).

    Sources of 1 MiB and more are hashed on the package's worker threads (:mod:`imulog.workers`, shared with the archive writer) while the caller parses them
    (hashlib releases the GIL): the SHA-256 of a 57 MB export takes ~45 ms, which then overlaps the parse.
    """
    with open(path, "rb") as f:
        data = f.read()
        st = os.fstat(f.fileno())
    if st.st_size == len(data):
        if len(data) < BACKGROUND_HASH_BYTES:
            remember_sha256(path, st, _sha256_hex(data))
        else:
            from imulog.workers import in_background

            remember_sha256(path, st, in_background(_sha256_hex, data))
    return data


def remember_sha256(path: Path, st: os.stat_result, digest: str | Future[str]) -> None:
    """Remember the SHA-256 of ``path`` as read while it had the size and mtime of ``st`` (:func:`known_sha256`);
    ``digest`` may still be being computed (a Future)."""
    if len(_DIGESTS) >= _DIGESTS_KEPT:
        _DIGESTS.pop(next(iter(_DIGESTS)))
    _DIGESTS[_stat_key(path, st)] = digest


def known_sha256(path: Path) -> str | None:
    """The SHA-256 :func:`read_source` computed for ``path`` when the file has not changed since (else None)."""
    try:
        digest = _DIGESTS.get(_stat_key(path, os.stat(path)))
    except OSError:
        return None
    return digest.result() if isinstance(digest, Future) else digest


def looks_binary(head: bytes) -> bool:
    """True for data that is not a text export (NUL bytes or many control characters)."""
    if not head:
        return False
    if b"\x00" in head:
        return True
    sample = head[:8192]
    controls = sum(1 for b in sample if b < 32 and b not in (9, 10, 13, 12))
    return controls > max(2, len(sample) // 100)


def decode(data: bytes) -> str:
    """Text of a header (UTF-8 with optional BOM, else Latin-1, which never fails)."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def head_lines(path: Path, head: bytes | None = None, max_lines: int = 200) -> list[str]:
    """The first lines of a text file (without line endings); raises for empty or binary files."""
    head = read_head(path) if head is None else head
    if not head.strip():
        raise ConversionError(path, "empty file")
    if looks_binary(head):
        raise ConversionError(path, "binary data, not a text export")
    lines = decode(head).splitlines()
    if len(head) == HEAD_BYTES and len(lines) > 1:
        lines = lines[:-1]  # the last one may be cut
    return lines[:max_lines]


# (head, its lines or None): detection hands the same head to every converter; one tuple, replaced whole, so
# that threads detecting at once never pair one head with another's lines
_SNIFFED: tuple[bytes | None, list[str] | None] = (None, None)


def text_head_lines(head: bytes, max_lines: int = 50) -> list[str] | None:
    """Like :func:`head_lines` for sniffing: None instead of raising. The head's lines are computed once for all
    the converters sniffing the same head (decoding 256 KiB and testing for binary data takes ~0.7 ms each)."""
    global _SNIFFED
    cached, lines = _SNIFFED
    if cached is not head:
        lines = None if not head.strip() or looks_binary(head) else decode(head).splitlines()
        _SNIFFED = (head, lines)
    return None if lines is None else lines[:max_lines]


def split_row(line: str, delimiter: str) -> list[str]:
    """Split one header/data row; strips whitespace and surrounding double quotes of each cell."""
    cells = line.split() if delimiter == " " else line.split(delimiter)
    return [c.strip().strip('"').strip() for c in cells]


def is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


# ------------------------------------------------------------------------------------ a cut final row
TAIL_BYTES = 64 * 1024  # enough for the last row and the rows above it that it is compared with
_REFERENCE_ROWS = 50


def _cells(line: bytes, delimiter: str) -> list[bytes]:
    text = line.rstrip(b"\r")
    return text.split() if delimiter == " " else text.split(delimiter.encode())


def final_row_cut(block: bytes, delimiter: str, *, at_eof: bool) -> tuple[int, str] | None:
    """Is the last row of a numeric block cut short? ``(offset of that row in block, reason)`` or None.

    ``block``: the end of the block (its last row and, where available, up to 50 rows above it), trailing blank
    lines allowed; ``at_eof``: the block ends the file. A row is cut when it has fewer fields than the rows above
    above, or, when the file ends without a line break after it, when one of its cells lacks the decimal point or
    exponent that every cell of that column above carries (``-31.25`` cut to ``-3``; ``1.5e-05`` cut to ``1.5``),
    is a whole number shorter than every one above (``600`` cut to ``60``), or has at least two decimals fewer
    than every cell above (``-40.62421`` cut to ``-40.6``; one decimal fewer is normal for numbers printed
    without trailing zeros). A cut that removes only the last decimal or two of a number that had more than the
    column's fewest cannot be told from a complete row: it changes the value by less than those decimals.
    """
    body = block.rstrip(b" \t\r\n")
    if not body:
        return None
    start = body.rfind(b"\n") + 1
    last = body[start:]
    newline_after = len(body) < len(block) and b"\n" in block[len(body) :]
    above = body[:start].split(b"\n")
    if start and len(block) >= TAIL_BYTES:
        above = above[1:]  # the first one may be a partial line of the tail window
    above = [ln for ln in above if ln.strip(b" \t\r")][-_REFERENCE_ROWS:]
    if not above:
        return None
    rows = [_cells(ln, delimiter) for ln in above]
    cells = _cells(last, delimiter)
    width = min(len(r) for r in rows)
    if len(cells) < width:
        return start, f"{len(cells)} fields where the rows above have {width}"
    if not at_eof or newline_after:
        return None
    for j, cell in enumerate(cells):
        column = [r[j].strip().strip(b'"') for r in rows if j < len(r)]
        if len(column) < len(rows) or not all(column):
            continue  # a column with empty cells (gaps, padding) says nothing about the length of its numbers
        c = cell.strip().strip(b'"')
        for mark, what in ((b".", "decimal point"), (b"e", "exponent")):
            if all(mark in x.lower() for x in column) and mark not in c.lower():
                return start, f"field {j + 1} {c.decode('latin-1')!r} has no {what} where every row above has one"
        if not any(b"." in x for x in column):  # whole numbers (counts): a shorter one lost digits
            shortest = min(len(x) for x in column)
            if len(c) < shortest:
                return start, f"field {j + 1} has {len(c)} characters where the rows above have at least {shortest}"
        else:  # %g-style numbers drop trailing zeros: only two decimals fewer than every row above count
            fewest = min(len(x) - x.index(b".") - 1 for x in column if b"." in x)
            decimals = len(c) - c.index(b".") - 1 if b"." in c else 0
            if decimals <= fewest - 2:
                return start, f"field {j + 1} has {decimals} decimals where the rows above have at least {fewest}"
    return None


def drop_cut_final_row(
    path: Path, data: bytes, delimiter: str, *, start: int = 0, end: int | None = None, line_offset: int = 0
) -> tuple[int, str | None]:
    """The end of the numeric block ``data[start:end]`` without a cut final row, and the one-line warning.

    The shared check every text converter calls before parsing (see :func:`final_row_cut` for what "cut"
    means): returns ``(end, None)`` for a complete block, else ``(offset where the cut row starts, warning)``.
    Dropping is always safe for a final row: it needs rows above it to be recognised as cut, so at least one
    complete row remains. ``line_offset``: lines of the file before ``data`` (when ``data`` is its last piece).
    """
    end = len(data) if end is None else end
    lo = max(start, end - TAIL_BYTES)
    after = data[end : end + 4096]
    blank_after = after[: len(after) - len(after.lstrip(b" \t\r\n"))]  # the line break a trimmed block lost
    at_eof = len(blank_after) == len(data) - end
    found = final_row_cut(data[lo:end] + blank_after, delimiter, at_eof=at_eof)
    if found is None:
        return end, None
    offset, reason = found
    row_start = lo + offset
    line = line_offset + data.count(b"\n", 0, row_start) + 1
    return row_start, cut_row_warning(path, line, reason)


def cut_row_warning(path: Path | str, line: int, reason: str) -> str:
    """The one-line warning for a dropped cut row (the same wording in every converter)."""
    return f"{Path(path).name}: line {line}: last row cut short ({reason}; the file was probably truncated): dropped"


def file_tail(path: Path, n: int = TAIL_BYTES) -> tuple[bytes, int]:
    """The last ``n`` bytes of a file and their offset in it."""
    with open(path, "rb") as f:
        f.seek(0, 2)
        size = f.tell()
        offset = max(0, size - n)
        f.seek(offset)
        return f.read(), offset


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
    delims = np.cumsum(raw == ord(spec.delimiter))
    at_end = np.concatenate([delims[ends], [delims[-1]]]) if len(raw) else np.zeros(1, dtype=np.int64)
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


# ---------------------------------------------------------------------------------------------- time
def to_ns(values: np.ndarray, factor_to_ns: float, origin: float | None = None) -> np.ndarray:
    """Times in a unit (``factor_to_ns`` ns per unit) to int64 ns, exact relative to the first sample.

    ``origin``: the recording's first time value when ``values`` are a later piece of it (same ns as converting
    the whole recording at once)."""
    values = np.asarray(values, dtype=np.float64)
    if len(values) == 0:
        return np.zeros(0, dtype=np.int64)
    t0 = values[0] if origin is None else np.float64(origin)
    base = round(t0 * factor_to_ns)
    if abs(base) > 9.2e18 or not np.isfinite(values).all():
        raise ValueError("time stamps out of range")
    rel = np.round((values - t0) * factor_to_ns)
    if len(rel) and np.abs(rel).max() > 9.2e18:
        raise ValueError("time stamps out of range")
    return rel.astype(np.int64) + np.int64(base)


def check_increasing(path: Path, t_ns: np.ndarray, first_line: int, column: str | None = None) -> None:
    """Raise ConversionError at the first duplicated or decreasing time stamp (``first_line`` = line of row 0)."""
    if len(t_ns) < 2:
        return
    d = np.diff(t_ns)
    bad = np.nonzero(d <= 0)[0]
    if len(bad):
        i = int(bad[0]) + 1
        what = "duplicated time stamp" if d[i - 1] == 0 else "time stamp goes backwards"
        raise ConversionError(path, what, line=first_line + i, column=column)


def estimate_rate_hz(t_ns: np.ndarray) -> float | None:
    """Median sampling rate in Hz (None for fewer than two samples)."""
    if len(t_ns) < 2:
        return None
    dt = float(np.median(np.diff(t_ns)))
    return 1e9 / dt if dt > 0 else None


MAX_NAME_CHARS = 64  # a name taken from a file (serial, label, stream name) is cut to this many characters


def sanitize_name(name: str) -> str:
    """A topic-safe stream name: lower case, [a-z0-9_], at most :data:`MAX_NAME_CHARS` characters.

    A longer name (a hostile 300k-character serial) keeps its first characters and a short hash of the whole, so
    two long names that differ only at their ends stay distinct."""
    text = str(name)
    s = re.sub(r"[^0-9a-zA-Z]+", "_", text[: 4 * MAX_NAME_CHARS]).strip("_").lower()
    if len(text) > 4 * MAX_NAME_CHARS or len(s) > MAX_NAME_CHARS:
        digest = hashlib.sha1(text.encode("utf-8", "replace")).hexdigest()[:8]
        s = f"{s[: MAX_NAME_CHARS - 9].rstrip('_')}_{digest}"
    return s or "imu"
