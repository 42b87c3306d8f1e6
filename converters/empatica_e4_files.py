"""One Empatica E4 file of a session: its header (start, rate), its rows taken window by window, its span.

Every file is read by the one text cutter (:func:`imulog.converters._pieces.iter_numeric`); :class:`Rows` keeps the
rows of the cutter's last piece that lie beyond the current time window, so a session's files are read side by side
in time windows (:func:`imulog.converters.empatica_e4.iter_e4_session`). Sample ``k`` of a signal file is at
``start + k / rate`` (ns from the session origin, rounded), so a window is a row range of each file; IBI beats and
tags are events, cut by their times. :func:`span_ns` gives a file's first and last time from its header and its
end (a count of its lines and its final rows), which the first piece declares.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from imulog.converters._common import G0, TableSpec, text_head_lines
from imulog.converters._final_row import drop_cut_final_row, file_tail
from imulog.converters._pieces import NumericPiece, iter_numeric
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Intervals, SignalStream

SIGNALS = {
    "ACC": (3, "1/64 g"),
    "BVP": (1, "nW"),
    "EDA": (1, "uS"),
    "TEMP": (1, "degC"),
    "HR": (1, "bpm"),
}
FILES = set(SIGNALS) | {"IBI", "TAGS"}
ACC_G_PER_COUNT = 1.0 / 64.0  # Empatica: ACC data in 1/64 g (range +-2 g)
UNIX = re.compile(r"^\d{9,10}(\.\d*)?$")
HEAD_BYTES = 4096


def kind_of(path: Path) -> str | None:
    """``ACC``, ``BVP``, ..., ``IBI`` or ``TAGS`` for an E4 file name, else None."""
    stem = Path(path).stem.upper()
    return stem if Path(path).suffix.lower() == ".csv" and stem in FILES else None


def first_cells(lines: list[str], row: int) -> list[str]:
    return [c.strip() for c in lines[row].split(",")] if len(lines) > row else []


@dataclass
class E4File:
    """What a file's header says: ``rate`` Hz (None: events), ``offset_ns`` of its start from the session origin
    (s for tags: their cells are Unix s), the numeric block (``spec``), and whether it holds no data row."""

    path: Path
    kind: str
    spec: TableSpec
    width: int
    rate: float | None
    offset_ns: int
    origin_s: float
    unit: str = ""
    empty: bool = False
    device: dict = field(default_factory=dict)

    @property
    def topic(self) -> str:
        return {"ACC": "/imu/e4", "TAGS": "/events/e4_tags"}.get(self.kind, f"/signals/e4_{self.kind.lower()}")

    def bytes_per_s(self, span: list[int] | None) -> float:
        """About how many bytes of text one second of this file takes (the time windows are sized by it)."""
        if self.rate is not None:
            return self.rate * _line_bytes(self.path, self.spec.skip_lines)
        if span is None or span[1] <= span[0]:
            return 0.0
        return self.path.stat().st_size / max(1.0, (span[1] - span[0]) / 1e9)


def _head(path: Path) -> bytes:
    with open(path, "rb") as f:
        return f.read(HEAD_BYTES)


def _line_bytes(path: Path, skip: int) -> float:
    """The mean length of the data lines in the file's first 4 KiB (their line breaks included)."""
    rows = _head(path).split(b"\n")[skip:-1]
    return sum(len(r) + 1 for r in rows) / len(rows) if rows else 16.0


def open_e4_file(path: Path, origin_s: float, device: dict) -> E4File:
    """The header of one E4 file: ConversionError naming the file and line when it is not an E4 header."""
    path = Path(path)
    kind = kind_of(path)
    if kind is None:
        raise ConversionError(path, "not an Empatica E4 file (ACC, BVP, EDA, HR, IBI, TEMP or tags .csv)")
    head = _head(path)
    size = path.stat().st_size
    if kind == "TAGS":
        spec = TableSpec(path=path, delimiter=",", skip_lines=0, names=["tag_time"])
        return E4File(path, kind, spec, 1, None, 0, origin_s, empty=_blank_after(head, size, 0), device=device)
    lines = text_head_lines(head, 3) or []
    start_cells = first_cells(lines, 0)
    if not start_cells or not UNIX.match(start_cells[0]):
        raise ConversionError(path, "first row is not the session start (Unix seconds)", line=1)
    offset_ns = int(round((float(start_cells[0]) - origin_s) * 1e9))
    if kind == "IBI":
        spec = TableSpec(path=path, delimiter=",", skip_lines=1, names=["offset_s", "ibi_s"])
        return E4File(path, kind, spec, 2, None, offset_ns, origin_s, "s", _blank_after(head, size, 1), device)
    width, unit = SIGNALS[kind]
    rate_cells = first_cells(lines, 1)
    try:
        rate = float(rate_cells[0])
    except (IndexError, ValueError):
        raise ConversionError(path, "second row is not the sample rate (Hz)", line=2) from None
    if not 1e-3 <= rate <= 10_000:
        raise ConversionError(path, f"sample rate {rate:g} Hz is not plausible", line=2)
    if len(start_cells) != width:
        raise ConversionError(path, f"{len(start_cells)} columns, {kind}.csv has {width}", line=1)
    names = [f"{kind.lower()}_{a}" for a in "xyz"] if width == 3 else [kind.lower()]
    spec = TableSpec(path=path, delimiter=",", skip_lines=2, names=names)
    if kind == "ACC":
        device.update(rate_hz=rate, units="ACC 1/64 g (converted to m/s^2)")
    return E4File(path, kind, spec, width, rate, offset_ns, origin_s, unit, _blank_after(head, size, 2), device)


def _blank_after(head: bytes, size: int, skip: int) -> bool:
    """True when the whole file is in ``head`` and nothing but blanks follows its ``skip`` header lines."""
    if len(head) < size:
        return False
    parts = head.split(b"\n", skip)
    return len(parts) <= skip or not parts[skip].strip()


def data_rows(f: E4File) -> int:
    """The rows the numeric parse reads from the file: its lines after the header, without trailing blank lines and
    a final row cut short (:func:`~imulog.converters._final_row.drop_cut_final_row`, as the parse drops it)."""
    newlines = 0
    with open(f.path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            newlines += block.count(b"\n")
    tail, offset = file_tail(f.path)
    body = tail.rstrip(b" \t\r\n")
    lines = newlines - tail.count(b"\n", len(body)) + (1 if body else 0)
    start = 0
    if offset == 0:
        for _ in range(f.spec.skip_lines):
            start = tail.find(b"\n", start) + 1
    if start and start >= len(body):
        return 0
    end, warning = drop_cut_final_row(f.path, tail, f.spec.delimiter, start=start)
    return lines - f.spec.skip_lines - (1 if warning is not None else 0)


def _edge_value(f: E4File, last: bool) -> float | None:
    """The first cell of the file's first (or last complete) data row, None when it is not a number."""
    if last:
        tail, _ = file_tail(f.path)
        body = tail.rstrip(b" \t\r\n")
        end, warning = drop_cut_final_row(f.path, tail, f.spec.delimiter)
        body = tail[:end].rstrip(b" \t\r\n") if warning is not None else body
        row = body[body.rfind(b"\n") + 1 :]
    else:
        rows = _head(f.path).split(b"\n")
        row = rows[f.spec.skip_lines] if len(rows) > f.spec.skip_lines else b""
    try:
        return float(row.split(b",")[0])
    except ValueError:
        return None


def span_ns(f: E4File) -> list[int] | None:
    """The file's first and last time (ns from the session origin), None without rows: what the first piece declares."""
    if f.empty:
        return None
    if f.rate is not None:
        n = data_rows(f)
        if n <= 0:
            return None
        return [f.offset_ns, f.offset_ns + int(np.round((n - 1) * (1e9 / f.rate)))]
    edges = [_edge_value(f, last) for last in (False, True)]
    if edges[0] is None or edges[1] is None:
        return None
    return [int(x) for x in _event_times(f, np.array(edges, dtype=np.float64))]


def _event_times(f: E4File, first_cells: np.ndarray) -> np.ndarray:
    """IBI beats (s from the file's start) or tags (Unix s) -> ns from the session origin."""
    if f.kind == "TAGS":
        return np.round((first_cells - f.origin_s) * 1e9).astype(np.int64)
    return f.offset_ns + np.round(first_cells * 1e9).astype(np.int64)


class Rows:
    """A file's rows read by the text cutter in pieces of about ``piece_bytes`` (None: whole) and handed out by time:
    :meth:`take` gives the rows before a time, keeping the rest of the cutter's piece for the next window."""

    def __init__(self, f: E4File, piece_bytes: int | None) -> None:
        self.f = f
        self.pieces: Iterator[NumericPiece] | None = None if f.empty else iter_numeric(f.spec, piece_bytes)
        self.values = np.zeros((0, f.width))
        self.t_ns = np.zeros(0, dtype=np.int64)
        self.done = 0  # rows converted so far (a signal's sample index)
        self.before: int | None = None  # the last event time so far (beats and tags must not go back)
        self.warnings: list[str] = []

    @property
    def finished(self) -> bool:
        return self.pieces is None and not len(self.t_ns)

    def _pull(self) -> None:
        piece = next(self.pieces, None)
        if piece is None:
            self.pieces = None
            return
        v = piece.values.reshape(-1, self.f.width)
        self.warnings.extend(piece.warnings)
        if self.f.rate is not None:
            t = self.f.offset_ns + np.round(np.arange(self.done, self.done + len(v)) * (1e9 / self.f.rate)).astype(
                np.int64
            )
        else:
            t = _event_times(self.f, v[:, 0])
            d = np.diff(t if self.before is None else np.concatenate([[self.before], t]))
            bad = (d < 0) if self.f.kind == "TAGS" else (d <= 0)
            if bad.any():
                i = int(np.nonzero(bad)[0][0]) + (1 if self.before is None else 0)
                what = "tag time goes back" if self.f.kind == "TAGS" else "beat time does not increase"
                raise ConversionError(self.f.path, what, line=piece.first_line + i)
        self.done += len(v)
        if len(t):
            self.before = int(t[-1])
        if len(self.t_ns):
            v, t = np.concatenate([self.values, v]), np.concatenate([self.t_ns, t])
        self.values, self.t_ns = v, t

    def take(self, t1: int | None) -> tuple[np.ndarray, np.ndarray]:
        """(values, times) of the rows before ``t1`` ns (None: every row left)."""
        while self.pieces is not None and (t1 is None or not len(self.t_ns) or self.t_ns[-1] < t1):
            self._pull()
        k = len(self.t_ns) if t1 is None else int(np.searchsorted(self.t_ns, t1, side="left"))
        out = self.values[:k], self.t_ns[:k]
        self.values, self.t_ns = self.values[k:], self.t_ns[k:]
        return out

    def stream(self, values: np.ndarray, t_ns: np.ndarray, first: int) -> ImuStream | SignalStream | Intervals:
        """The file's stream of these rows (``first``: the number of the first event, for the tags' labels)."""
        f = self.f
        if f.kind == "TAGS":
            labels = [f"tag {first + i + 1}" for i in range(len(t_ns))]
            return Intervals(topic=f.topic, start_ns=t_ns, end_ns=t_ns.copy(), labels=labels)
        if f.kind == "IBI":  # the beat's offset from the start (s), the interval (s)
            return SignalStream(topic=f.topic, t_ns=t_ns, columns=["ibi"], units=["s"], values=values[:, 1:])
        if f.kind == "ACC":
            # stored as the file's counts: (counts / 64) * g, the same double as counts * (1/64) * g (1/64 is exact);
            # multiplied in place: one array of the piece's size, not two
            acc = values * ACC_G_PER_COUNT
            acc *= G0
            res = {"resolution": {"acc": {"divisor": 1.0 / ACC_G_PER_COUNT, "scale": G0}}}
            return ImuStream(name="e4", t_ns=t_ns, acc=acc, meta={**f.device, **res})
        return SignalStream(topic=f.topic, t_ns=t_ns, columns=list(f.spec.names), units=[f.unit], values=values)
