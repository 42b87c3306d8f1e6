"""How many rows the viewer sends for what it only animates: pure numpy, no Rerun.

A moving cursor in the 3D view is redrawn at the display's rate; rows between two frames are never seen. The
cursor is therefore sent at :data:`DISPLAY_RATE_HZ` (the first sample of each frame interval), while the
trajectory's time series and its line strip keep every sample. Marker class ids (labels, colours) change only
where a marker is lost or found again, so they are sent at those rows only (Rerun's latest-at query carries
them forward to the rows in between).
"""

from __future__ import annotations

import numpy as np

#: Rate (Hz) of the animated 3D cursors: about a display's frame rate.
DISPLAY_RATE_HZ = 25.0


def display_rows(t_ns: np.ndarray, rate_hz: float = DISPLAY_RATE_HZ) -> np.ndarray:
    """Indices (int64, increasing) of the samples of ``t_ns`` (int64 ns, sorted) kept at ``rate_hz``.

    The first sample of each interval of ``1 / rate_hz`` s from the first sample, and the last sample (so the
    cursor ends where the path does). A stream at or below ``rate_hz`` keeps every sample.
    """
    n = len(t_ns)
    if n <= 2:
        return np.arange(n, dtype=np.int64)
    period_ns = max(1, int(round(1e9 / rate_hz)))
    frame = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) // period_ns
    keep = np.empty(n, dtype=bool)
    keep[0] = True
    np.not_equal(frame[1:], frame[:-1], out=keep[1:])
    keep[-1] = True
    return np.flatnonzero(keep)


def pattern_changes(valid: np.ndarray) -> np.ndarray:
    """Rows (int64) of ``valid`` (N, M) bool where the set of valid columns differs from the previous row's,
    and row 0."""
    valid = np.asarray(valid, dtype=bool)
    if len(valid) == 0:
        return np.zeros(0, dtype=np.int64)
    change = np.empty(len(valid), dtype=bool)
    change[0] = True
    np.any(valid[1:] != valid[:-1], axis=1, out=change[1:])
    return np.flatnonzero(change)
