"""A phase as a sum of minimum-jerk submovements, fitted to its gravity-free acceleration (issue 31 point 1,
thirteenth round; an experiment, not part of the method: docs/accuracy.md, "whole-phase fit"). The model's
derivatives are shared with the oracle of ``boundary_limit.py``.

Model of one axis over a stretch of samples at times ``t`` (s): ``a(t) = c + d t + sum_i A_i mj''((t - t_i) / T_i)
/ T_i^2`` with ``mj`` the minimum-jerk profile ``10 s^3 - 15 s^4 + 6 s^5`` (0 before, 1 after), ``t_i`` (s) and
``T_i`` (s) each submovement's onset and duration (shared by the three axes), ``A_i`` (m) its displacement along the
axis, ``c`` (m/s^2) the rest window's mean error and ``d`` (m/s^3) the tilt's slow growth. The amplitudes and the
nuisance terms are linear: they are solved by least squares for every trial of the timing (variable projection),
so the search is over ``2 k`` times only.

Starts near the truth (the plain fit's local optima are the obstacle: docs/accuracy.md, the information limit):
a greedy decomposition of the velocity, one submovement at a time at the residual speed's highest peak (Rohrer
and Hogan's style), each refitted with the ones before, then every ``k`` refitted on the acceleration and chosen
by BIC. Pure numpy/scipy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

MIN_DURATION_S = 0.05  # s: a submovement's shortest duration
EDGE_S = 0.3  # s: every submovement starts and ends this far inside the stretch (observed rest on both sides)
MIN_AMPLITUDE_M = 0.01  # m: a submovement moves the hand at least this far (smaller ones fit the sensor's errors)
MAX_DURATION_S = 8.0  # s: its longest (the simulator's slowest phases last 4-8 s)
FWHM = 0.5412  # full width at half maximum of the minimum-jerk speed bell, in units of its duration


def mj_derivatives(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """d/dtau, d2/dtau2 and d3/dtau3 of the minimum-jerk profile at ``tau`` (0 outside [0, 1])."""
    inside = (tau > 0.0) & (tau < 1.0)
    x = np.where(inside, tau, 0.0)
    d1 = 30.0 * x**2 * (1.0 - x) ** 2
    d2 = 60.0 * x - 180.0 * x**2 + 120.0 * x**3
    d3 = np.where(inside, 60.0 - 360.0 * x + 360.0 * x**2, 0.0)
    return d1, d2, d3


def basis(t_s: np.ndarray, onsets_s: np.ndarray, durations_s: np.ndarray, order: int) -> np.ndarray:
    """(N, k) unit submovements' velocity (``order`` 1, 1/s) or acceleration (``order`` 2, 1/s^2) at ``t_s``."""
    cols = []
    for t0, T in zip(onsets_s, durations_s, strict=True):
        d = mj_derivatives((t_s - t0) / T)[order - 1]
        cols.append(d / T**order)
    return np.column_stack(cols) if cols else np.zeros((len(t_s), 0))


@dataclass(frozen=True)
class Decomposition:
    """Fitted submovements: ``onsets_s``, ``durations_s`` (s), ``amplitudes_m`` (k, 3, m), the residual sum of
    squares ``sse`` (units of the data squared) over ``n`` values."""

    onsets_s: np.ndarray
    durations_s: np.ndarray
    amplitudes_m: np.ndarray
    sse: float
    n: int

    @property
    def k(self) -> int:
        return len(self.onsets_s)

    @property
    def onset_s(self) -> float:
        return float(np.min(self.onsets_s))

    @property
    def offset_s(self) -> float:
        return float(np.max(self.onsets_s + self.durations_s))

    def bic(self) -> float:
        """BIC with the noise's variance unknown: ``n ln(sse / n) + p ln n``, ``p`` = 2 k times, 3 k amplitudes
        and the nuisance terms (6)."""
        return float(self.n * np.log(max(self.sse, 1e-300) / self.n) + (5 * self.k + 6) * np.log(self.n))


def _nuisance(t_s: np.ndarray, order: int, extra: np.ndarray | None = None) -> np.ndarray:
    """Columns of the nuisance terms: ``c + d t`` on the acceleration (its integral ``c t + d t^2/2`` plus a
    constant on the velocity), and ``extra`` (N, m) columns of the acceleration (their running integral on the
    velocity): e.g. the wrist's rotation angle, through which a sensor's scale and misalignment leak gravity."""
    tc = t_s - t_s.mean()
    cols = [np.ones_like(tc), tc] if order == 2 else [np.ones_like(tc), tc, tc**2]
    if extra is not None:
        x = np.asarray(extra, dtype=float).reshape(len(t_s), -1)
        if order == 1:
            x = np.cumsum(x, axis=0) * float(np.median(np.diff(t_s)))
        cols.extend(x.T)
    return np.column_stack(cols)


def _solve(y: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares coefficients (columns x 3) of ``y`` (N, 3) on ``G`` and the residual (N, 3)."""
    c = np.linalg.lstsq(G, y, rcond=None)[0]
    return c, y - G @ c


def fit_times(
    t_s: np.ndarray,
    y: np.ndarray,
    onsets_s: np.ndarray,
    durations_s: np.ndarray,
    order: int,
    fixed_onset_s: float | None = None,
    fixed_offset_s: float | None = None,
    max_nfev: int = 200,
    extra: np.ndarray | None = None,
) -> Decomposition:
    """Submovements' times fitted to ``y`` (N, 3): the velocity (``order`` 1, m/s) or the acceleration (``order`` 2,
    m/s^2) at ``t_s`` (s), started at ``onsets_s`` / ``durations_s`` (s), amplitudes and nuisance terms solved
    linearly. ``fixed_onset_s`` / ``fixed_offset_s``: the first submovement starts / the last one ends there (the
    model held to given boundaries, for the evidence against them)."""
    onsets_s, durations_s = np.asarray(onsets_s, float), np.asarray(durations_s, float)
    k = len(onsets_s)
    first, last = int(np.argmin(onsets_s)), int(np.argmax(onsets_s + durations_s))
    N = _nuisance(t_s, order, extra)
    lo_t, hi_t = float(t_s[0]) + EDGE_S, float(t_s[-1]) - EDGE_S

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        on, du = x[:k].copy(), np.maximum(x[k:], MIN_DURATION_S)
        if fixed_onset_s is not None:
            on[first] = fixed_onset_s
        if fixed_offset_s is not None:
            if last == first and fixed_onset_s is not None:
                du[last] = max(fixed_offset_s - fixed_onset_s, MIN_DURATION_S)
            else:
                on[last] = fixed_offset_s - du[last]
        return on, np.maximum(np.minimum(du, hi_t - on), MIN_DURATION_S)  # a submovement ends within the stretch

    def resid(x: np.ndarray) -> np.ndarray:
        on, du = unpack(x)
        return _solve(y, np.column_stack([basis(t_s, on, du, order), N]))[1].ravel()

    x0 = np.r_[onsets_s, np.maximum(durations_s, MIN_DURATION_S)]
    lb = np.r_[np.full(k, lo_t), np.full(k, MIN_DURATION_S)]
    ub = np.r_[np.full(k, hi_t), np.full(k, min(hi_t - lo_t, MAX_DURATION_S))]
    fit = least_squares(resid, np.clip(x0, lb + 1e-9, ub - 1e-9), bounds=(lb, ub), max_nfev=max_nfev, x_scale=0.1)
    on, du = unpack(fit.x)
    c, r = _solve(y, np.column_stack([basis(t_s, on, du, order), N]))
    return Decomposition(on, du, c[:k], float(np.sum(r**2)), r.size)


def _peak_start(t_s: np.ndarray, speed: np.ndarray) -> tuple[float, float]:
    """Onset and duration (s) of a minimum-jerk bell at ``speed``'s highest peak, its width from where the speed
    falls to half the peak on either side."""
    p = int(np.argmax(speed))
    half = 0.5 * speed[p]
    left = p
    while left > 0 and speed[left] > half:
        left -= 1
    right = p
    while right < len(speed) - 1 and speed[right] > half:
        right += 1
    width = max(float(t_s[right] - t_s[left]), 2 * (t_s[1] - t_s[0]))
    T = width / FWHM
    return float(t_s[p]) - 0.5 * T, T


def greedy_starts(
    t_s: np.ndarray,
    v: np.ndarray,
    k_max: int,
    extra: np.ndarray | None = None,
    first: tuple[float, float] | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Starts for ``k`` = 1..``k_max`` submovements from the velocity ``v`` (N, 3, m/s) at ``t_s`` (s): each step
    adds a bell at the highest peak of the residual speed (the velocity minus the submovements so far) and refits
    all of them to the velocity. ``first``: the first submovement's (onset, duration) (s), e.g. the present
    boundaries, instead of the highest peak. Returns (onsets, durations) per ``k``."""
    on, du = np.zeros(0), np.zeros(0)
    out = []
    resid = v
    for i in range(k_max):
        if i == 0 and first is not None:
            dec = fit_times(t_s, v, np.array([first[0]]), np.array([first[1]]), order=1, extra=extra)
            on, du = dec.onsets_s, dec.durations_s
            resid = _solve(v, np.column_stack([basis(t_s, on, du, 1), _nuisance(t_s, 1, extra)]))[1]
            out.append((on.copy(), du.copy()))
            continue
        t0, T = _peak_start(t_s, np.linalg.norm(resid, axis=1))
        dec = fit_times(t_s, v, np.r_[on, t0], np.r_[du, T], order=1, extra=extra)
        on, du = dec.onsets_s, dec.durations_s
        G = np.column_stack([basis(t_s, on, du, 1), _nuisance(t_s, 1, extra)])
        resid = _solve(v, G)[1]
        out.append((on.copy(), du.copy()))
    return out


def block_means(x: np.ndarray, block: int) -> np.ndarray:
    """Means of ``x`` (N, ...) over consecutive blocks of ``block`` samples (the last partial block dropped)."""
    n = (len(x) // block) * block
    return x[:n].reshape(n // block, block, *x.shape[1:]).mean(axis=1)


def decompose(
    t_s: np.ndarray,
    a: np.ndarray,
    v: np.ndarray,
    k_max: int = 4,
    extra: np.ndarray | None = None,
    present: tuple[float, float] | None = None,
) -> Decomposition:
    """The phase's submovements: greedy starts from the velocity ``v`` (N, 3, m/s) (from its highest peak, and
    from one submovement over the ``present`` (onset, offset) in s when given), each refitted to the acceleration
    ``a`` (N, 3, m/s^2) at ``t_s`` (s), ``k`` and the start chosen by BIC."""
    best = None
    starts = greedy_starts(t_s, v, k_max, extra)
    if present is not None:
        starts += greedy_starts(t_s, v, k_max, extra, (present[0], present[1] - present[0]))
    for on, du in starts:
        dec = fit_times(t_s, a, on, du, order=2, extra=extra)
        if np.any(dec.durations_s <= MIN_DURATION_S * 1.01) or np.any(
            np.linalg.norm(dec.amplitudes_m, axis=1) < MIN_AMPLITUDE_M
        ):
            continue
        if best is None or dec.bic() < best.bic():
            best = dec
    return best


def held_fit(
    t_s: np.ndarray,
    a: np.ndarray,
    v: np.ndarray,
    onset_s: float,
    offset_s: float,
    k_max: int = 4,
    extra: np.ndarray | None = None,
) -> Decomposition:
    """The phase's submovements with its first onset held at ``onset_s`` and its last end at ``offset_s`` (s):
    greedy starts from one submovement over those boundaries, ``k`` by BIC (see :func:`decompose`)."""
    best = None
    for on, du in greedy_starts(t_s, v, k_max, extra, (onset_s, offset_s - onset_s)):
        dec = fit_times(t_s, a, on, du, 2, fixed_onset_s=onset_s, fixed_offset_s=offset_s, extra=extra)
        if best is None or dec.bic() < best.bic():
            best = dec
    return best


def profile_boundary(
    t_s: np.ndarray,
    a: np.ndarray,
    start: Decomposition,
    onset_s: float,
    offsets_s: np.ndarray,
    extra: np.ndarray | None = None,
) -> tuple[np.ndarray, list[Decomposition]]:
    """The profile of the fit's residual over candidate offsets ``offsets_s`` (s, in order), the onset held at
    ``onset_s``: each refitted from the previous one (warm start from ``start``). Returns the sse per offset and
    the fits."""
    fits, sse = [], []
    prev = start
    for off in offsets_s:
        on, du = prev.onsets_s.copy(), prev.durations_s.copy()
        last = int(np.argmax(on + du))
        du[last] = max(du[last] + (off - (on[last] + du[last])), MIN_DURATION_S)
        on[last] = off - du[last]
        dec = fit_times(t_s, a, on, du, 2, fixed_onset_s=onset_s, fixed_offset_s=off, extra=extra)
        fits.append(dec)
        sse.append(dec.sse)
        prev = dec
    return np.array(sse), fits
