"""Generic delimited IMU text (CSV, TSV, semicolon): units from headers, a units row, or a mapping file.

Understands
* unit-bearing headers: ``Time (s),Gyroscope X (deg/s),...,Accelerometer X (g),...,Magnetometer X (uT)``;
* Shimmer Consensys exports: a ``"sep=;"`` line, a names row (``Shimmer_40AC_Accel_LN_X_CAL``) and a units
  row (``ms;m/(s^2);...;deg/s``);
* two-row headers (a sensor row above an axis row, as in the gaitmap sample): one IMU stream per sensor;
* a mapping file (``imulog.mapping/1``, see :mod:`imulog.converters.mapping`) for exports whose headers carry no units,
  such as the BlueBuddy wrist IMU of the R2G thesis.

Recognised IMU columns go to :class:`~imulog.model.ImuStream` in SI units; other numeric columns are kept,
units as found, in a :class:`~imulog.model.SignalStream` ``/signals/<device>``.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._binary import concat_chunks
from imulog.converters._common import (
    estimate_rate_hz,
    read_head,
    text_head_lines,
    unit_overrides,
)
from imulog.converters._pieces import PIECE_BYTES, NumericPiece, iter_numeric
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.delimited_header import (
    INFER,
    Column,
    Layout,
    analyse_header,
    detect_delimiter,
)
from imulog.converters.delimited_plan import (
    PLAUSIBLE_RATE_HZ,
    TIME_UNITS,
    _assumed_units,
    _check_infinite,
    _plan,
    _units_warning,
    resolve_inferred,
)
from imulog.converters.delimited_streams import _recording
from imulog.converters.delimited_time import (
    UNIX_S_RANGE,
    StepCounts,
    _times,
    host_column,
    host_stamps,
    unix_start,
)
from imulog.converters.errors import ConversionError
from imulog.converters.host_clock import HostClockFit
from imulog.converters.mapping import Mapping, load_mapping, sibling_mapping
from imulog.converters.plausibility import MAX_CHECK_SAMPLES

from imulog.model import Recording, first_pieces

__all__ = [
    "analyse_header",
    "Column",
    "CONVERTER",
    "DelimitedConverter",
    "detect_delimiter",
    "INFER",
    "iter_delimited",
    "Layout",
    "PIECE_BYTES",
    "PLAUSIBLE_RATE_HZ",
    "read_delimited",
    "resolve_inferred",
    "TIME_UNITS",
    "UNIX_S_RANGE",
    "unix_start",
]

#: rows that decide what the header does not say (time unit, unit-less axes), whole or in pieces of any size: the
#: rows the IMU plausibility check takes whole (20 min at 100 Hz)
DECIDE_ROWS = MAX_CHECK_SAMPLES


def read_delimited(
    path: Path,
    *,
    mapping: Mapping | None = None,
    rate_hz: float | None = None,
    default_units: dict[str, str] | None = None,
    device_meta: dict[str, Any] | None = None,
    fmt: str = "delimited",
    head: bytes | None = None,
    units: dict[str, str] | None = None,
    header_lines: list[str] | None = None,
    raw: set[int] | None = None,
) -> Recording:
    """Read one delimited IMU text file into a Recording (see module docstring): :func:`iter_delimited` with the
    whole file as one piece.

    Empty or NaN cells in IMU columns are gaps (NaN in the stream); ``units`` replaces the header's unit per
    quantity (``{"gyr": "deg/s"}``); units the header does not give are inferred from the values and said in
    ``Recording.warnings``. ``header_lines``: the file's first lines as a format reader normalised them (same
    number of lines, e.g. Shimmer's four header rows as a names and a units row); ``raw``: see :func:`analyse_header`.
    """
    pieces = list(
        iter_delimited(
            path,
            mapping=mapping,
            rate_hz=rate_hz,
            default_units=default_units,
            device_meta=device_meta,
            fmt=fmt,
            head=head,
            units=units,
            header_lines=header_lines,
            raw=raw,
            piece_bytes=None,
        )
    )
    return pieces[0] if len(pieces) == 1 else concat_chunks(pieces)


def _read_ahead(pieces: Iterator[NumericPiece], rows: int) -> tuple[list[NumericPiece], np.ndarray]:
    """The first pieces of ``pieces`` that hold ``rows`` rows (all, when fewer) and those rows' values."""
    ahead, _ = first_pieces(pieces, rows, lambda piece: len(piece.values))
    if len(ahead) <= 1:
        return ahead, ahead[0].values[:rows] if ahead else np.zeros((0, 0))
    return ahead, np.concatenate([p.values for p in ahead])[:rows]


def iter_delimited(
    path: Path,
    *,
    mapping: Mapping | None = None,
    rate_hz: float | None = None,
    default_units: dict[str, str] | None = None,
    device_meta: dict[str, Any] | None = None,
    fmt: str = "delimited",
    head: bytes | None = None,
    units: dict[str, str] | None = None,
    header_lines: list[str] | None = None,
    raw: set[int] | None = None,
    piece_bytes: int | None = PIECE_BYTES,
) -> Iterator[Recording]:
    """The Recording of a delimited text file as consecutive pieces of about ``piece_bytes`` of text each (None:
    the whole file as one piece, what :func:`read_delimited` returns); options as :func:`read_delimited`.

    Every value, time stamp, gap and error (file, line, column) is the same whatever the piece size; the units the
    header lacks are inferred from the first :data:`DECIDE_ROWS` rows (the first pieces read ahead), a cut final
    row is dropped from the last.
    Host receive stamps that repeat get a uniform clock fitted over the whole recording: a first pass over the
    pieces sums the line's terms (:mod:`imulog.converters.host_clock`), the second converts, so memory stays one
    piece. While reading, the file's SHA-256 is computed (the conversion record reuses it).
    """
    path = Path(path)
    plan = _plan(
        path,
        head,
        mapping=mapping,
        rate_hz=rate_hz,
        default_units=default_units,
        device_meta=device_meta,
        fmt=fmt,
        units=units,
        header_lines=header_lines,
        raw=raw,
    )
    time_cols = [c for c in plan.layout.columns if c.quantity == "time"]
    index_cols = [c for c in plan.layout.columns if c.quantity == "index"]
    pieces = iter_numeric(plan.spec, piece_bytes)
    # what the header does not say is decided on the first DECIDE_ROWS rows, whatever the piece size: read ahead
    ahead, head = _read_ahead(pieces, DECIDE_ROWS)
    for piece in ahead:
        _check_infinite(path, plan.layout, piece.values, piece.first_line)
    assumed = _assumed_units(plan, head)
    pieces = itertools.chain(ahead, pieces)
    fit: HostClockFit | None = None
    host = host_column(plan)
    if host is not None:  # first pass: the line through every host stamp; a single piece is kept, not read again
        fit, kept = HostClockFit(), []
        origin = float(head[0, host.index]) if len(head) else None
        for k, piece in enumerate(pieces):
            _check_infinite(path, plan.layout, piece.values, piece.first_line)
            fit.add(host_stamps(plan, host, piece.values, origin))
            kept = [piece] if k == 0 else []
        pieces = iter(kept) if kept else iter_numeric(plan.spec, piece_bytes)
    first_row = 0
    origin = None  # the recording's first time value: every piece's ns are relative to it
    before: float | None = None  # the previous piece's last time (ns) or index: time must keep increasing
    rate_meta: float | None = None
    started = False
    steps = StepCounts() if time_cols and not plan.rate else None  # the exact median step, piece by piece
    for values, first_line, _, warnings, _ in pieces:
        _check_infinite(path, plan.layout, values, first_line)
        if not started and time_cols:
            origin = float(values[0, time_cols[0].index])
        t_ns, time_desc = _times(plan, values, first_line, first_row=first_row, origin=origin, before=before, fit=fit)
        if not started:
            if len(head) <= len(values):
                head_t = t_ns[: len(head)]
            else:  # the rows read ahead: their times as one block (the same as piece by piece)
                head_t = _times(plan, head, first_line, origin=origin, fit=fit)[0]
            assumed.extend(resolve_inferred(path, plan.layout, head, head_t, plan.units))
            warnings.extend(_units_warning(path, assumed))
            rate_meta = float(plan.rate) if plan.rate else estimate_rate_hz(t_ns)
        if steps is not None:
            steps.add(np.diff(t_ns) if before is None else np.diff(np.concatenate([[before], t_ns])))
            rate_meta = steps.rate_hz() if steps.exact else rate_meta  # the last piece's: the whole recording's
        if time_cols:
            before = int(t_ns[-1])
        elif index_cols:
            before = float(values[-1, index_cols[0].index])
        rec = _recording(plan, values, t_ns, time_desc, rate_meta, warnings)
        if not started:
            start = unix_start(plan.layout, values, t_ns)
            if start is not None:
                rec.metadata["imulog.trial"] = start
            started = True
        yield rec
        first_row += len(values)


class DelimitedConverter(Converter):
    name = "delimited"
    description = "delimited IMU text (CSV/TSV/semicolon; units in headers, a units row, or a mapping file)"
    extensions = (".csv", ".tsv", ".txt")
    example = "imulog convert fusion_sensor_data.csv -o trial.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head)
        if not lines:
            return 0.0
        if path.suffix.lower() in (".json", ".toml", ".md"):
            return 0.0
        if sibling_mapping(path) is not None:
            return 0.6
        try:
            layout = analyse_header(path, lines[:20])
        except ConversionError:
            return 0.0
        kinds = {c.quantity for c in layout.columns}
        if kinds & {"acc", "gyr"}:
            return 0.5
        axes = [c for c in layout.columns if c.quantity == "auto"]
        # bare X,Y,Z columns (units and quantity from the values): below every format that knows its layout
        return 0.35 if len(axes) >= 3 and {c.axis for c in axes} == {"x", "y", "z"} else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        path = Path(path)
        mapping_path = options.mapping or sibling_mapping(path)
        mapping = load_mapping(mapping_path) if mapping_path else None
        return read_delimited(
            path, mapping=mapping, rate_hz=options.rate_hz, head=read_head(path), units=unit_overrides(options.extra)
        )

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MB of text each (``imulog convert`` streams text files of 32 MB and more)."""
        options = options or ConvertOptions()
        path = Path(path)
        mapping_path = options.mapping or sibling_mapping(path)
        mapping = load_mapping(mapping_path) if mapping_path else None
        return iter_delimited(
            path,
            mapping=mapping,
            rate_hz=options.rate_hz,
            units=unit_overrides(options.extra),
            piece_bytes=_pieces.PIECE_BYTES,
        )


CONVERTER = DelimitedConverter()
