"""Empatica E4 session folders (E4 connect "download session" zip, unpacked): one recording per folder.

Every signal file has the same two-line header (Empatica's "Data export" description)::

    1680686620.000000, 1680686620.000000, 1680686620.000000     (session start, Unix s, UTC, per column)
    32.000000, 32.000000, 32.000000                             (sample rate, Hz)
    -34,-23,45                                                  (samples)

Files: ``ACC.csv`` (x, y, z in 1/64 g, 32 Hz) -> ``/imu/e4`` in m/s^2; ``BVP.csv`` (photoplethysmograph, 64 Hz),
``EDA.csv`` (electrodermal activity, uS, 4 Hz), ``TEMP.csv`` (skin temperature, degC, 4 Hz), ``HR.csv`` (average
heart rate, bpm, 1 Hz, computed from BVP: starts about 10 s later) -> ``/signals/e4_<file>``; ``IBI.csv``
(first row ``start, IBI``; then the beat's offset from the start in s and the inter-beat interval in s) ->
``/signals/e4_ibi`` (irregular, one sample per beat); ``tags.csv`` (Unix s of each button press) ->
``/events/e4_tags``. Time is ns from the earliest start of the folder's files, so every file of the session is
on one time base (a file converted alone still reads its siblings' first lines for that origin).

Memory: a session (the folder's files, :meth:`EmpaticaE4Converter.iter_session`) or one file (``iter_chunks``) is
read in time windows [t0, t1) of about 16 MiB of text in all (:func:`iter_e4_session`): every file through the one
text cutter (:mod:`imulog.converters.empatica_e4_files`), a window being a row range of each signal file and the
beats and tags before t1; every piece holds every stream (empty where a file has no row in the window). The first
piece declares every stream's span (from each file's header and a count of its lines) and the IMU's meta
(``imulog.pieces``); the warnings (a final row cut short, dropped; a file without rows, left out) come with the last.
The whole session or file is the one-piece case. A damaged file stops the session with the file's one-line error
(header errors before any row is read; in pieces, of two damaged files the one whose damage comes first in time).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from datetime import UTC, datetime
from pathlib import Path

from imulog.converters import _pieces
from imulog.converters._common import text_head_lines
from imulog.converters._lab import trial_start
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.empatica_e4_files import (
    ACC_G_PER_COUNT,
    FILES,
    SIGNALS,
    UNIX,
    E4File,
    Rows,
    first_cells,
    kind_of,
    open_e4_file,
    span_ns,
)
from imulog.converters.errors import ConversionError

from imulog.model import PIECES_RECORD, Recording

__all__ = ["ACC_G_PER_COUNT", "FILES", "SIGNALS", "iter_e4_file", "iter_e4_session", "read_e4_file", "session_start"]

_kind, _first_cells, _UNIX = kind_of, first_cells, UNIX  # the names this module used before the split


def session_start(path: Path) -> float | None:
    """The Unix start (s) in the first row of an E4 file, None when it has none."""
    try:
        with open(path, "rb") as f:
            head = f.read(256)
    except OSError:
        return None
    lines = text_head_lines(head, 2) or []
    cells = first_cells(lines, 0)
    if not cells or not UNIX.match(cells[0]):
        return None
    return float(cells[0])


def folder_origin(path: Path) -> float:
    """The earliest start (Unix s) among the E4 files beside ``path``: the session's common time origin."""
    starts = [s for p in Path(path).parent.iterdir() if kind_of(p) and kind_of(p) != "TAGS" for s in [session_start(p)]]
    starts = [s for s in starts if s is not None]
    if not starts:
        raise ConversionError(path, "no E4 session start in the folder's files")
    return min(starts)


def _origin(paths: list[Path]) -> float:
    """The session origin: the folder's earliest start; tags alone (no signal file beside them): the first tag."""
    path = paths[0]
    if any(kind_of(p) not in (None, "TAGS") for p in path.parent.iterdir()):
        return folder_origin(path)
    head = path.read_bytes()[:256].split(b"\n")[0].split(b",")[0].strip()
    try:
        return float(head)
    except ValueError:
        return 0.0


def read_e4_file(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file: :func:`iter_e4_session` of one file as one piece."""
    (rec,) = iter_e4_session([Path(path)], options, piece_bytes=None)
    return rec


def iter_e4_file(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = _pieces.PIECE_BYTES
) -> Iterator[Recording]:
    """One E4 file in pieces of about ``piece_bytes`` of text (None: one piece): a session of one file."""
    return iter_e4_session([Path(path)], options, piece_bytes)


#: the longest time window (s) of a session read in pieces: E4 rows are short (3 to 10 bytes), so 16 MiB of their text
#: is about 5 hours of a session and parses to several times its size; windows of at most half an hour keep a
#: session's memory that of its first hour, whatever its length
WINDOW_S = 1800.0


def _window_ns(files: list[E4File], spans: dict[str, list[int] | None], piece_bytes: int | None) -> int | None:
    """The length of a time window (ns) holding about ``piece_bytes`` of text of all files and at most
    :data:`WINDOW_S`; None: one window."""
    if piece_bytes is None:
        return None
    per_s = sum(f.bytes_per_s(spans.get(f.topic)) for f in files)
    longest = int(WINDOW_S * 1e9)
    return longest if per_s <= 0 else max(1_000_000, min(longest, int(piece_bytes / per_s * 1e9)))


def _cut_bytes(f: E4File, spans: dict, window_ns: int, piece_bytes: int) -> int:
    """The text cutter's piece size for one file: about its text in one window, at least 256 bytes."""
    per_s = f.bytes_per_s(spans.get(f.topic))
    return max(256, min(piece_bytes, int(per_s * window_ns / 1e9))) if per_s > 0 else piece_bytes


def iter_e4_session(
    paths: Sequence[Path], options: ConvertOptions | None = None, piece_bytes: int | None = _pieces.PIECE_BYTES
) -> Iterator[Recording]:
    """The files of one E4 session (one folder) as one recording in pieces, each covering one time window of every
    file, sized so that a window holds about ``piece_bytes`` of text in all (None: the whole session, one piece).

    Every file is read by the text cutter (each file's cutter pieces about its text in one window), rows handed
    out by time (:class:`~imulog.converters.empatica_e4_files.Rows`). Every header is read first, so a damaged
    header fails before any row. A file without rows is left out with a warning (an ``IBI.csv`` of a session without
    detected beats); alone, it is an error."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise ConversionError(None, "no E4 files")
    kinds = [kind_of(p) for p in paths]
    for p, k in zip(paths, kinds, strict=True):
        if k is None:
            raise ConversionError(p, "not an Empatica E4 file (ACC, BVP, EDA, HR, IBI, TEMP or tags .csv)")
        if kinds.count(k) > 1:
            raise ConversionError(p, f"a second {k} file in the session")
    device = {
        "format": "empatica-e4",
        "model": "Empatica E4",
        "time_base": "ns from the session's earliest file start (Unix s, UTC)",
        "source": paths[0].parent.name,
    }
    origin_s = _origin(paths)
    files = [open_e4_file(p, origin_s, device) for p in paths]  # every header before any row
    warnings: list[str] = []
    for f in files:
        if f.empty and f.kind != "TAGS":
            if len(files) == 1:
                raise ConversionError(f.path, "no data rows", line=f.spec.skip_lines + 1)
            warnings.append(f"{f.path.name}: no data rows: left out")
    files = [f for f in files if not f.empty or f.kind == "TAGS"]
    spans = {f.topic: span_ns(f) for f in files} if piece_bytes is not None else {}
    window = _window_ns(files, spans, piece_bytes)
    # each file cut into pieces of about its text in one window (a tiny file: one piece of at most piece_bytes)
    rows = [Rows(f, None if window is None else _cut_bytes(f, spans, window, piece_bytes)) for f in files]
    starts = [s[0] for f in files if f.kind != "TAGS" for s in [spans.get(f.topic)] if s is not None]
    t1 = None if window is None else min(starts, default=0) + window
    counts = [0] * len(rows)
    first = True
    while True:
        taken = [r.take(t1) for r in rows]
        last = all(r.finished for r in rows)
        if not last and not any(len(t) for _, t in taken):
            t1 += window
            continue
        rec = Recording(sources=[str(p) for p in paths])
        for k, (r, (v, t)) in enumerate(zip(rows, taken, strict=True)):
            stream = r.stream(v, t, counts[k])
            counts[k] += len(t)
            if r.f.kind == "TAGS":
                rec.events.append(stream)
            elif r.f.kind == "ACC":
                rec.imus.append(stream)
            else:
                rec.signals.append(stream)
        if first:
            rec.metadata["imulog.device.e4"] = dict(device)
            _start(rec, origin_s, files, taken, spans)
            if window is not None:
                declared = {f.topic: spans[f.topic] for f in files if spans.get(f.topic) is not None}
                rec.metadata[PIECES_RECORD] = {"spans": declared, "meta": {s.topic: dict(s.meta) for s in rec.imus}}
            first = False
        if last:
            rec.warnings = [*warnings, *(w for r in rows for w in r.warnings)]
        yield rec
        del rec, taken  # not held while the next window is read
        if last:
            return
        t1 += window


def _start(rec: Recording, origin_s: float, files: list[E4File], taken: list, spans: dict) -> None:
    """``start_time``: the wall time of the session's first sample (tags aside): from the declared spans in pieces,
    from the samples in one piece (it holds them all)."""
    if spans:
        firsts = [spans[f.topic][0] for f in files if f.kind != "TAGS" and spans.get(f.topic) is not None]
    else:
        firsts = [int(t[0]) for f, (_, t) in zip(files, taken, strict=True) if f.kind != "TAGS" and len(t)]
    if not firsts:
        return
    # start_time is the wall time of the first sample (the trial's time axis starts there); t_ns stay on the session
    # origin, so files converted one by one line up, and a folder's files start at its earliest
    first_s = origin_s + min(firsts) / 1e9
    rec.metadata["imulog.trial"] = trial_start(datetime.fromtimestamp(first_s, tz=UTC), "E4 files' first row (Unix s)")


class EmpaticaE4Converter(Converter):
    name = "empatica-e4"
    description = "Empatica E4 session folder (ACC 1/64 g, BVP, EDA, HR, IBI, TEMP, tags .csv; one trial per folder)"
    extensions = (".csv",)
    example = "imulog convert ../shared/data/devices/empatica_e4 -o e4"

    def sniff(self, path: Path, head: bytes) -> float:
        kind = kind_of(path)
        if kind is None:
            return 0.0
        lines = text_head_lines(head, 3)
        first = first_cells(lines, 0) if lines else []
        if kind == "TAGS":
            return 0.6 if first and UNIX.match(first[0]) else 0.0
        if kind == "IBI":
            ok = len(first) == 2 and UNIX.match(first[0]) and first[1].upper() == "IBI"
        else:
            width = SIGNALS[kind][0]
            second = first_cells(lines, 1) if lines else []
            ok = len(first) == width and all(UNIX.match(c) for c in first) and len(second) == width
        if ok:
            return 0.9
        # a session's file whose header is damaged (cut, missing) is still the session's: its reader names the damage
        return 0.5 if _has_session_sibling(Path(path)) else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).parent.name or "e4"

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_e4_file(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """One file in time windows of about 16 MB of text (see :func:`iter_e4_session`)."""
        return iter_e4_session([Path(path)], options, piece_bytes=_pieces.PIECE_BYTES)

    def iter_session(
        self, paths: Sequence[Path], options: ConvertOptions | None = None, *, whole: bool = False
    ) -> Iterator[Recording]:
        """The folder's files as one recording in time windows of about 16 MB of text (``whole``: one piece)."""
        return iter_e4_session(paths, options, piece_bytes=None if whole else _pieces.PIECE_BYTES)


def _has_session_sibling(path: Path) -> bool:
    """True when another E4 file beside ``path`` starts with a session start (a file of the same session)."""
    try:
        return any(p != path and kind_of(p) not in (None, "TAGS") and session_start(p) for p in path.parent.iterdir())
    except OSError:
        return False


CONVERTER = EmpaticaE4Converter()
