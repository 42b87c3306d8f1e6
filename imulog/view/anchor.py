"""Place per-repetition IMU displacements in the Vicon world frame for the 3D view and the error panel.

The trajectory step writes each repetition's *displacement* from its first sample (``imulog.trajectory``
``origin = "repetition_start"``): a single IMU cannot know absolute position. To draw it over the Vicon path,
each repetition is anchored at the Vicon cluster position at the repetition's start. Pure numpy; times int64 ns
on the reference clock, positions m.
"""

from __future__ import annotations

import numpy as np


def interpolate_positions(
    t_query_ns: np.ndarray, t_ns: np.ndarray, pos_m: np.ndarray, max_gap_s: float | None = None
) -> np.ndarray:
    """Linear interpolation of positions (N, 3) at ``t_query_ns``; NaN outside the valid span and, with
    ``max_gap_s``, between valid samples further apart than that (s)."""
    ok = np.all(np.isfinite(pos_m), axis=1)
    out = np.full((len(t_query_ns), 3), np.nan)
    if ok.sum() < 2:
        return out
    t, p = t_ns[ok].astype(np.float64), pos_m[ok]
    tq = np.asarray(t_query_ns, dtype=np.float64)
    inside = (tq >= t[0]) & (tq <= t[-1])
    for axis in range(3):
        out[inside, axis] = np.interp(tq[inside], t, p[:, axis])
    if max_gap_s is not None:
        idx = np.clip(np.searchsorted(t, tq), 1, len(t) - 1)
        out[(t[idx] - t[idx - 1]) > max_gap_s * 1e9] = np.nan
    return out


def anchor_repetitions(
    t_ns: np.ndarray,
    displacement_m: np.ndarray,
    rep_start_ns: np.ndarray,
    ref_t_ns: np.ndarray,
    ref_pos_m: np.ndarray,
) -> np.ndarray:
    """World positions (N, 3) m: each sample's displacement plus the reference position at its repetition start.

    A sample belongs to the latest repetition starting at or before it; samples before the first start are
    anchored at the first start.
    """
    starts = np.sort(np.asarray(rep_start_ns, dtype=np.int64))
    if len(starts) == 0:
        return np.asarray(displacement_m, dtype=np.float64).copy()
    rep = np.clip(np.searchsorted(starts, t_ns, side="right") - 1, 0, len(starts) - 1)
    anchors = interpolate_positions(starts, ref_t_ns, ref_pos_m)
    return displacement_m + anchors[rep]


def position_error_cm(
    t_ns: np.ndarray, pos_m: np.ndarray, ref_t_ns: np.ndarray, ref_pos_m: np.ndarray, max_gap_s: float = 0.05
) -> np.ndarray:
    """Euclidean distance (cm) between ``pos_m`` and the reference interpolated at ``t_ns`` (NaN across
    reference gaps longer than ``max_gap_s``, as in :mod:`imulog.steps.evaluate`)."""
    ref = interpolate_positions(t_ns, ref_t_ns, ref_pos_m, max_gap_s)
    return 100.0 * np.linalg.norm(pos_m - ref, axis=1)
