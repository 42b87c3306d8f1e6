"""Numeric tables of delimited text in pieces of bounded size: the one way text readers read their rows.

A reader parses its header, describes the numeric block as a :class:`~imulog.converters._table.TableSpec` and takes
the rows from :func:`iter_numeric`; the whole file is the one-piece case (``piece_bytes=None``).
"""

from __future__ import annotations

import hashlib
import os
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from imulog.converters._final_row import TAIL_BYTES, drop_cut_final_row
from imulog.converters._source import read_source, remember_sha256
from imulog.converters._table import TableSpec, read_numeric
from imulog.converters.errors import ConversionError

#: bytes of text per piece when a large file is converted piece by piece (``Converter.iter_chunks`` of text formats)
PIECE_BYTES = 16 * 1024 * 1024


class NumericPiece(NamedTuple):
    """One piece of a numeric table: its rows' ``values`` (N, ncols), the line number of its first row, its number
    in the file, its warnings (a cut final row) and ``text``, the bytes of its rows (for a column of text, such as
    formatted time stamps: :func:`text_column`)."""

    values: np.ndarray
    first_line: int
    index: int
    warnings: list[str]
    text: memoryview


def iter_numeric(spec: TableSpec, piece_bytes: int | None, *, missing: bytes | None = None) -> Iterator[NumericPiece]:
    """The numeric block of ``spec`` (:func:`~imulog.converters._table.read_numeric`) in pieces of about
    ``piece_bytes`` of text, each cut after a whole row (:class:`NumericPiece`). None: the whole file, read once by :func:`read_source`, as one piece. Values, gaps, a cut final row
    (dropped from the last piece, with its warning) and errors (file, line, column) are the same whatever the piece
    size; the file's SHA-256 is computed while reading and remembered (:func:`known_sha256`). A ``spec.byte_range``
    (one section of a file: Vicon Nexus CSV) is cut alone, ``spec.skip_lines`` being the lines before it.
    ``missing``: another spelling of an empty cell (BIDS: ``n/a``), read as a gap (:func:`blank_cells`)."""
    path = spec.path
    base = spec
    if piece_bytes is None:
        data = read_source(path)  # read once: parsed from memory, its SHA-256 computed from these bytes
        spec = replace(base, warnings=[])
        if missing is not None and missing in data:
            data, spec = _blanked(data, spec, missing)
        values = read_numeric(spec, data)
        start, end = base.byte_range or (0, len(data))
        for _ in range(0 if base.byte_range else base.skip_lines):
            start = data.index(b"\n", start) + 1
        yield NumericPiece(values, base.skip_lines + 1, 0, list(spec.warnings), memoryview(data)[start:end])
        return
    for piece, lines_before, k, last, before in _cut_text(path, base.skip_lines, piece_bytes, span=base.byte_range):
        if missing is not None and missing in piece:
            piece = blank_cells(piece, missing, base.delimiter)
        spec = replace(
            base,
            skip_lines=lines_before,
            byte_range=(0, len(piece)),
            in_memory=True,
            check_final_row=False,
            allow_trailing_blank=last,
            warnings=[],
        )
        warnings: list[str] = []
        if last:
            end, warning = _cut_final_row(path, piece, before, spec.delimiter, lines_before)
            if warning is not None:
                spec = replace(spec, byte_range=(0, end))
                warnings.append(warning)
            if k and not piece[:end].strip(b" \t\r\n"):
                continue  # nothing but blank lines after the previous piece (the last piece: the loop ends)
        yield NumericPiece(read_numeric(spec, piece), lines_before + 1, k, warnings, memoryview(piece))
        del piece  # not held while the next piece is read and parsed


def _cut_final_row(
    path: Path, piece: bytes, before: bytes, delimiter: str, lines_before: int, end: int | None = None
) -> tuple[int, str | None]:
    """:func:`~imulog.converters._final_row.drop_cut_final_row` of the last piece (its rows up to ``end``), judged
    with ``before`` (the text above it, :func:`_cut_text`) as the whole file judges it: the end of the piece
    without a cut final row, and the warning."""
    end = len(piece) if end is None else end
    if end >= TAIL_BYTES or not before:
        return drop_cut_final_row(path, piece, delimiter, end=end, line_offset=lines_before)
    offset = lines_before - before.count(b"\n")
    row, warning = drop_cut_final_row(path, before + piece, delimiter, end=len(before) + end, line_offset=offset)
    if warning is None or row < len(before):
        return end, None
    return row - len(before), warning


def _blanked(data: bytes, spec: TableSpec, missing: bytes) -> tuple[bytes, TableSpec]:
    """The whole file's bytes with ``missing`` cells blanked, and ``spec`` parsing that copy (not the file)."""
    start = 0
    for _ in range(spec.skip_lines):
        start = data.find(b"\n", start) + 1
        if start == 0:
            return data, spec  # the file ends inside the header: read_numeric says so
    data = blank_cells(data, missing, spec.delimiter)
    return data, replace(spec, in_memory=True, byte_range=spec.byte_range or (start, len(data)))


def blank_cells(data: bytes, token: bytes, delimiter: str) -> bytes:
    """``data`` with every cell that is exactly ``token`` (between delimiters or line ends) written ``nan``, a gap to
    both parsers (``_table.NA_CELLS``; not an empty cell, which would make a one-column row a blank line); lines and
    fields keep their numbers, so errors name the same line and column."""
    import re

    d = re.escape(delimiter.encode())
    return re.sub(rb"(?<![^" + d + rb"\n])" + re.escape(token) + rb"(?=" + d + rb"|[\r\n]|\Z)", b"nan", data)


def text_pieces(
    path: Path, skip_lines: int, piece_bytes: int, span: tuple[int, int] | None = None
) -> Iterator[tuple[bytes, int, int, bool]]:
    """The text after ``skip_lines`` header lines in pieces of about ``piece_bytes`` (at least that, up to a line
    break): (piece, lines before it in the file, piece number, whether it is the last). A piece ends between two
    lines that are not blank, so that a blank line is never at a border (readers report it as in the whole file),
    and the last piece holds the text's last two rows (a cut last row is judged and dropped in it, with its
    warning, as in the whole file). The file's SHA-256 is computed while reading and remembered
    (:func:`known_sha256`) when the file did not change meanwhile. ``span``: the bytes ``[start, end)`` alone (a
    section of the file), ``skip_lines`` being the lines before it."""
    for piece, lines_before, k, last, _ in _cut_text(path, skip_lines, piece_bytes, span):
        yield piece, lines_before, k, last


def _cut_text(
    path: Path, skip_lines: int, piece_bytes: int, span: tuple[int, int] | None = None
) -> Iterator[tuple[bytes, int, int, bool, bytes]]:
    """:func:`text_pieces` with, for the last piece, ``before``: the last :data:`TAIL_BYTES` of the text before it
    (or all of it), so that a cut final row is judged against the rows above it as in the whole file (empty bytes
    for the other pieces)."""
    digest = hashlib.sha256()
    total = 0
    with open(path, "rb") as f:
        left = None
        if span is not None:
            f.seek(span[0])
            left = span[1] - span[0]
        for _ in range(0 if span is not None else skip_lines):
            line = f.readline()
            if not line.endswith(b"\n"):
                raise ConversionError(path, "file ends inside the header", line=skip_lines)
            digest.update(line)
            total += len(line)

        def read(n: int) -> bytes:
            nonlocal left
            if left is not None:
                n = min(n, left)
                left -= n
            return f.read(n)

        lines_before = skip_lines
        k = 0
        chunk = max(piece_bytes, 1 << 16)  # bytes read at a time (small pieces: several cut from one read)
        buf, pos = b"", 0  # the text read and not yet given, from buf[pos]
        recent: deque[bytes] = deque()  # the last pieces given, TAIL_BYTES of text or more
        held = 0
        while True:
            nxt = read(chunk)
            digest.update(nxt)
            total += len(nxt)
            ends = len(nxt) < chunk  # the text ends: the rest is the last piece
            buf, pos, nxt = buf[pos:] + nxt, 0, b""  # nxt released: not a third copy held while a piece is parsed
            while (cut := _border(buf, pos + piece_bytes - 1)) > 0:
                if cut - pos > len(buf) // 2:  # a large piece: the rest copied, not the whole buffer kept
                    piece, buf, pos = buf[pos:cut], buf[cut:], 0
                else:
                    piece, pos = buf[pos:cut], cut
                yield piece, lines_before, k, False, b""
                lines_before += piece.count(b"\n")
                recent.append(piece[-TAIL_BYTES:])
                held += len(recent[-1])
                while held - len(recent[0]) >= TAIL_BYTES:
                    held -= len(recent.popleft())
                piece = b""  # released before the next piece is cut (the consumer's copy too: see iter_table)
                k += 1
            if ends:
                break
        yield buf[pos:], lines_before, k, True, b"".join(recent)[-TAIL_BYTES:]
        st = os.fstat(f.fileno())
    if span is None and st.st_size == total:
        remember_sha256(path, st, digest.hexdigest())


def _border(buf: bytes, start: int) -> int:
    """The first place at or after ``start`` (just after a line break) that has a line that is not blank before it
    and two after it, complete, in ``buf``; 0 when ``buf`` has none. So a blank line is never at a border and the
    last piece holds the text's last two rows (a cut last row dropped, a row remains to carry its warning)."""
    while True:
        cut = buf.find(b"\n", start) + 1
        if cut == 0:
            return 0
        mid = buf.find(b"\n", cut)
        end = buf.find(b"\n", mid + 1) if mid >= 0 else -1
        if end < 0:
            return 0
        before = buf[buf.rfind(b"\n", 0, cut - 1) + 1 : cut - 1]
        if before.strip(b" \t\r") and buf[cut:mid].strip(b" \t\r") and buf[mid + 1 : end].strip(b" \t\r"):
            return cut
        start = cut


def text_column(piece: NumericPiece, column: int, delimiter: str = ",") -> Any:
    """Column ``column`` of the piece's rows as text (a pandas Series of str, one per row of ``piece.values``),
    e.g. formatted time stamps that the numeric parse leaves out."""
    import pandas as pd  # here: detecting a format must not import pandas
    import pyarrow as pa

    return pd.read_csv(
        pa.BufferReader(pa.py_buffer(piece.text)),
        sep=delimiter,
        header=None,
        usecols=[column],
        nrows=len(piece.values),
        dtype=str,
        engine="c",
        skip_blank_lines=False,
    )[column]


def iter_table(
    path: Path,
    *,
    delimiter: str,
    skip_lines: int,
    names: list[str],
    piece_bytes: int | None,
    required: tuple[int, ...] | list[int] = (),
    skip_columns: tuple[int, ...] | list[int] = (),
    warnings: list[str] | None,
    ragged: bool = False,
    transform: Callable[[bytes], bytes] | None = None,
) -> Iterator[tuple[np.ndarray, int]]:
    """:func:`imulog.converters._lab.read_table` in pieces of about ``piece_bytes`` of text cut after whole rows
    (:func:`text_pieces`; None: the whole file at once): (values, line number of the piece's first row). Values,
    errors (their line numbers in the file) and a cut final row's warning are those of the whole file.
    ``warnings`` has no default: with a list, a final row cut short is dropped and its warning appended
    (:func:`hand_over` moves it to the piece's recording; a first pass that counts rows passes a list of its own,
    so that it counts the rows the second pass reads); None reads such a row as it is (ragged tables, whose short
    last rows are normal, are never checked).
    ``ragged``: as ``read_table``'s; ``transform``: applied to the text before parsing (the whole file's bytes, or
    each piece's), e.g. QTM's ``NULL`` cells to empty ones; it must keep the line breaks."""
    from imulog.converters._lab import read_table

    kw: dict[str, Any] = dict(
        delimiter=delimiter, names=names, required=required, skip_columns=skip_columns, ragged=ragged
    )
    if piece_bytes is None:
        data = None if transform is None else transform(Path(path).read_bytes())
        yield read_table(path, skip_lines=skip_lines, warnings=warnings, data=data, **kw), skip_lines + 1
        return
    for piece, lines_before, k, last, before in _cut_text(path, skip_lines, piece_bytes):
        if transform is not None:
            piece, before = transform(piece), transform(before)
        if k and last and not piece.strip(b" \t\r\n\x00"):
            continue  # blank lines after the previous piece
        if last and warnings is not None:  # a cut final row, judged and named as in the whole file
            end, warning = _cut_final_row(path, piece, before, delimiter, lines_before, end=len(_trimmed(piece)))
            if warning is not None:
                piece = piece[:end]
                warnings.append(warning)
        try:
            values = read_table(path, data=piece, skip_lines=0, **kw)
        except ConversionError as e:
            if e.line is None:
                raise
            raise ConversionError(path, e.problem, line=e.line + lines_before, column=e.column) from None
        yield values, lines_before + 1
        del piece, values  # not held while the next piece is read and parsed


def hand_over(notes: list[str], rec: Any) -> Any:
    """``rec`` (a :class:`~imulog.model.Recording`) with the warnings :func:`iter_table` appended to ``notes`` while
    reading its piece (a cut final row comes with the last piece); ``notes`` emptied for the next piece."""
    rec.warnings.extend(notes)
    notes.clear()
    return rec


def _trimmed(data: bytes) -> bytes:
    """``data`` without its trailing blank lines (whitespace only) and line breaks, as ``read_table`` trims it."""
    block = data.rstrip(b"\r\n\x00")
    while True:
        cut = block.rfind(b"\n")
        if cut < 0 or block[cut + 1 :].strip():
            return block
        block = block[:cut].rstrip(b"\r\n")
