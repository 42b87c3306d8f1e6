"""A final row cut short (an interrupted export): found, dropped with a warning naming the line."""

from __future__ import annotations

from pathlib import Path

import numpy as np

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
        if continues_steps(column, c):
            continue  # a time printed %g-style ends on a whole number (681.99, 682): the next step, not a cut
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


def continues_steps(column: list[bytes], cell: bytes) -> bool:
    """Do the cells above step by one constant (a time column) and does ``cell`` take exactly the next step?
    (relative tolerance 1e-9 of the values; a cut number lost digits, so it cannot continue the steps)"""
    try:
        values = np.array([float(x) for x in column[-10:]] + [float(cell)])
    except ValueError:
        return False
    if len(values) < 4:
        return False
    steps = np.diff(values)
    tol = 1e-9 * float(np.max(np.abs(values))) + 1e-12
    return bool(steps[0] != 0 and np.ptp(steps) <= tol)


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
