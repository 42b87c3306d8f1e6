"""Where the sections of a Vicon Nexus CSV are, found in one pass over the file a block at a time (bounded memory).

A section starts at the top of the file or after a blank line with its name (``Trajectories``, ``Devices``, ...);
five header lines (name, rate, names row, ``Frame,Sub Frame,...`` row, units row) precede its data rows, which end
at the next blank line or the end of the file. :func:`find_sections` gives each section's byte range and line;
:func:`section_header` reads its five header lines; :func:`edge_rows` its first and last data rows' frame and sub
frame (the spans the first piece declares); :func:`max_sub_frame` the largest sub frame of a section, a pass over
its second column (the sub frames per frame of a Devices section without Trajectories).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
from imulog.converters._common import decode, split_row
from imulog.converters.errors import ConversionError

_BLANK_LINE = re.compile(rb"\n[ \t]*\r?(?=\n)")
SECTIONS = ("Trajectories", "Devices", "Model Outputs", "Segments", "Joints")
SCAN_BYTES = 16 * 1024 * 1024  # bytes read at a time while looking for sections
MAX_LINE = 1 << 20  # a header line longer than this is not a Nexus header (read no further)


@dataclass
class Section:
    name: str
    line: int  # 0-based line index of the name line
    nrows: int  # data rows
    offset: int = 0  # byte offset of the name line
    data_start: int = 0  # byte range of the data rows
    data_end: int = 0


def first_cell(line: str) -> str:
    return line.split(",", 1)[0].strip().strip('"')


def _line_at(f: BinaryIO, pos: int, end: int | None = None) -> bytes:
    """The line starting at ``pos`` (without its line break; at most :data:`MAX_LINE` bytes, not past ``end``)."""
    f.seek(pos)
    line = f.readline(MAX_LINE if end is None else max(0, min(MAX_LINE, end - pos)))
    return line[:-1] if line.endswith(b"\n") else line


def _blank_lines(f: BinaryIO, block_bytes: int) -> tuple[list[tuple[int, int, int]], int]:
    """(blank line start, the offset after it, lines before that offset) of every blank line, and the file size."""
    out: list[tuple[int, int, int]] = []
    carry, base, lines = b"", 0, 0
    f.seek(0)
    while True:
        chunk = f.read(block_bytes)
        data = carry + chunk
        cut = data.rfind(b"\n") + 1 if chunk else len(data)
        if chunk and cut == 0:
            carry = data  # a line longer than a block: read on
            continue
        block, carry = data[:cut], data[cut:]
        pre = b"\n" if base else b""  # the line break ending the previous block, for a blank line at this one's start
        for m in _BLANK_LINE.finditer(pre + block):
            after = m.end() + 1 - len(pre)
            out.append((base + m.start() + 1 - len(pre), base + after, lines + block.count(b"\n", 0, after)))
        lines += block.count(b"\n")
        base += len(block)
        if not chunk:
            return out, base


def find_sections(path: Path, block_bytes: int | None = None) -> list[Section]:
    """Section starts and data byte ranges: sections begin at the top or after a blank line; a section's data rows
    end at the next blank line or the end of the file. The file is read ``block_bytes`` (:data:`SCAN_BYTES`) at a
    time."""
    with open(path, "rb") as f:
        blanks, size = _blank_lines(f, block_bytes or SCAN_BYTES)
        blank_starts = np.array([b for b, _, _ in blanks], dtype=np.int64)
        candidates = {0: 0}
        for _, after, line in blanks:
            if after < size:
                candidates.setdefault(after, line)
        starts: list[tuple[int, str, int]] = []
        for pos, line0 in sorted(candidates.items()):
            first = decode(_line_at(f, pos)).rstrip("\r")
            name = first_cell(first)
            if name in SECTIONS:
                starts.append((pos, name, line0))
            elif pos == 0:
                raise ConversionError(
                    path, f"not a Vicon Nexus CSV: first line must be one of {', '.join(SECTIONS)}", line=1
                )
            elif first.strip(" ,\t\r\n"):
                raise ConversionError(
                    path,
                    f"unexpected text after a blank line (expected a section name): {first[:30]!r}",
                    line=line0 + 1,
                )
        sections = []
        for k, (offset, name, line0) in enumerate(starts):
            end = starts[k + 1][0] if k + 1 < len(starts) else size
            data_start = offset
            for j in range(5):
                f.seek(data_start)
                line = f.readline(max(0, end - data_start))
                if not line.endswith(b"\n"):
                    raise ConversionError(path, f"{name} section header ends early", line=line0 + j + 1)
                data_start += len(line)
            later = blank_starts[(blank_starts >= data_start) & (blank_starts < end)]
            stop = int(later[0]) if len(later) else end
            if data_start >= stop or not _line_at(f, data_start, stop).strip(b"\r\t ,"):
                raise ConversionError(path, f"{name} section has no data rows", line=line0 + 6)
            sections.append(
                Section(name=name, line=line0, nrows=-1, offset=offset, data_start=data_start, data_end=stop)
            )
    return sections


def section_header(path: Path, sec: Section) -> tuple[float, list[str], list[str], list[str], int]:
    """(rate Hz, names row, ``Frame,Sub Frame,...`` row, units row, fields of the first data row) of a section."""
    with open(path, "rb") as f:
        rows = []
        pos = sec.offset
        for k in range(5):
            f.seek(pos)
            line = f.readline(MAX_LINE)
            if not line.endswith(b"\n"):
                raise ConversionError(path, f"{sec.name} section header ends early", line=sec.line + k + 1)
            rows.append(decode(line[:-1]).rstrip("\r"))
            pos += len(line)
        first_data = _line_at(f, pos)
    rate_cell = split_row(rows[1], ",")[0]
    try:
        rate = float(rate_cell)
    except ValueError:
        raise ConversionError(path, f"{sec.name} rate {rate_cell!r} is not a number", line=sec.line + 2) from None
    if not (rate > 0 and np.isfinite(rate)):
        raise ConversionError(path, f"{sec.name} rate must be positive, got {rate_cell!r}", line=sec.line + 2)
    names, header, units = (split_row(r, ",") for r in rows[2:5])
    if len(header) < 2 or header[0].lower() != "frame" or header[1].lower() != "sub frame":
        raise ConversionError(path, "expected 'Frame,Sub Frame,...' header", line=sec.line + 4)
    width = len(header)
    while width > 2 and header[width - 1] == "":
        width -= 1
    header = header[:width]
    names = (names + [""] * width)[:width]
    units = (units + [""] * width)[:width]
    return rate, names, header, units, first_data.count(b",") + 1


def _frame_sub(line: bytes) -> tuple[float, float] | None:
    cells = line.split(b",", 2)
    try:
        return float(cells[0]), float(cells[1])
    except (ValueError, IndexError):
        return None


def edge_rows(path: Path, sec: Section) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """(frame, sub frame) of the section's first and last data rows, or None when either is not numbers (the
    rows' reading then names the problem)."""
    with open(path, "rb") as f:
        first = _frame_sub(_line_at(f, sec.data_start, sec.data_end))
        back = max(sec.data_start, sec.data_end - 65536)
        f.seek(back)
        tail = f.read(sec.data_end - back).rstrip(b" \t\r\n")
    last = _frame_sub(tail[tail.rfind(b"\n") + 1 :])
    return (first, last) if first is not None and last is not None else None


def max_sub_frame(path: Path, sec: Section, piece_bytes: int) -> float:
    """The largest sub frame (second column) of a section's data rows (NaN when none is a number), read in pieces
    of about ``piece_bytes`` (:func:`imulog.converters._pieces.text_pieces`)."""
    import io

    import pandas as pd
    from imulog.converters._pieces import text_pieces

    top = np.nan
    for piece, _, _, _ in text_pieces(path, sec.line + 5, piece_bytes, span=(sec.data_start, sec.data_end)):
        if not piece.strip():
            continue
        col = pd.read_csv(io.BytesIO(piece), header=None, usecols=[1], dtype=str, skip_blank_lines=True)[1]
        top = np.fmax(top, pd.to_numeric(col.str.strip(), errors="coerce").max())
    return float(top)
