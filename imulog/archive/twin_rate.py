"""Which samples a viewer twin keeps: every k-th, for at most :data:`TWIN_RATE_HZ` and :data:`MAX_TWIN_MESSAGES`.

Part of :mod:`imulog.archive.twins` (which re-exports these names); recordings longer than
:data:`OVERVIEW_AFTER_S` get one sample per :data:`OVERVIEW_EPOCH_S`; IMU axes are low-passed first
(:func:`decimated`, :mod:`imulog.archive.twin_filter`).
"""

from __future__ import annotations

import math

import numpy as np

from imulog.model import ImuStream

# At most this rate (every k-th sample of the canonical channel). A preview for Foxglove and Rerun's MCAP loader:
# 25 Hz keeps a wrist's movements (below ~10 Hz) and costs about 6 % of a 100 Hz IMU trial's size, where 50 Hz
# cost 12 % (MCAP indexes every message uncompressed); imulog's own viewer and every step read the full rate.
TWIN_RATE_HZ = 25.0
MAX_TWIN_MESSAGES = 180_000  # 2 h at 25 Hz; longer recordings get a proportionally lower twin rate
# Recordings longer than this (home monitoring, days) get an epoch-rate overview instead: one low-passed sample
# per OVERVIEW_EPOCH_S (a day 8 640 messages, 0.5 MB; a week 60 480). Issue 28: the 25 Hz copy budgeted to
# 180 000 messages cost 10.5 MB a day, 7 % of the archive. Short trials keep 25 Hz.
OVERVIEW_AFTER_S = 3 * 3600.0
OVERVIEW_EPOCH_S = 10.0


def decimation(t_ns: np.ndarray, rate_hz: float = TWIN_RATE_HZ, max_messages: int = MAX_TWIN_MESSAGES) -> np.ndarray:
    """Indices of the samples a twin keeps: every k-th, k chosen for <= ``rate_hz`` and <= ``max_messages``."""
    n = len(t_ns)
    if n < 2:
        return np.arange(n)
    return np.arange(0, n, decimation_step(n, float(np.median(np.diff(t_ns))), rate_hz, max_messages))


def decimation_step(
    n: int, median_dt_ns: float, rate_hz: float = TWIN_RATE_HZ, max_messages: int = MAX_TWIN_MESSAGES
) -> int:
    """The ``k`` of :func:`decimation` for ``n`` samples whose median sampling interval is ``median_dt_ns`` (ns)."""
    src_rate = 1e9 / median_dt_ns if median_dt_ns > 0 else rate_hz
    k = max(1, math.ceil(src_rate / rate_hz - 1e-9), math.ceil(n / max_messages))
    if n / src_rate > OVERVIEW_AFTER_S:  # its length in samples over its rate (not the span: clock jumps)
        k = max(k, overview_step(src_rate))
    return k


def overview_step(rate_hz: float) -> int:
    """Every k-th sample of a long recording's twin: one per :data:`OVERVIEW_EPOCH_S`."""
    return max(1, math.ceil(rate_hz * OVERVIEW_EPOCH_S - 1e-9))


def decimated(stream: ImuStream) -> tuple[np.ndarray, ImuStream]:
    """The kept indices of a twin and the stream at them, low-passed first (:mod:`imulog.archive.twin_filter`)."""
    from imulog.archive.twin_filter import lowpassed

    keep = decimation(stream.t_ns)
    k = int(keep[1] - keep[0]) if len(keep) > 1 else 1
    return keep, lowpassed(stream, keep, k)
