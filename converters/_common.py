"""Shared helpers for text converters: time stamps and names here; units (``_units``), source bytes and text lines
(``_source``), a cut final row (``_final_row``) and fast numeric tables (``_table``) are re-exported from their modules."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import numpy as np
from imulog.converters._final_row import (
    TAIL_BYTES,
    cut_row_warning,
    drop_cut_final_row,
    file_tail,
    final_row_cut,
)
from imulog.converters._source import (
    BACKGROUND_HASH_BYTES,
    HEAD_BYTES,
    decode,
    head_lines,
    is_number,
    known_sha256,
    looks_binary,
    read_head,
    read_source,
    remember_sha256,
    split_row,
    text_head_lines,
)
from imulog.converters._table import (
    ARROW_BLOCK_BYTES,
    NA_CELLS,
    TableSpec,
    locate_problem,
    read_numeric,
)
from imulog.converters._units import (
    G0,
    LENGTH_TO_M,
    NORMALISED_MAG_UNITS,
    QUANTITIES,
    SI_UNIT,
    UNIT_FACTORS,
    UNIT_QUANTITIES,
    check_unit,
    normalise_unit,
    unit_factor,
    unit_overrides,
)
from imulog.converters.errors import ConversionError

__all__ = [
    "ARROW_BLOCK_BYTES",
    "BACKGROUND_HASH_BYTES",
    "check_increasing",
    "check_unit",
    "cut_row_warning",
    "decode",
    "drop_cut_final_row",
    "estimate_rate_hz",
    "file_tail",
    "final_row_cut",
    "G0",
    "HEAD_BYTES",
    "head_lines",
    "is_number",
    "known_sha256",
    "LENGTH_TO_M",
    "locate_problem",
    "looks_binary",
    "MAX_NAME_CHARS",
    "NA_CELLS",
    "normalise_unit",
    "NORMALISED_MAG_UNITS",
    "QUANTITIES",
    "read_head",
    "read_numeric",
    "read_source",
    "remember_sha256",
    "sanitize_name",
    "SI_UNIT",
    "split_row",
    "TableSpec",
    "TAIL_BYTES",
    "text_head_lines",
    "to_ns",
    "unit_factor",
    "UNIT_FACTORS",
    "unit_overrides",
    "UNIT_QUANTITIES",
]


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


def check_increasing(
    path: Path, t_ns: np.ndarray, first_line: int, column: str | None = None, before: float | None = None
) -> None:
    """Raise ConversionError at the first duplicated or decreasing time stamp (``first_line`` = line of row 0);
    ``before``: the last time of the piece before this one, which the first row must follow."""
    if before is not None:
        t_ns = np.concatenate([[before], t_ns])
        first_line -= 1
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
