"""Where a movement leaves (or reaches) rest: extrapolating the flank of its acceleration or speed to zero.

A level crossing is late by ``level / slope``: a hand starting from rest with finite jerk accelerates as
``a = j (t - t0)`` and moves at ``v = j (t - t0)^2 / 2`` (minimum jerk, Flash & Hogan 1985: ``j = 60 D / T^3``),
so a slow phase crosses any fixed level long after it began (issue 31: 0.05-0.2 s on the stroke-like grid, up to
0.85 s for a 6-s reach). Fitting that shape to the flank between the rest and a level well above the noise, with
a constant for a rest's bias, gives ``t0`` (a "hinge" fit). An offset is the same problem time-reversed (the
arrays then run from the rest after the phase into it). Pure numpy; indices are local sample indices.
"""

from __future__ import annotations

import numpy as np

from imulog.process.segmentation.flank_noise import FlankNoiseParams, impulse_response, whitener

_MAX_CELLS = 1 << 21  # candidate x sample cells per block of hinge_fit (16 MB of float64)


def hinge_fit(
    x: np.ndarray,
    y: np.ndarray,
    power: int = 1,
    drift: bool = False,
    curvature: bool = False,
    spread: list | None = None,
    whiten: np.ndarray | None = None,
    kernel: np.ndarray | None = None,
) -> float | None:
    """``t0`` (in units of ``x``, sub-sample) of the least-squares fit ``y = c + k max(x - t0, 0)^power``, ``k > 0``
    (with ``drift``: ``+ b x``; with ``curvature``: ``+ k2 max(x - t0, 0)^(power + 1)``, ``k2 <= 0``).

    ``t0`` runs over the samples of ``x`` but the last two (the vertex of the parabola through the errors
    around the best one refines it); ``c`` absorbs a constant offset (a rest's bias), ``b x`` a linear drift (a
    velocity integrated from a rest whose bias is known only to the noise of a short window), the next power
    the flank's bending towards its peak (the speed of a movement from rest is ``k t^2 + k2 t^3 + ...``;
    minimum jerk: ``30 D / T^3 (t^2 - 2 t^3 / T + ...)``, so a pure square fitted up to a few cm/s puts a slow
    phase's ``t0`` 0.1-0.3 s early; a free ``k2 > 0`` lets a slow rise of noise and drift pass for a late,
    steepening flank). None without a rising fit. ``spread``: a list that gets the standard deviation of ``t0``
    (units of ``x``) over the candidates, weighted by the likelihood ``exp(-(sse - min) / (2 s^2))``, ``s^2`` the
    best fit's residual variance (:func:`t0_spread`). ``whiten`` (n, n): the residual is weighed as ``W r`` (a
    generalised least-squares fit for noise of covariance ``(W^T W)^-1``, :mod:`~imulog.process.segmentation.flank_noise`);
    ``kernel`` (odd length, symmetric): the hinge passed through this impulse response (the low-pass the data went
    through; ``x`` evenly spaced), so the model's corner is as smooth as the data's.
    """
    n_cand = max(len(x) - 2, 0)
    if n_cand == 0:
        return None
    w = (lambda h: h) if whiten is None else (lambda h: h @ whiten.T)  # rows of samples, whitened
    basis = _baseline(x, drift, whiten)
    yc = _residual(w(y[None, :]), basis)[0]
    span = max(float(x[-1] - x[0]), 1e-12)  # powers of (x - t0) / span: a well-conditioned normal matrix
    sse = np.empty(n_cand)
    rows = max(1, _MAX_CELLS // max(len(x), 1))  # candidates per block: memory bounded whatever the length
    for lo in range(0, n_cand, rows):
        d = _hinges(x, x[lo : min(lo + rows, n_cand)], span, power, kernel)  # one row per t0
        h1 = _residual(w(d), basis)
        g11, r1 = np.einsum("ij,ij->i", h1, h1), h1 @ yc
        with np.errstate(divide="ignore", invalid="ignore"):  # least squares of y = c (+ b x) + k h (+ k2 h x)
            out = np.where((g11 > 0) & (r1 > 0), float(yc @ yc) - r1**2 / g11, np.inf)
            if curvature:  # k2 < 0 only (the flank bends towards its peak); else k2 = 0, the plain power
                h2 = _residual(w(_hinges(x, x[lo : min(lo + rows, n_cand)], span, power + 1, kernel)), basis)
                g12, g22, r2 = np.einsum("ij,ij->i", h1, h2), np.einsum("ij,ij->i", h2, h2), h2 @ yc
                det = g11 * g22 - g12**2
                k, k2 = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
                fit = (g22 * r1**2 - 2 * g12 * r1 * r2 + g11 * r2**2) / det
                out = np.where((det > 1e-12 * g11 * g22) & (k > 0) & (k2 < 0), float(yc @ yc) - fit, out)
        sse[lo : lo + len(d)] = out
    t0 = _vertex(x, sse)
    if spread is not None and t0 is not None:
        spread.append(t0_spread(x[:n_cand], sse, len(x) - len(basis) - 1 - int(curvature)))
    return t0


def t0_spread(t0: np.ndarray, sse: np.ndarray, dof: int) -> float:
    """Standard deviation (units of ``t0``) of the candidate onsets ``t0`` weighted by the likelihood of their fits,
    ``exp(-(sse - min) / (2 s^2))`` with ``s^2 = min / dof`` (white residuals): how far the data let ``t0`` move. A
    shallow flank in noise has a wide, flat error profile; a steep one a narrow one."""
    ok = np.isfinite(sse)
    best = float(np.min(sse[ok]))
    s2 = max(best / max(dof, 1), 1e-300)
    w = np.exp(-(sse[ok] - best) / (2.0 * s2))
    mean = float(np.sum(w * t0[ok]) / np.sum(w))
    return float(np.sqrt(np.sum(w * (t0[ok] - mean) ** 2) / np.sum(w)))


def _hinges(x: np.ndarray, t0: np.ndarray, span: float, power: int, kernel: np.ndarray | None) -> np.ndarray:
    """(len(t0), len(x)) rows ``(max(x - t0, 0) / span)^power``, each convolved with ``kernel`` if given (evaluated
    on ``x`` extended by half the kernel on both sides, so that the rows are exact up to their ends)."""
    if kernel is None:
        return (np.maximum(x[None, :] - t0[:, None], 0.0) / span) ** power
    from scipy.ndimage import convolve1d  # lazy, as scipy.signal

    half = len(kernel) // 2
    step = float(x[1] - x[0]) if len(x) > 1 else 1.0
    xe = float(x[0]) + step * np.arange(-half, len(x) + half)
    d = (np.maximum(xe[None, :] - t0[:, None], 0.0) / span) ** power
    return convolve1d(d, kernel, axis=1, mode="nearest")[:, half : half + len(x)]


def _vertex(x: np.ndarray, sse: np.ndarray) -> float | None:
    """``x`` at the least of the errors ``sse`` (one per candidate ``x[i]``), refined to the vertex of the parabola
    through the neighbouring errors (the onset between two samples); None when no candidate fitted."""
    if not np.isfinite(sse).any():
        return None
    i = int(np.argmin(sse))
    frac = 0.0
    if 0 < i < len(sse) - 1 and np.isfinite(sse[i - 1]) and np.isfinite(sse[i + 1]):
        curv = sse[i - 1] - 2 * sse[i] + sse[i + 1]
        if curv > 0:
            frac = float(np.clip(0.5 * (sse[i - 1] - sse[i + 1]) / curv, -0.5, 0.5))
    step = float(x[1] - x[0]) if len(x) > 1 else 1.0
    return float(x[i] + frac * step)


def _baseline(x: np.ndarray, drift: bool, whiten: np.ndarray | None = None) -> np.ndarray:
    """Orthonormal rows spanning the baseline of :func:`hinge_fit`: a constant, and a line with ``drift``
    (whitened by ``whiten``, (n, n), if given)."""
    rows = [np.ones_like(x, dtype=float)]
    if drift and len(x) > 2:
        rows.append(np.asarray(x, dtype=float) - float(np.mean(x)))
    if whiten is not None:
        return np.linalg.qr((np.array(rows) @ whiten.T).T)[0].T
    return np.array([r / np.linalg.norm(r) for r in rows])


def _residual(h: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Rows of ``h`` minus their projection on the orthonormal rows of ``basis``."""
    return h - (h @ basis.T) @ basis


def flank_zero(
    a: np.ndarray,
    first: int,
    level: float,
    top: float,
    span: int,
    back: int,
    smooth: int = 5,
    spread: list | None = None,
    rest_samples: int = 0,
    noise: FlankNoiseParams | None = None,
) -> float | None:
    """Where the acceleration flank leaving a rest starts (local sample index), by a hinge fit.

    ``a`` (n, 3) m/s^2 gravity-free acceleration in time order from the rest into the movement; ``first`` the
    current onset. A movement that starts from rest with finite jerk has an acceleration rising linearly
    from zero (minimum jerk: ``a = 60 D t / T^3`` near the onset, Flash & Hogan 1985), so a level is crossed
    ``level / jerk`` after the true onset: a slow movement crosses it late. The model ``a = 0`` before
    ``t0`` and ``k (t - t0)`` after it is fitted by least squares to the component of ``a`` along its
    direction at the flank's top (signed, so the noise does not bias it), over the samples from ``back``
    before ``first`` to the flank's top: the first sample at ``min(top, half the flank's peak)`` (a
    curved flank near its peak would tilt the line); the peak is the largest ``|a|`` within ``span`` samples
    of ``first`` and must reach twice the ``level``. Returns ``t0``, or None without such a flank;
    ``spread`` gets the line fit's spread of ``t0`` (:func:`hinge_fit`).

    ``rest_samples`` > 0: the acceleration is relative to a rest window of that many samples, so the rest's level
    before ``t0`` is zero to the precision of that window's mean: the fit gets as many zero samples before ``lo``
    (a prior on the fit's constant with the window's weight; without it a dip or bump of the low-passed noise at
    the flank's foot can pass for the rest's level and the flank's start, issue 31 thirteenth round); ``t0`` stays
    within the samples fitted.

    ``noise``: the low-passed noise's model (:mod:`~imulog.process.segmentation.flank_noise`); the line is then a
    generalised least-squares fit that weighs the filtered noise's correlation."""
    n = len(a)
    first = max(int(first), 0)
    if n == 0 or first >= n:
        return None
    an = np.linalg.norm(a, axis=1)
    window = an[first : min(n, first + span)]
    rise = np.flatnonzero(window >= 2 * level)
    if len(rise) == 0:
        return None
    # the flank's peak: the first local maximum of |a| (smoothed over ~smooth samples) after it reaches 2 levels
    sm = np.convolve(window, np.ones(smooth) / smooth, mode="same") if len(window) > smooth else window
    m = int(rise[0])
    while m + 1 < len(sm) and sm[m + 1] >= sm[m]:
        m += 1
    height = min(top, max(0.5 * float(max(sm[m], window[rise[0]])), 1.5 * level))
    p = first + int(np.flatnonzero(window >= height)[0])
    lo = max(0, first - back)
    if p - lo < 3:
        return None
    y = a[lo : p + 1] @ (a[p] / an[p])
    x = np.arange(lo, p + 1, dtype=float)
    if rest_samples <= 0:
        if noise is None:
            return hinge_fit(x, y, 1, spread=spread)
        return hinge_fit(x, y, 1, spread=spread, whiten=whitener(noise, len(x)), kernel=impulse_response(noise))
    n0 = int(rest_samples)  # the rest window's mean: zero, with the weight of its samples
    w = None if noise is None else whitener(noise, len(x), apart=n0)  # the window lies elsewhere: independent
    x, y = np.r_[np.arange(lo - n0, lo, dtype=float), x], np.r_[np.zeros(n0), y]
    t0 = hinge_fit(x, y, 1, spread=spread, whiten=w, kernel=None if noise is None else impulse_response(noise))
    return None if t0 is None else max(t0, float(lo))


def speed_flank_zero(
    v: np.ndarray, first: int, height: float, max_fit: int | None = None, spread: list | None = None
) -> float | None:
    """Where the speed leaving a rest starts to rise (local sample index), for movements too slow for their
    acceleration to clear the noise.

    ``v`` (n, 3) m/s velocity integrated from the rest (the array's start, a zero-velocity update) in time order;
    ``first`` the current onset. A movement starting from rest with finite jerk has a speed rising as
    ``(t - t0)^2`` (minimum jerk: ``30 D t^2 / T^3``; a 30-cm reach over 6 s reaches 3 cm/s only 0.85 s after it
    started, with a peak acceleration of 0.05 m/s^2, below the accelerometer's noise level). The model
    ``v = c + b t`` before ``t0`` (a bias integrated from the rest drifts linearly) and ``c + b t + k (t - t0)^2``
    after it is fitted to the component of ``v`` along its direction where
    the speed first reaches ``height`` (m/s) at or after ``first``, over the samples from the rest to there
    (at most the last ``max_fit`` of them: a rest hours long in daily life adds nothing to the fit but time).
    None when the speed does not reach ``height`` within twice the stretch already walked; ``spread`` gets the
    fit's spread of ``t0`` (:func:`hinge_fit`)."""
    n = len(v)
    first = max(int(first), 0)
    if n < 4 or first >= n:
        return None
    vn = np.linalg.norm(v, axis=1)
    hit = np.flatnonzero(vn[first : min(n, 2 * first + 4)] >= height)
    if len(hit) == 0:
        return None
    return _speed_fit(v, first + int(hit[0]), max_fit, spread=spread)


def combined_t0(z: float, zs: float | None, spread: list[float], first: int, agree: int) -> float:
    """The acceleration flank's ``t0`` ``z`` and the speed flank's ``zs`` (local samples, time order from the rest)
    averaged with weights inverse to their variances (``spread``: their sd, samples), when both exist, lie within
    ``agree`` samples of each other and ``zs`` is not after ``first`` (where the acceleration crossed its level:
    the hand moved by then); else ``z``. Two estimates of one onset from partly different samples: the
    acceleration up to half its first peak, and the acceleration summed over the speed's rise to
    ``velocity_level_mps`` (issue 31 eleventh round)."""
    if zs is None or len(spread) < 2 or abs(zs - z) >= agree or zs > first:
        return z
    wa, ws = 1.0 / max(spread[0], 1e-3) ** 2, 1.0 / max(spread[1], 1e-3) ** 2
    return float((wa * z + ws * zs) / (wa + ws))


def first_motion(
    v: np.ndarray,
    height: float,
    min_run: int,
    until: int,
    near: int,
    max_fit: int | None = None,
    scale: np.ndarray | None = None,
    late_only: bool = True,
) -> float | None:
    """Where a movement that the hand continues up to ``until`` left the rest at the array's start (local sample
    index, sub-sample).

    ``v`` (n, 3) m/s velocity integrated from a verified rest (the array's start) in time order; ``until`` the
    current boundary, inside the movement (with ``scale``, also in its last part, under ``height``: the run may
    then lie beyond ``until``, inside the phase, with no stop in between). From ``until`` back towards the
    rest, the hand moves while its speed stays at half ``height`` or more (a hand that stopped on the way, e.g. before a rest's drift, is a
    different movement); the first run of at least ``min_run`` samples at ``height`` or more after that is the
    movement's flank, and its ``t0`` (:func:`speed_flank_zero`'s model) where it began. Unlike
    :func:`speed_flank_zero` this does not need the acceleration to have crossed a level: a slow last
    submovement (the wrist no longer turning) can stay under the acceleration level for seconds at 3-13 cm/s
    (issue 31). None when the speed at ``until`` is under half ``height``, the flank starts within 3 samples
    of the rest, or the speed at the run is within half ``height`` of the line through the velocity before
    ``t0`` (the rest window's bias integrated back: a ramp, not a movement).

    ``scale`` (n,) m/s: the speed is compared with ``height`` x ``scale`` per sample instead of ``height`` (m/s)
    (``height`` then in units of the velocity's noise sd, :mod:`~imulog.process.segmentation.arrival`), the flank is
    fitted up to the run, and with ``late_only`` the run must lie beyond ``until``."""
    vn = np.linalg.norm(v, axis=1)
    unit = np.ones(len(vn)) if scale is None else np.maximum(np.asarray(scale, dtype=float), 1e-12)
    vn = vn / unit  # the speed in units of its level (m/s, or noise sd)
    until = min(int(until), len(vn) - 1)
    if until < 3:
        return None
    stops = _runs(vn[: until + 1] < 0.5 * height, min_run)  # the hand still (or a rest's slow drift)
    if len(stops) == 0 or stops[-1][1] > until:
        return None
    rest, e = stops[-1]  # the hand moves over [e, until]
    if scale is None:
        runs = [(a, b) for a, b in _runs(vn[e : until + 1] >= height, min_run) + e if a < until]
    else:  # against the noise the run may also lie beyond the boundary, inside the phase, without a stop between
        runs = [(a, b) for a, b in _runs(vn[e : max(until + 1, near)] >= height, min_run) + e]
        if runs and runs[0][0] >= until and len(_runs(vn[until : runs[0][0]] < 0.5 * height, min_run)):
            return None
    if not runs or not 3 <= runs[0][0] < near:
        return None
    low = np.flatnonzero(vn[: runs[0][0] + 1] < 0.5 * height)  # fitted up to half the height: the lower part
    p = int(low[-1]) + 1 if len(low) else runs[0][0]  # of the flank, from where the hand was last still
    if scale is not None:
        # late_only: only a boundary in the last part (under the height) with the run inside the phase; a window
        # moving with a rest's drift sees the stop before the drift as several noise sd right from the window
        if late_only and runs[0][0] < until:
            return None
        p = int(runs[0][0])  # fitted up to the run: half the noise-scaled height can be the window's bias integrated
    z = _speed_fit(v, max(p, 3), max_fit, start=int(rest))
    if z is None:
        return None
    # a movement, not the window's bias integrated (a ramp): at the run, the speed along it stands out by half the
    # height from the line through the velocity before t0
    r0 = int(runs[0][0])
    x = np.arange(int(rest), r0 + 1, dtype=float)
    y = v[int(rest) : r0 + 1] @ (v[r0] / max(float(np.linalg.norm(v[r0])), 1e-12))
    before = x <= z
    coef = np.polyfit(x[before], y[before], 1) if before.sum() >= 3 else np.array([0.0, float(y[0])])
    if y[-1] - np.polyval(coef, x[-1]) < 0.5 * height * unit[r0]:
        return None
    # against the noise, the boundary (before the run) also moves: its speed, not only the ramp's, is the stop's bound
    if scale is not None and until < r0 and y[until - int(rest)] - np.polyval(coef, until) < 0.5 * height * unit[until]:
        return None
    return z


def _runs(mask: np.ndarray, min_run: int) -> np.ndarray:
    """``[start, end)`` (k, 2) of the True runs of ``mask`` at least ``min_run`` long (one shorter at its end)."""
    d = np.diff(np.r_[0, np.asarray(mask, dtype=np.int8), 0])
    out = np.c_[np.flatnonzero(d == 1), np.flatnonzero(d == -1)].astype(np.int64)
    return out[(out[:, 1] - out[:, 0] >= min_run) | (out[:, 1] == len(mask))]


def _speed_fit(v: np.ndarray, p: int, max_fit: int | None, start: int = 0, spread: list | None = None) -> float | None:
    """``t0`` of ``v = c + b t + k max(t - t0, 0)^2 + k2 max(t - t0, 0)^3`` along ``v[p]``'s direction, fitted from
    the rest to ``p``: the model differentiated, ``dv = b + 2 k (t - t0) + 3 k2 (t - t0)^2`` (per sample), is
    fitted to the sample-to-sample differences of ``v`` (the acceleration, whose noise is white; ``v`` is its
    running sum, whose noise is a random walk that an ordinary least-squares fit of ``v`` itself weights as if it
    were white, so that a slow wander of the integrated noise passed for the flank: issue 31)."""
    speed = float(np.linalg.norm(v[p]))
    if p < 3 or speed <= 0:
        return None
    lo = max(int(start), 0 if max_fit is None else p - int(max_fit))
    if p - lo < 4:
        return None
    dv = np.diff(v[lo : p + 1] @ (v[p] / speed))  # dv[i] spans samples lo + i .. lo + i + 1
    return hinge_fit(np.arange(lo, p, dtype=float) + 0.5, dv, 1, curvature=True, spread=spread)
