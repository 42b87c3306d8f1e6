"""The rests between a repetition's phases as evidence for the optimisation's start and reference (issue 31 point 2).

Where the hand is still, its position is known better than anywhere else: from the anthropometrics (the bottle,
the mouth) and from the protocol (the hand comes back home). :func:`rest_positions` measures an estimate there;
:func:`rest_blend_weight` judges the rotating-bias compensation of the optimisation's start by them (an option);
:func:`repetition_offsets` estimates where each repetition starts and ends relative to the trial's home, from the
start's own return displacements (the chain of rests; :func:`window_links` says which window starts where the
previous one ends, for this chain and for :mod:`imulog.process.trajectory_rest_model`'s). Times in s, positions in m.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imulog.process.minjerk import R2GWaypoints
from imulog.process.trajectory_repetitions import Repetition

# Reference coordinates per rest that do not come from the start itself (trial_waypoints): the bottle's x and y
# and the mouth's y and z from the anthropometrics (the mouth's x too when ``mouth_dx_m`` is given), and home
# (the hand's start: 0 on every axis, where the protocol puts it back on average).
ANCHORED_REST_AXES = {"bottle": (0, 1), "mouth": (1, 2), "home": (0, 1, 2)}


def rest_positions(
    t_s: np.ndarray, positions_m: np.ndarray, static_mask: np.ndarray, repetition: Repetition
) -> np.ndarray:
    """Mean position (4, 3) m of an estimate over each rest of a complete repetition, relative to its start: after
    the reach (bottle), the lift (mouth), the return of the bottle (bottle) and the return of the hand (home);
    NaN where a rest has no static sample."""
    t = np.asarray(t_s, dtype=np.float64)[repetition.start : repetition.stop]
    p = np.asarray(positions_m, dtype=np.float64)[repetition.start : repetition.stop]
    st = np.asarray(static_mask, dtype=bool)[repetition.start : repetition.stop]
    b = np.asarray(repetition.phase_bounds_s, dtype=np.float64)
    out = np.full((4, 3), np.nan)
    for k in range(4):
        hi = b[k + 1, 0] if k < 3 else t[-1]
        sel = st & (t >= b[k, 1]) & (t <= hi)
        if np.any(sel):
            out[k] = np.nanmean(p[sel] - p[0], axis=0)
    return out


def rest_blend_weight(
    t_s: np.ndarray,
    measured_m: np.ndarray,
    compensated_m: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
    mouth_x_anchored: bool = False,
) -> tuple[float, float, float]:
    """Per global axis, how much (0..1) of the rotating-bias compensation the optimisation's start should take.

    The two starts (ZUPT on the measured and on the compensated acceleration, (N, 3) m each) differ only by the
    compensation, and ZUPT is linear in the acceleration, so ``measured + w (compensated - measured)`` is ZUPT on
    the blended acceleration. The compensation is fitted to the movements' closures, whose velocity integral it
    matches even where its time course within a movement is wrong (issue 31 point 2). Its time course is judged at
    the rests instead: each complete repetition's rest positions (:func:`rest_positions`) against the reference
    coordinates that do not come from either start (:data:`ANCHORED_REST_AXES`: the anthropometric bottle and
    mouth, home), one equation per rest; ``w`` is their least-squares blend, shrunk towards 1 by its own
    uncertainty (:func:`_shrunk_weight`) and clipped to [0, 1]. An axis without such an equation, or where the
    compensation does not move the rests, keeps all of it (1)."""
    anchored = {k: set(v) for k, v in ANCHORED_REST_AXES.items()}
    if mouth_x_anchored:
        anchored["mouth"].add(0)
    targets = {
        "bottle": np.asarray(waypoints.bottle_m, dtype=np.float64),
        "mouth": np.asarray(waypoints.mouth_m, dtype=np.float64),
        "home": np.zeros(3),
    }
    r_all: list[list[list[float]]] = [[], [], []]  # per axis, per repetition: the residuals and compensations
    c_all: list[list[list[float]]] = [[], [], []]
    for rep in repetitions:
        if len(rep.phase_bounds_s) != 4:
            continue
        a = rest_positions(t_s, measured_m, static_mask, rep)
        c = rest_positions(t_s, compensated_m, static_mask, rep) - a
        for ax in range(3):
            rows = [
                (a[k, ax] - targets[name][ax], c[k, ax])
                for k, name in enumerate(("bottle", "mouth", "bottle", "home"))
                if ax in anchored[name] and np.isfinite(a[k, ax]) and np.isfinite(c[k, ax])
            ]
            if rows:
                r_all[ax].append([x for x, _ in rows])
                c_all[ax].append([y for _, y in rows])
    return tuple(_shrunk_weight(r_all[ax], c_all[ax]) for ax in range(3))


def _shrunk_weight(residuals: list[list[float]], compensations: list[list[float]]) -> float:
    """The least-squares ``w`` minimising ``sum (r + w c)^2`` (r, c in m, one list per repetition), shrunk towards
    1 (the whole compensation) by the positive-part James-Stein factor of ``w - 1`` against its standard error
    (cluster-robust by repetition: a repetition's rests share where the hand started), clipped to [0, 1]."""
    den = float(sum(np.sum(np.square(c)) for c in compensations))
    if den <= 0 or len(residuals) < 2:
        return 1.0
    w = -float(sum(np.dot(r, c) for r, c in zip(residuals, compensations, strict=True))) / den
    scores = [
        float(np.dot(np.asarray(r) + w * np.asarray(c), c)) for r, c in zip(residuals, compensations, strict=True)
    ]
    var = float(np.sum(np.square(scores))) / den**2 * len(scores) / (len(scores) - 1)
    shrink = max(0.0, 1.0 - var / (w - 1.0) ** 2) if w != 1.0 else 0.0
    return float(np.clip(1.0 + shrink * (w - 1.0), 0.0, 1.0))


def window_links(repetitions: Sequence[Repetition]) -> np.ndarray:
    """Per window (in list order), whether it starts where the previous one ends: its first rest is the previous
    window's last, so both share that rest's place (bool (K,); the first window never)."""
    reps = list(repetitions)
    return np.array([i > 0 and reps[i].start <= reps[i - 1].stop for i in range(len(reps))], dtype=bool)


def repetition_offsets(
    t_s: np.ndarray,
    initial_m: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    sigma_end_m: Sequence[float],
    sigma_home_m: float,
) -> np.ndarray:
    """Where each repetition starts relative to the trial's home (K, 2, 3) m: [k, 0] its start, [k, 1] its end.

    The hand comes back 1-3 cm from where it started, and the next repetition's bottle and mouth, fixed in the
    room, are then that much nearer or farther from its start (issue 31 point 2, cause b). Per axis, the starts
    ``o`` of consecutive windows (one window's last rest is the next one's first) solve one least squares:
    the initial estimate's displacement at each complete repetition's home rest (:func:`rest_positions`) is
    ``o[k + 1] - o[k]`` within ``sigma_end_m`` (per axis, the estimate's static-position error), and every ``o``
    is 0 within ``sigma_home_m`` (the hand rests about one home; the reference's own uncertainty at rests). The
    last window's end is its own unknown; a window that is not a complete repetition breaks the chain (no
    equation). Zero where there is nothing to chain."""
    reps = list(repetitions)
    n = len(reps)
    out = np.zeros((n, 2, 3))
    if n == 0:
        return out
    # unknowns: each window's start, plus one end per window whose successor does not start where it stops
    links = window_links(reps)
    follows = [i + 1 < n and bool(links[i + 1]) for i in range(n)]
    end_index = {}
    m = n
    for i in range(n):
        if follows[i]:
            end_index[i] = i + 1
        else:
            end_index[i] = m
            m += 1
    ends = np.full((n, 3), np.nan)
    for i, rep in enumerate(reps):
        if len(rep.phase_bounds_s) == 4:
            ends[i] = rest_positions(t_s, initial_m, static_mask, rep)[3]
    for ax in range(3):
        rows, rhs = [], []
        for i in range(n):
            if np.isfinite(ends[i, ax]):
                r = np.zeros(m)
                r[end_index[i]], r[i] = 1.0, -1.0
                rows.append(r / sigma_end_m[ax])
                rhs.append(ends[i, ax] / sigma_end_m[ax])
        if not rows:
            continue
        design = np.vstack([*rows, np.eye(m) / sigma_home_m])
        o, *_ = np.linalg.lstsq(design, np.r_[rhs, np.zeros(m)], rcond=None)
        for i in range(n):
            out[i, 0, ax], out[i, 1, ax] = o[i], o[end_index[i]]
    return out


def shifted_waypoints(waypoints: R2GWaypoints, offset_m: np.ndarray, axes: Sequence[bool]) -> R2GWaypoints:
    """The reference's waypoints for a repetition that starts ``offset_m[0]`` and ends ``offset_m[1]`` (3,) m from
    the trial's home (:func:`repetition_offsets`), on the ``axes`` given (x, y, z): the bottle and the mouth stay
    where they are in the room, so relative to this start they move by ``-offset_m[0]``; the end is
    ``offset_m[1] - offset_m[0]``."""
    use = np.asarray(axes, dtype=bool)
    start = np.where(use, offset_m[0], 0.0)
    end = np.where(use, offset_m[1], 0.0) - start
    return R2GWaypoints(
        bottle_m=tuple((np.asarray(waypoints.bottle_m) - start).tolist()),
        mouth_m=tuple((np.asarray(waypoints.mouth_m) - start).tolist()),
        end_m=tuple(end.tolist()),
    )
