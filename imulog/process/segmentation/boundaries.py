"""Phase-boundary refinement on the bias-corrected, lightly filtered gyroscope (an imulog addition).

DynAMoS finds movements on a gyroscope norm low-passed at 1.5 Hz. That is robust for *detecting* movements, but
its onsets and offsets are biased: the zero-phase filter smears every movement by a few hundred milliseconds and
rings (at ~8 % of the peak) before and after it, the threshold is a fraction of the trial's maximum rather than
a property of the sensor, and the static level of the norm includes the gyroscope bias (``|omega + b|``, not
``|omega|``). On smooth (minimum-jerk, bell-shaped) movements the angular velocity rises from rest as
``t^2``, so slow movements cross any fixed level late: the published method (no refinement) loses ~0.13 s at
each end, the flank refinement of :func:`~imulog.process.segmentation.dynamos.refine_boundaries` still
~0.05-0.14 s on slow phases, i.e. phase durations up to 0.3 s short.

This module places every onset and offset of the *final* phases (after event correction) where the angular
velocity leaves / returns to the sensor's own static noise:

1. ``omega`` = gyroscope (rad/s) low-passed per axis at ``cutoff_hz`` (zero-phase, 2nd order; human movement
   is below ~10 Hz, the filter only takes white noise off), a lower cut-off for a noisy gyroscope
   (:func:`adaptive_cutoff_hz`);
2. adjacent static period: the gap to the neighbouring phase (or, with ``static_window_s > 0``, its quietest
   stretch of that length); there the bias ``b`` = per-axis median and the noise = per-axis robust standard
   deviation (rms over the axes) of ``omega``;
3. ``r = |omega - b|`` (rad/s) and the level ``n_sigma x noise`` (at least ``min_level_rad_s``): the onset is
   the first sample of the run of ``r > level`` that leads into the phase's motion (then, with ``descend``,
   further out while ``r`` keeps falling), the offset likewise at the end; a boundary that would move more than
   ``max_shift_s`` outward stays where it was (the "static" period is not static: drift, slow wander);
4. corrective sub-movements: motion that resumes within ``continuation_s`` after the offset, reaches
   ``continuation_peak_fraction`` of the phase's peak ``r`` and settles before the next phase belongs to the
   phase (a reach that stops short and corrects ends when the hand arrives); the offset moves to its end.

Intervals are half-open sample ranges ``[start, end)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.param_rules import check_rules


@dataclass(frozen=True)
class BoundaryParams:
    """Parameters of :func:`refine_phase_boundaries` (imulog defaults; units in the names).

    enabled: refine the phase boundaries at all (False keeps the DynAMoS/event-correction boundaries).
    cutoff_hz: zero-phase 2nd-order Butterworth low-pass (Hz) on each gyroscope axis before the norm (the
        highest cut-off used; see :func:`adaptive_cutoff_hz`).
    target_level_rad_s: on a noisy gyroscope the cut-off is lowered until the motion level comes down to this
        (rad/s, ~1.7 deg/s); 0 = always ``cutoff_hz``.
    min_cutoff_hz: lowest cut-off (Hz) the adaptation may choose (more smoothing smears the boundaries).
    static_window_s: length (s) of the quietest stretch of the adjacent gap used for bias and noise; 0 (default)
        uses the whole gap between the neighbouring phases (robust statistics).
    min_static_s: a shorter usable gap falls back to the static estimate of the other side of the phase.
    guard_s: the static window keeps this distance (s) from the current boundary.
    n_sigma: the motion level is ``n_sigma`` x the static noise (rms per-axis sd, rad/s).
    min_level_rad_s: lower bound of the level (rad/s), for quantised, nearly noise-free signals.
    strong_fraction: the search for the onset (offset) starts at the first (last) sample of the phase whose
        ``r`` exceeds this fraction of the phase's peak ``r``: certainly inside the movement.
    descend: after the level crossing, keep moving outward while ``r`` still decreases (down to the noise).
    max_shift_s: an onset (offset) that would move more than this (s) outward from the DynAMoS boundary is
        kept where DynAMoS put it: the adjacent period is not static enough to define a level.
    continuation_s: a sub-movement starting within this time (s) after the offset can extend the phase (0 = off).
    continuation_peak_fraction: ... if its peak ``r`` reaches this fraction of the phase's peak ``r``.
    """

    enabled: bool = True
    cutoff_hz: float = 25.0
    target_level_rad_s: float = 0.03
    min_cutoff_hz: float = 6.0
    static_window_s: float = 0.0
    min_static_s: float = 0.25
    guard_s: float = 0.1
    n_sigma: float = 4.0
    min_level_rad_s: float = 0.002
    strong_fraction: float = 0.1
    descend: bool = True
    max_shift_s: float = 0.3
    continuation_s: float = 1.0
    continuation_peak_fraction: float = 0.1
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def lowpass_axes(gyr_rad_s: np.ndarray, rate_hz: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass of each axis of ``gyr_rad_s`` (N, 3) rad/s; NaN samples become 0."""
    g = np.asarray(gyr_rad_s, dtype=float)
    if g.ndim == 1:
        g = g[:, None]
    g = np.where(np.isfinite(g), g, 0.0)
    if cutoff_hz and cutoff_hz < rate_hz / 2 and len(g) > 3 * (2 * order + 1):
        from scipy.signal import butter, sosfiltfilt  # lazy: scipy.signal costs ~0.5 s to import

        sos = butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")
        g = sosfiltfilt(sos, g, axis=0)
    return g


def white_noise_rad_s(gyr_rad_s: np.ndarray) -> float:
    """Per-sample white noise (rad/s, rms over the axes) of a gyroscope: robust spread of the second
    differences (1.4826 x MAD / sqrt 6), which smooth human motion barely changes."""
    g = np.asarray(gyr_rad_s, dtype=float)
    g = g[np.all(np.isfinite(g), axis=1)]
    if len(g) < 3:
        return 0.0
    d2 = g[2:] - 2 * g[1:-1] + g[:-2]
    mad = 1.4826 * np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) / np.sqrt(6.0)
    return float(np.sqrt(np.mean(mad**2)))


def adaptive_cutoff_hz(gyr_rad_s: np.ndarray, rate_hz: float, params: BoundaryParams) -> float:
    """Low-pass cut-off (Hz) for the boundary search: ``cutoff_hz``, lowered for a noisy gyroscope until the
    motion level ``n_sigma x`` filtered noise reaches ``target_level_rad_s`` (never below ``min_cutoff_hz``).

    White noise of per-sample sd ``s`` low-passed at ``f`` keeps about ``s sqrt(2 f / rate)``.
    """
    if params.target_level_rad_s <= 0 or not params.cutoff_hz:
        return params.cutoff_hz
    noise = white_noise_rad_s(gyr_rad_s)
    if noise <= 0:
        return params.cutoff_hz
    f = (params.target_level_rad_s / (params.n_sigma * noise)) ** 2 * rate_hz / 2
    return float(np.clip(f, params.min_cutoff_hz, params.cutoff_hz))


def quietest_window(omega: np.ndarray, lo: int, hi: int, length: int) -> tuple[int, int] | None:
    """``[a, a + length)`` inside ``[lo, hi)`` with the smallest summed per-axis variance (None if too short)."""
    lo, hi = max(0, int(lo)), min(len(omega), int(hi))
    if hi - lo < 3:
        return None
    length = int(min(length, hi - lo))
    seg = omega[lo:hi]
    c1 = np.concatenate([np.zeros((1, seg.shape[1])), np.cumsum(seg, axis=0)])
    c2 = np.concatenate([np.zeros((1, seg.shape[1])), np.cumsum(seg**2, axis=0)])
    s1 = c1[length:] - c1[:-length]
    s2 = c2[length:] - c2[:-length]
    var = (s2 - s1**2 / length).sum(axis=1)
    a = lo + int(np.argmin(var))
    return a, a + length


def static_estimate(omega: np.ndarray, window: tuple[int, int], params: BoundaryParams) -> tuple[np.ndarray, float]:
    """Bias (3,) rad/s and motion level (rad/s) from a static stretch of the filtered gyroscope.

    Bias = per-axis median; noise = per-axis robust standard deviation (1.4826 x median absolute deviation,
    so that a short fidget in the stretch does not inflate it), rms over the axes; level = ``n_sigma`` x noise.
    """
    w = omega[window[0] : window[1]]
    bias = np.median(w, axis=0)
    mad = 1.4826 * np.median(np.abs(w - bias), axis=0)
    sigma = float(np.sqrt(np.mean(mad**2)))
    return bias, max(params.n_sigma * sigma, params.min_level_rad_s)


def _onset(r: np.ndarray, start: int, end: int, level: float, lo: int, strong: float, descend: bool) -> int:
    """First sample of the run above ``level`` that leads to the phase's first strong sample."""
    above = np.flatnonzero(r[start:end] >= strong)
    i = start + int(above[0]) if len(above) else start
    while i - 1 >= lo and r[i - 1] > level:
        i -= 1
    if descend:
        while i - 1 >= lo and r[i - 1] < r[i]:
            i -= 1
    return i


def _offset(r: np.ndarray, start: int, end: int, level: float, hi: int, strong: float, descend: bool) -> int:
    """Exclusive end of the run above ``level`` that leaves the phase's last strong sample."""
    above = np.flatnonzero(r[start:end] >= strong)
    j = start + int(above[-1]) + 1 if len(above) else end
    while j < hi and r[j] > level:
        j += 1
    if descend:
        while j < hi and r[j] < r[j - 1]:
            j += 1
    return j


def refine_phase_boundaries(
    gyr_rad_s: np.ndarray,
    rate_hz: float,
    start: np.ndarray,
    end: np.ndarray,
    params: BoundaryParams = BoundaryParams(),
    *,
    cutoff_hz: float | None = None,
    bounds: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Refined ``[start, end)`` sample ranges of time-ordered, non-overlapping phases (see module docstring).

    ``gyr_rad_s`` (N, 3) rad/s sampled at ``rate_hz``; ``start``/``end`` the phases to refine (e.g. after event
    correction). A boundary never crosses the neighbouring phase.

    For a piece of a longer recording (:mod:`imulog.steps.phases_windows`): ``cutoff_hz`` is the recording's
    :func:`adaptive_cutoff_hz` (Hz), and ``bounds`` (samples of the piece, default ``(0, N)``) the end of the
    phase before the first and the start of the phase after the last, so the piece's filter margins lie outside.
    """
    s = np.array(start, dtype=np.int64)
    e = np.array(end, dtype=np.int64)
    if not params.enabled or len(s) == 0:
        return s, e
    if cutoff_hz is None:
        cutoff_hz = adaptive_cutoff_hz(gyr_rad_s, rate_hz, params)
    omega = lowpass_axes(gyr_rad_s, rate_hz, cutoff_hz)
    first, n = bounds if bounds is not None else (0, len(omega))
    win = max(3, int(round(params.static_window_s * rate_hz)))
    min_static = max(3, int(round(params.min_static_s * rate_hz)))
    guard = int(round(params.guard_s * rate_hz))
    cont = int(round(params.continuation_s * rate_hz))
    shift = int(round(params.max_shift_s * rate_hz))
    order = np.argsort(s, kind="stable")
    s_sorted, e_sorted = s[order].copy(), e[order].copy()
    out_s, out_e = s_sorted.copy(), e_sorted.copy()
    for k in range(len(s_sorted)):
        a, b = int(s_sorted[k]), int(e_sorted[k])
        prev_end = int(out_e[k - 1]) if k > 0 else first
        next_start = int(s_sorted[k + 1]) if k + 1 < len(s_sorted) else n
        if params.static_window_s > 0:
            pre = quietest_window(omega, prev_end + guard, a - guard, win)
            post = quietest_window(omega, b + guard, next_start - guard, win)
        else:  # the whole gap between the phases
            pre = (prev_end + guard, a - guard) if a - prev_end > 2 * guard else None
            post = (b + guard, next_start - guard) if next_start - b > 2 * guard else None
        if pre is not None and pre[1] - pre[0] < min_static:
            pre = None
        if post is not None and post[1] - post[0] < min_static:
            post = None
        if pre is None and post is None:
            continue
        bias_pre, level_pre = static_estimate(omega, pre or post, params)
        bias_post, level_post = static_estimate(omega, post or pre, params)
        # work on the stretch between the neighbouring phases, in local sample indices (offset o)
        o = prev_end
        sub = omega[o:next_start]
        r_pre = np.linalg.norm(sub - bias_pre, axis=1)
        r_post = np.linalg.norm(sub - bias_post, axis=1)
        la, lb, end_local = a - o, b - o, next_start - o
        peak = float(r_pre[la:lb].max()) if lb > la else 0.0
        lo = (pre[0] if pre is not None else prev_end) - o
        strong = max(params.strong_fraction * peak, level_pre)
        new_a = o + _onset(r_pre, la, lb, level_pre, max(lo, 0), strong, params.descend)
        if new_a < a - shift:  # no static level near the onset (drift, slow wander): keep the DynAMoS onset
            new_a = a
        hi = (post[1] if post is not None else next_start) - o
        strong = max(params.strong_fraction * peak, level_post)
        j = _offset(r_post, la, lb, level_post, min(hi, end_local), strong, params.descend)
        if o + j > b + shift:
            j = lb
        big_level = max(params.continuation_peak_fraction * peak, level_post)
        while cont > 0:  # corrective sub-movements after the offset, before the next phase
            big = np.flatnonzero(r_post[j : min(j + cont, end_local)] >= big_level)
            if len(big) == 0:
                break
            c1 = j + int(big[0])
            bound = min(end_local, c1 + cont)
            while c1 < bound and r_post[c1] > level_post:
                c1 += 1
            while params.descend and c1 < bound and r_post[c1] < r_post[c1 - 1]:
                c1 += 1
            if c1 >= bound or c1 <= j:  # runs into the next phase or never settles: not a sub-movement
                break
            j = c1
        new_b = o + j
        if new_b <= new_a:
            continue
        out_s[k], out_e[k] = new_a, new_b
    s[order], e[order] = out_s, out_e
    return s, e
