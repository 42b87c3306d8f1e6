"""HDF5 recordings in row ranges: what the three h5py readers (APDM ``.h5``, BROAD, OpenSignals ``.h5``) share.

h5py (the HDF5 C library) runs in a guarded child process (time and memory limit,
:mod:`imulog.converters._guard`). A reader first scans the file in one child (names, shapes, attributes, declared
sizes against storage, and what only the whole file decides, read in slices of :data:`SCAN_ROWS` rows: time
checks, the median step, event runs), then reads each piece's rows in a child of its own, so a hostile file ends
in one line and the parent holds one piece at a time. The whole file is the one-piece case (``piece_bytes=None``:
one row range).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from imulog.model import Recording

#: bytes of samples (float64 values of every data set a piece reads) per piece when a file is converted in pieces
PIECE_BYTES = 16 * 1024 * 1024
#: rows a scan reads at a time (its memory in the guarded child)
SCAN_ROWS = 1 << 20


def row_ranges(n: int, row_bytes: int, piece_bytes: int | None) -> list[tuple[int, int]]:
    """Consecutive ``[start, stop)`` row ranges covering ``n`` rows, each about ``piece_bytes`` of rows of
    ``row_bytes`` bytes; one range for ``piece_bytes=None`` (the whole file) or an empty file."""
    if piece_bytes is None or n <= 0:
        return [(0, max(n, 0))]
    step = max(1, int(piece_bytes) // max(1, int(row_bytes)))
    return [(a, min(n, a + step)) for a in range(0, n, step)]


def scan_slices(n: int, rows: int = SCAN_ROWS) -> Iterator[slice]:
    """Slices of at most ``rows`` rows covering ``n`` rows (how a scan reads a long data set in bounded memory)."""
    for a in range(0, n, rows):
        yield slice(a, min(n, a + rows))


def true_runs(pieces: Iterator[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(first, last) row of every run of True in a boolean mask given in consecutive pieces (runs that cross a
    piece border are one run)."""
    starts: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    prev, offset = False, 0
    for m in pieces:
        m = np.asarray(m, dtype=bool).reshape(-1)
        if not len(m):
            continue
        d = np.diff(np.concatenate([[prev], m]).astype(np.int8))
        starts.append(np.nonzero(d == 1)[0] + offset)
        ends.append(np.nonzero(d == -1)[0] + offset - 1)
        prev, offset = bool(m[-1]), offset + len(m)
    if prev:
        ends.append(np.array([offset - 1]))
    empty = np.zeros(0, dtype=np.int64)
    return (
        np.concatenate(starts).astype(np.int64) if starts else empty,
        np.concatenate(ends).astype(np.int64) if ends else empty,
    )


def declared_spans(first: Recording, last_ns: Callable[[str], int]) -> dict[str, Any]:
    """The ``imulog.pieces`` declaration (:data:`imulog.model.PIECES_RECORD`) of a reader whose scan knows every
    stream's last time: ``spans``, topic -> [its first time in the first piece, ``last_ns(topic)``] (intervals: their
    first start and last end). ``imulog convert`` takes the recording's length from it (the viewer twins' budget)."""
    spans: dict[str, list[int] | None] = {}
    for s in first.streams():
        t = getattr(s, "t_ns", None)
        if t is None:
            spans[s.topic] = [int(np.min(s.start_ns)), int(np.max(s.end_ns))] if len(s.start_ns) else None
        elif len(t):
            spans[s.topic] = [int(t[0]), int(last_ns(s.topic))]
    return {"spans": spans}


class H5Messages(NamedTuple):
    """How a reader words h5py's failures: ``opened`` when the file cannot be opened (``open_errors``), ``damaged``
    when reading it raises one of ``errors`` (both with ``{e}``, the error's text)."""

    opened: str
    damaged: str
    open_errors: tuple[type[BaseException], ...]
    errors: tuple[type[BaseException], ...]


def guarded_h5(
    path: Path, fn: Callable[..., Any], *args: Any, words: H5Messages, timeout_s: float, memory_bytes: int
) -> Any:
    """``fn(open h5py file, path, *args)`` in a guarded child (:func:`imulog.converters._guard.guarded_reader`):
    its ConversionErrors come back unchanged, h5py's errors on a damaged file as ``words`` say, a hang, crash or
    runaway allocation as one line naming h5py."""
    from imulog.converters._guard import guarded_reader

    return guarded_reader(path, "h5py", _in_file, path, fn, args, words, timeout_s=timeout_s, memory_bytes=memory_bytes)


def _in_file(path: Path, fn: Callable[..., Any], args: tuple, words: H5Messages) -> Any:
    """``fn(f, path, *args)`` on the open file (runs in the guarded child)."""
    from imulog.converters.errors import ConversionError

    try:
        import h5py
    except ImportError:  # pragma: no cover - h5py is in the hdf5 extra
        raise ConversionError(path, "reading HDF5 needs h5py: pip install 'imulog[hdf5]'") from None
    try:
        f = h5py.File(path, "r")
    except words.open_errors as e:
        raise ConversionError(path, words.opened.format(e=e)) from None
    try:
        with f:
            return fn(f, path, *args)
    except ConversionError:
        raise
    except words.errors as e:  # h5py reports damaged b-trees, heaps and chunks so, often only when data is read
        raise ConversionError(path, words.damaged.format(e=e)) from None
