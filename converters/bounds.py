"""What a reader may allocate from what a file declares: the bounds every converter uses (issue 26).

A header's count, length, rate or end time is a claim; the bytes that follow are the evidence. Readers check a
claim against the bytes before they allocate from it, so an input of N bytes converts (or fails with one line
naming the field) in time and memory that grow with N, not with what a header says:

* :class:`RatioLimit`: decompressed members of containers (``.gt3x`` ZIP members, ``.gz``/``.zip`` wrappers) are
  read in bounded blocks and refused beyond :data:`MAX_RATIO` times their compressed size (past
  :data:`RATIO_FLOOR`), like the MCAP chunks;
* :func:`read_h5`: an HDF5 data set is read only when its declared size fits its allocated storage (HDF5 returns
  a fill value for unwritten chunks, so a 4.5 kB file can declare 2e9 rows);
* :func:`fill_budget`: NaN samples a reader may add for missing time (idle sleep, lost packets) without bytes
  behind them: :data:`FILL_SAMPLES_PER_BYTE` per byte of the input;
* :func:`check_epoch_ns`: absolute times outside 1970-2100 are errors, never wrapped.

Names taken from files (serials, labels, stream names) are capped and sanitised by
:func:`imulog.converters._common.sanitize_name` before they become topics.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters.errors import ConversionError, excerpt

MAX_RATIO = 100  # decompressed / compressed bytes of a container member, checked past RATIO_FLOOR
RATIO_FLOOR = 64 << 20
H5_MAX_RATIO = 1100  # an HDF5 filter's expansion: deflate cannot exceed 1032:1 (a constant channel reaches it)
H5_FLOOR = 64 << 20  # a data set may always declare this much
FILL_SAMPLES_PER_BYTE = 16  # NaN samples for missing time per byte of input (about 400 B of memory per byte)
FILL_FLOOR = 1 << 20  # a small file may still fill this many samples (a few minutes at 100 Hz)
MIN_EPOCH_NS = 0  # 1970-01-01T00:00:00Z
MAX_EPOCH_NS = int(datetime(2100, 1, 1, tzinfo=UTC).timestamp()) * 1_000_000_000


class RatioLimit:
    """Counts the bytes decompressed from one member; refuses more than ``ratio`` x ``compressed`` past ``floor``."""

    def __init__(
        self, path: str | Path, what: str, compressed: int, *, ratio: float = MAX_RATIO, floor: int = RATIO_FLOOR
    ) -> None:
        self.path, self.what, self.ratio = path, what, ratio
        self.compressed = int(compressed)
        self.limit = max(int(floor), int(ratio * max(int(compressed), 1)))
        self.total = 0

    def add(self, n: int) -> None:
        self.total += int(n)
        if self.total > self.limit:
            raise ConversionError(
                self.path,
                f"{self.what} decompresses to more than {self.ratio:g} times its stored size ({self.total} bytes "
                f"from {self.compressed}): refused as a likely decompression bomb; unpack it yourself if it is genuine",
            )


class BoundedStream:
    """A readable stream whose decompressed bytes count against a :class:`RatioLimit` (reads of at most ``block``)."""

    def __init__(self, stream: Any, limit: RatioLimit, block: int = 8 << 20) -> None:
        self._s, self._limit, self._block = stream, limit, block

    def read(self, n: int = -1) -> bytes:
        n = self._block if n is None or n < 0 else min(n, self._block)
        data = self._s.read(n)
        self._limit.add(len(data))
        return data

    def close(self) -> None:
        self._s.close()

    def __enter__(self) -> BoundedStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_h5(
    path: str | Path, ds: Any, name: str, *, ratio: float = H5_MAX_RATIO, dtype: Any = None, rows: slice | None = None
) -> np.ndarray:
    """The data of h5py data set ``ds`` (``name`` in messages), refused when its declared size cannot be stored
    (:func:`check_h5_size`); ``rows``: only these rows (first axis), e.g. one piece of a long recording."""
    check_h5_size(path, ds, name, ratio=ratio)
    out = ds[()] if rows is None else ds[rows]
    return np.asarray(out, dtype=dtype) if dtype is not None else np.asarray(out)


def check_h5_size(path: str | Path, ds: Any, name: str, *, ratio: float = H5_MAX_RATIO) -> None:
    """Refuse h5py data set ``ds`` (``name`` in messages) when its declared size cannot be stored.

    The declared size (shape x item size) must fit in the storage HDF5 allocated for it (x ``ratio`` for a
    filtered data set; :data:`H5_FLOOR` at least) and in the file: chunks never written (stored 0 bytes, read as
    the fill value) cannot make a small file declare gigabytes."""
    shape = tuple(int(s) for s in ds.shape)
    itemsize = int(ds.dtype.itemsize)
    declared = int(np.prod(shape, dtype=np.float64) * itemsize) if shape else itemsize
    try:
        stored = int(ds.id.get_storage_size())
    except Exception:  # noqa: BLE001 - h5py versions or virtual data sets: fall back to the file size
        stored = Path(path).stat().st_size
    stored = min(stored, Path(path).stat().st_size)
    try:  # any filter (gzip, lzf, szip, a plug-in's): the stored bytes may expand up to the ratio limit
        compressed = ds.id.get_create_plist().get_nfilters() > 0
    except Exception:  # noqa: BLE001 - not a regular data set: judge by the compression h5py names
        compressed = getattr(ds, "compression", None) is not None
    allowed = max(H5_FLOOR, stored * (ratio if compressed else 1) + (1 << 16))
    if declared > allowed:
        raise ConversionError(
            path,
            f"{name} declares shape {shape} ({declared:.3g} bytes) but stores {stored} bytes: the file is damaged "
            "or cut off (HDF5 returns a fill value for what was never written)",
        )


def fill_budget(path: str | Path) -> int:
    """NaN samples a reader may insert for missing time in ``path``: :data:`FILL_SAMPLES_PER_BYTE` per byte."""
    try:
        size = Path(path).stat().st_size
    except OSError:
        size = 0
    return max(FILL_FLOOR, FILL_SAMPLES_PER_BYTE * size)


def check_epoch_ns(path: str | Path | None, field: str, epoch_ns: Any) -> int:
    """``epoch_ns`` (ns since 1970) as an int when it lies in 1970-2100, else ConversionError naming ``field``."""
    try:
        v = int(epoch_ns)
    except (TypeError, ValueError, OverflowError):
        raise ConversionError(path, f"{field} {excerpt(epoch_ns)} is not a time") from None
    if not MIN_EPOCH_NS <= v < MAX_EPOCH_NS:
        raise ConversionError(
            path,
            f"{field} is {v / 1e9:.6g} s from 1970, outside 1970-2100: the header is damaged or the device clock "
            "was not set (set the start with --meta start_time=... after fixing the file)",
        )
    return v


def check_epoch_array(path: str | Path | None, field: str, epoch_ns: np.ndarray, offset: int = 0) -> None:
    """Every value of ``epoch_ns`` (int64 ns since 1970, or float) in 1970-2100, else ConversionError (first bad;
    ``offset``: the index of the first value in the whole array, for a piece)."""
    a = np.asarray(epoch_ns)
    if a.size == 0:
        return
    bad = ~((a >= MIN_EPOCH_NS) & (a < MAX_EPOCH_NS))
    if bad.any():
        i = int(np.argmax(bad))
        raise ConversionError(
            path, f"{field} sample {i + offset}: {float(a.reshape(-1)[i]) / 1e9:.6g} s from 1970 is outside 1970-2100"
        )
