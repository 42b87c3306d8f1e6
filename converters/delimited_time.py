"""Sample times of delimited text: time columns, host clocks, indices or a rate; Unix start; the median step."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._common import (
    check_increasing,
    to_ns,
    unit_factor,
)
from imulog.converters.delimited_header import Column, Layout, _tokens
from imulog.converters.delimited_plan import _Plan
from imulog.converters.errors import ConversionError
from imulog.converters.host_clock import HostClockFit

from imulog.numeric import add_counts, median_of_counts


def _is_host_clock(plan: _Plan, column: Column) -> bool:
    return "unix" in _tokens(column.name) or bool(plan.mapping and plan.mapping.host_clock)


def host_column(plan: _Plan) -> Column | None:
    """The time column when it holds host receive stamps (a Unix time column, or ``time.host_clock`` in the
    mapping file), else None."""
    time_cols = [c for c in plan.layout.columns if c.quantity == "time"]
    return time_cols[0] if time_cols and _is_host_clock(plan, time_cols[0]) else None


def host_stamps(plan: _Plan, column: Column, values: np.ndarray, origin: float | None) -> np.ndarray:
    """The host stamps of a piece as int64 ns (``origin``: the recording's first time value), as :func:`_times`
    converts them."""
    try:
        return to_ns(values[:, column.index], column.factor, origin)
    except ValueError:
        raise ConversionError(plan.path, "time stamps out of range", column=column.name) from None


def _times(
    plan: _Plan,
    values: np.ndarray,
    first_line: int,
    *,
    first_row: int = 0,
    origin: float | None = None,
    before: float | None = None,
    fit: HostClockFit | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Sample times (int64 ns) of the rows ``values`` and how they were found; ConversionError naming the line.

    For a later piece of the file: ``first_row`` its first row's index in the recording, ``origin`` the recording's
    first time value, ``before`` the last time (or index) value of the piece before it. ``fit``: the host clock
    fitted over every piece (:func:`host_stamps`), for a time column of host receive stamps.
    """
    path = plan.path
    time_cols = [c for c in plan.layout.columns if c.quantity == "time"]
    index_cols = [c for c in plan.layout.columns if c.quantity == "index"]
    if time_cols:
        tc = time_cols[0]
        try:
            t_ns = to_ns(values[:, tc.index], tc.factor, origin)
        except ValueError:
            raise ConversionError(path, "time stamps out of range", column=tc.name) from None
        time_desc: dict[str, Any] = {"column": tc.name, "unit": tc.unit}
        if fit is not None and fit.applies:
            slope, _ = fit.line()
            if not slope > 0:
                raise ConversionError(path, "host time stamps do not increase", column=tc.name)
            t_ns, off = fit.times(t_ns, first_row)
            if off is not None:
                raise ConversionError(
                    path, "host time stamp more than 1 s off the sample clock", line=first_line + off, column=tc.name
                )
            time_desc["clock"] = "host receive time with repeated stamps: least-squares fit of a uniform rate"
        _check_increasing(path, t_ns, first_line, tc.name, before)
    elif plan.rate:
        rate = float(plan.rate)
        if index_cols:
            idx = values[:, index_cols[0].index]
            _check_increasing(path, idx, first_line, index_cols[0].name, before)
            t_ns = np.round(idx * (1e9 / rate)).astype(np.int64)
        else:
            t_ns = np.round(np.arange(first_row, first_row + len(values)) * (1e9 / rate)).astype(np.int64)
        time_desc = {"column": None, "rate_hz": rate}
    else:
        raise ConversionError(path, "no time column in the header and no rate given (mapping device.rate_hz or --rate)")
    return t_ns, time_desc


def _check_increasing(path: Path, t: np.ndarray, first_line: int, column: str, before: float | None) -> None:
    """:func:`check_increasing` of ``t``, continuing from ``before`` (the previous piece's last value)."""
    check_increasing(path, t, first_line, column, before)


UNIX_S_RANGE = (9.0e8, 4.2e9)  # 1998 .. 2103: a first stamp in this range (s since 1970) is a Unix time


def unix_start(layout: Layout, values: np.ndarray, t_ns: np.ndarray) -> dict[str, str] | None:
    """``imulog.trial`` start (UTC) from a Unix time column (``Timestamp_Unix``, ``System_Timestamp``): the time
    column itself when it is one (its first, fitted, stamp), else a Unix column beside the device's clock (its
    first cell, the host time of the first sample). None when the file has no Unix time."""
    from datetime import UTC, datetime

    cols = [c for c in layout.columns if c.quantity == "time"] + [c for c in layout.columns if c.quantity == "extra"]
    for c in cols:
        tokens = _tokens(c.name)
        is_unix = "unix" in tokens or ("system" in tokens and any(t.startswith("timestamp") for t in tokens))
        if not is_unix or len(values) == 0:
            continue
        if c.quantity == "time":
            first_s = float(t_ns[0]) / 1e9
        else:
            factor = unit_factor("time", c.unit or "ms") or 1e6
            first_s = float(values[0, c.index]) * factor / 1e9
        if not UNIX_S_RANGE[0] < first_s < UNIX_S_RANGE[1]:
            continue
        when = datetime.fromtimestamp(first_s, tz=UTC)
        return {
            "start_time": when.isoformat(timespec="milliseconds"),
            "time_zone": "UTC",
            "start_time_source": f"column {c.name!r} (Unix time of the first sample)",
        }
    return None


class StepCounts:
    """How often each time step (ns) occurs, to give the whole recording's median rate (as
    :func:`estimate_rate_hz` of all time stamps) from its pieces; gives up beyond a million distinct steps."""

    MAX_DISTINCT = 1_000_000

    def __init__(self) -> None:
        self.counts: dict[int, int] = {}
        self.exact = True

    def add(self, steps: np.ndarray) -> None:
        if not self.exact or not len(steps):
            return
        add_counts(self.counts, steps)
        if len(self.counts) > self.MAX_DISTINCT:
            self.exact, self.counts = False, {}

    def rate_hz(self) -> float | None:
        """1e9 / the median step (the mean of the two middle steps for an even count), None without steps."""
        step = median_of_counts(self.counts)
        return 1e9 / step if step is not None and step > 0 else None
