"""The heading carried through rests (``AnchorParams.heading="gyroscope"``, issue 31 point 2), window by window.

A rest keeps the filter's tilt but the heading the gyroscope carried through the movement before it, so the heading
chains from rest to rest. The chain restarts at every rest where the trajectory step may cut a window
(:func:`restart_rests`: a rest of the phases' mask at least ``TrajectoryWindows.chain_rest_s`` long and not inside
a repetition): the movement into it arrives at the filter's tilt over the rest's first ``bias_window_s`` with the
heading carried, the rest's first half keeps that orientation and its second half the filter's orientation at the
rest's last sample, where the next chain starts; each chain between two restarts is turned about the vertical so
that its mean heading equals the filter's over its samples (restart rests left out). Everything a chain computes
then comes from its own samples and the ends of its two restart rests, so a window that starts and ends at such
rests computes what the whole recording computes on the samples it owns (up to the middles of those rests; the
other half of an edge rest is the next chain's in the whole computation and the window's own chain in the window).
Pure numpy; times in s, rates in rad/s, quaternions w,x,y,z sensor-to-global.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

Z_AXIS = np.array([0.0, 0.0, 1.0])


def restart_rests(
    static: np.ndarray, t_s: np.ndarray, min_rest_s: float, repetitions_s: Sequence[tuple[float, float]] = ()
) -> np.ndarray:
    """(N,) bool: the samples of the runs of ``static`` (the phases step's zero-velocity mask) of at least
    ``min_rest_s`` s (in samples at the mean rate of ``t_s``, as the step's window plan counts them) whose middle
    lies outside every repetition ``(start s, end s)`` of ``repetitions_s``: where the trajectory step may cut a
    window (``imulog.steps.windows.rest_windows``: at a rest, never inside a repetition). A rest at either end of
    the samples counts whatever its length: a window that reads only ``context_s`` of a long rest starts there."""
    from imulog.process.rest_runs import static_runs

    m = np.asarray(static, dtype=bool)
    t = np.asarray(t_s, dtype=np.float64)
    out = np.zeros(len(m), dtype=bool)
    if len(m) < 2:
        return out
    rate = (len(t) - 1) / max(t[-1] - t[0], 1e-9)
    spans = np.asarray(list(repetitions_s), dtype=np.float64).reshape(-1, 2)
    shortest = max(1, int(round(min_rest_s * rate)))
    for a, b in static_runs(m):
        if b - a < shortest and a > 0 and b < len(m):  # a rest at either end: a window starts or ends there
            continue
        mid = t[(int(a) + int(b) - 1) // 2]
        if not np.any((spans[:, 0] < mid) & (mid < spans[:, 1])):
            out[a:b] = True
    return out


def _levelled(vertical: np.ndarray, heading_from: np.ndarray) -> np.ndarray:
    """One orientation (4,) with the tilt of ``vertical`` (K, 3), the rest's vertical in the sensor frame per sample
    (unit vectors; averaged over the samples), and the heading of ``heading_from`` (4,): ``heading_from`` turned by
    the least rotation that maps its vertical onto that mean."""
    from imulog.process import quaternion as quat

    up = np.nanmean(vertical, axis=0)
    if not np.all(np.isfinite(up)):  # no valid sample in the rest: keep the heading's own tilt
        return np.asarray(heading_from, dtype=np.float64)
    return quat.normalize(quat.multiply(quat.from_two_vectors(quat.rotate(heading_from, up), Z_AXIS), heading_from))


def heading_offset(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Angle (rad) about the vertical of the global-frame rotation from ``q_b`` to ``q_a`` (both (..., 4))."""
    from imulog.process import quaternion as quat

    d = quat.multiply(q_a, quat.conjugate(q_b))
    return 2.0 * np.arctan2(d[..., 3], d[..., 0])


def _finite_rows(q: np.ndarray, lo: int, hi: int) -> np.ndarray:
    return lo + np.flatnonzero(np.all(np.isfinite(q[lo:hi]), axis=1))


def _near_start(t: np.ndarray, lo: int, hi: int, window_s: float) -> slice:
    """The samples of ``[lo, hi)`` within ``window_s`` s of its start (at least one)."""
    return slice(lo, max(lo + 1, min(hi, int(np.searchsorted(t, t[lo] + window_s, side="right")))))


def _mean_angle(off: np.ndarray) -> float:
    off = off[np.isfinite(off)]
    return float(np.arctan2(np.mean(np.sin(off)), np.mean(np.cos(off)))) if len(off) else 0.0


def rest_verticals(q: np.ndarray, acc: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) the vertical in the sensor frame per sample: the filter's (``q`` (N, 4) sensor-to-global), or with
    ``acc`` (N, 3) m/s^2, the accelerometer's specific force in the sensor frame, the direction it measures (at a
    rest, gravity's; ``AnchorParams.rest_tilt = "accelerometer"``)."""
    from imulog.process import quaternion as quat

    if acc is None:
        return quat.rotate_inverse(q, np.tile(Z_AXIS, (len(q), 1)))
    a = np.asarray(acc, dtype=np.float64)
    norm = np.linalg.norm(a, axis=1, keepdims=True)
    return a / np.where(norm > 0, norm, np.nan)


def heading_through_rests(
    q: np.ndarray,
    gyr: np.ndarray,
    t: np.ndarray,
    static: np.ndarray,
    params: Any,
    restart: np.ndarray | None = None,
    acc: np.ndarray | None = None,
) -> np.ndarray:
    """Orientation (N, 4) with the heading carried through rests (``params``: ``AnchorParams``), the chain
    restarted at the rests that overlap ``restart`` (:func:`restart_rests`; None: one chain over the recording).

    Rests are constant (the filter's mean tilt, the heading carried from the movement before) and movements are
    integrated from the gyroscope between them; a movement that cannot be integrated (too long, NaN gyroscope or
    filter) is the filter's turned to the heading reached, and a rest without a valid filter sample keeps the
    orientation reached. In a restart rest the movement into it ends at the filter's tilt over its first
    ``bias_window_s`` with the heading carried (the rest's first half keeps it), the movement out of it starts at
    the filter's orientation at its last valid sample (the rest's second half keeps it; the recording's last rest
    stays with the chain before it). Each chain is then turned about the vertical onto the filter's mean
    heading over its samples (restart rests excluded; the frame the align step fitted). ``acc`` (N, 3) m/s^2, the
    accelerometer in the sensor frame: each rest's tilt is the direction it measures averaged over the rest instead
    of the filter's (:func:`rest_verticals`)."""
    from imulog.process import quaternion as quat
    from imulog.process.rest_runs import rest_bias, spread_to, static_runs, through_movement

    out = q.copy()
    up = rest_verticals(q, acc)
    up[~np.all(np.isfinite(q), axis=1)] = np.nan  # a rest's tilt only where the filter is valid
    rests = [(int(a), int(b)) for a, b in static_runs(static)]
    rests = [r for r in rests if len(_finite_rows(q, *r))]
    if not rests:
        return out
    is_restart = [restart is not None and bool(np.any(restart[a:b])) for a, b in rests]
    chain_of = np.full(len(q), 0)  # the chain each sample is turned with
    in_mean = np.ones(len(q), dtype=bool)  # samples whose offset sets their chain's turn (not a restart rest's)
    s0, e0 = rests[0]
    if is_restart[0]:
        out[s0:e0] = cur = q[_finite_rows(q, s0, e0)[-1]]
        in_mean[s0:e0] = False
    else:
        out[s0:e0] = cur = _levelled(up[s0:e0], q[_finite_rows(q, s0, e0)[0]])
    chain = 0
    for k, ((_, a), (b, e2)) in enumerate(zip(rests[:-1], rests[1:], strict=True)):  # movement [a, b)
        to_restart = is_restart[k + 1]
        w = gyr[a - 1 : b + 1]
        tilt = up[_near_start(t, b, e2, params.bias_window_s)] if to_restart else up[b:e2]  # (a window may cut it)
        if t[b] - t[a - 1] > params.max_movement_s or not np.all(np.isfinite(w)):
            off = heading_offset(cur, q[a - 1]) if np.all(np.isfinite(q[a - 1])) else 0.0
            turn = quat.from_axis_angle(Z_AXIS, float(off))
            out[a:b] = quat.multiply(turn, q[a:b])
            nxt = _levelled(tilt, quat.multiply(turn, q[_finite_rows(q, b, e2)[0]]))
        else:
            bias = rest_bias(gyr, t, static, a, params.bias_window_s)
            free = through_movement(cur, w, t[a - 1 : b + 1], bias, None, params.spread)
            nxt = _levelled(tilt, free[-1])
            out[a - 1 : b + 1] = (
                free if params.spread == "none" else spread_to(free, w, t[a - 1 : b + 1], bias, nxt, params.spread)
            )
        chain_of[a:b] = chain
        out[b:e2] = cur = nxt
        chain_of[b:e2] = chain
        if to_restart and k + 2 < len(rests):  # from the rest's middle on: the filter's, where the next chain starts
            m = (b + e2) // 2
            in_mean[b:e2] = False
            out[m:e2] = cur = q[_finite_rows(q, b, e2)[-1]]
            chain += 1
            chain_of[m:] = chain
        elif to_restart:
            in_mean[b:e2] = False
    # each chain onto the filter's mean heading over its samples (the frame the align step fitted)
    off = heading_offset(q, out)
    for c in range(chain + 1):
        sel = chain_of == c
        if sel.any():
            turn = quat.from_axis_angle(Z_AXIS, _mean_angle(off[sel & in_mean]))
            out[sel] = quat.multiply(turn, out[sel])
    # before the first rest and after the last: the filter's, turned to the heading at that rest
    for lo, hi, ref in ((0, s0, s0), (rests[-1][1], len(q), rests[-1][1] - 1)):
        if hi > lo and np.all(np.isfinite(q[ref])):
            out[lo:hi] = quat.multiply(quat.from_axis_angle(Z_AXIS, float(heading_offset(out[ref], q[ref]))), q[lo:hi])
    return quat.normalize(out)
