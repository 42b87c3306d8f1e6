"""The frame grid of a C3D export: one point rate, analogs at a whole multiple of it, pure numpy.

C3D stores ``ANALOG:RATE = k * POINT:RATE`` (k a positive integer). :func:`plan_grid` picks the rates so
that the fastest analog channel is written sample for sample: when its rate is a whole multiple of the
marker rate (to within half an analog period over the trial) the points keep the marker rate; otherwise
the frames follow the analog channel and the points are interpolated onto them (a note says so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Grid:
    """Frames at ``point_rate_hz`` from ``g0_ns``; ``ratio`` analog samples per frame."""

    g0_ns: int
    point_rate_hz: float
    ratio: int
    frames: int
    points_resampled: bool = False

    @property
    def analog_rate_hz(self) -> float:
        return self.point_rate_hz * self.ratio

    @property
    def period_ns(self) -> float:
        return 1e9 / self.point_rate_hz

    @property
    def analog_period_ns(self) -> float:
        return self.period_ns / self.ratio

    def point_times(self) -> np.ndarray:
        return self.g0_ns + np.round(np.arange(self.frames) * self.period_ns).astype(np.int64)

    def analog_times(self) -> np.ndarray:
        return self.g0_ns + np.round(np.arange(self.frames * self.ratio) * self.analog_period_ns).astype(np.int64)


def fits(rate_hz: float, target_hz: float, span_s: float) -> bool:
    """True when samples at ``rate_hz`` placed on a ``target_hz`` grid drift < half a period over ``span_s``."""
    return target_hz > 0 and abs(rate_hz - target_hz) * span_s < 0.5


def whole_multiple(rate_hz: float, base_hz: float, span_s: float) -> int:
    """``k`` when ``rate_hz`` is ``k * base_hz`` (k >= 1, within :func:`fits`), else 0."""
    k = round(rate_hz / base_hz) if base_hz > 0 else 0
    return int(k) if k >= 1 and fits(rate_hz, k * base_hz, span_s) else 0


def aligned_start(anchor_ns: int, start_ns: int, period_ns: float) -> int:
    """The grid time at or before ``start_ns`` that is a whole number of periods from ``anchor_ns``."""
    steps = math.ceil((anchor_ns - start_ns) / period_ns - 1e-9)
    return int(round(anchor_ns - max(steps, 0) * period_ns))


def plan_grid(
    span_ns: tuple[int, int],
    marker: tuple[float, int] | None,
    analog: tuple[float, int] | None,
) -> Grid:
    """The grid covering ``span_ns`` (first, last sample of every channel written).

    ``marker`` / ``analog``: (rate on the export clock in Hz, first sample time in ns) of the marker channel
    and of the fastest analog channel, or None. The grid's phase follows the channel written as is.
    """
    start, end = span_ns
    span_s = max(end - start, 0) / 1e9
    if marker is None and analog is None:
        raise ValueError("a C3D grid needs markers or an analog channel")
    if analog is None or marker is None:
        rate, anchor = marker if analog is None else analog  # type: ignore[misc]
        ratio, resampled = 1, False
    else:
        k = whole_multiple(analog[0], marker[0], span_s)
        if k:
            rate, anchor, ratio, resampled = marker[0], marker[1], k, False
        else:  # the analog channel at its own rate, the points interpolated onto its frames
            ratio = max(1, round(analog[0] / marker[0]))
            rate, anchor, resampled = analog[0] / ratio, analog[1], True
    period = 1e9 / rate
    g0 = aligned_start(anchor, start, period)
    a_period = period / ratio
    n_analog = int(math.floor((end - g0) / a_period + 0.5)) + 1
    return Grid(g0, rate, ratio, max(1, math.ceil(n_analog / ratio)), resampled)


def place_on_grid(t_ns: np.ndarray, g0_ns: int, period_ns: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Grid index of each sample (nearest) and which samples fall on the grid [0, n)."""
    idx = np.round((np.asarray(t_ns, np.int64) - g0_ns) / period_ns).astype(np.int64)
    ok = (idx >= 0) & (idx < n)
    return idx, ok


def interp_gapped(t_src_ns: np.ndarray, values: np.ndarray, t_dst_ns: np.ndarray, period_ns: float) -> np.ndarray:
    """Linear interpolation of (N, C) values onto ``t_dst_ns``; NaN outside and across gaps > 1.5 periods."""
    t = np.asarray(t_src_ns, np.int64)
    v = np.asarray(values, np.float64).reshape(len(t), -1)
    out = np.full((len(t_dst_ns), v.shape[1]), np.nan)
    if len(t) < 2:
        return out
    k = np.clip(np.searchsorted(t, t_dst_ns, side="right") - 1, 0, len(t) - 2)
    inside = (t_dst_ns >= t[0]) & (t_dst_ns <= t[-1])
    gap_ok = (t[k + 1] - t[k]) <= 1.5 * period_ns
    frac = ((t_dst_ns - t[k]) / np.maximum(t[k + 1] - t[k], 1))[:, None]
    res = v[k] * (1.0 - frac) + v[k + 1] * frac
    ok = inside & gap_ok
    out[ok] = res[ok]
    j = np.clip(np.searchsorted(t, t_dst_ns), 0, len(t) - 1)
    exact = t[j] == t_dst_ns  # on a sample: its value, also beside a gap
    out[exact] = v[j[exact]]
    return out


def placed(t_ns: np.ndarray, values: np.ndarray, g0_ns: int, period_ns: float, n: int) -> np.ndarray:
    """(n, C) values with each sample at its nearest grid slot (no interpolation), NaN in empty slots."""
    v = np.asarray(values, np.float64).reshape(len(t_ns), -1)
    idx, ok = place_on_grid(t_ns, g0_ns, period_ns, n)
    out = np.full((n, v.shape[1]), np.nan)
    out[idx[ok]] = v[ok]
    return out
