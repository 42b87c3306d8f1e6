"""A phase's last movement fitted with one smooth speed profile, its arrival extrapolated (issue 31 point 1).

Step 9 of :mod:`~imulog.process.segmentation.hand`. A slow phase's last part decelerates at a few hundredths of
m/s^2 for seconds: a 0.5-s rest window placed there takes the deceleration for the sensor's bias (a constant
acceleration and an accelerometer bias are the same thing to one window) and the velocity integrated from it
hardly moves, so the phase ends seconds early; and the last 0.1-0.3 s of a 5-6-s minimum-jerk phase move at
under 2 mm/s, below what the sensors resolve. What tells a deceleration from a rest is the jerk over seconds:
a minimum-jerk movement (Flash & Hogan 1985) of ``D`` m over ``T`` s decelerates as
``a(s) = -60 D / T^2 (s - 3 s^2 + 2 s^3)``, ``s`` the time left to the arrival in units of ``T``: the deceleration
fades linearly to zero at the arrival, then the hand rests.

The model ``a = c + K g((t_end - t) / T)`` (``g(s) = s - 3 s^2 + 2 s^3`` on ``0 < s < 1``, 0 after the
arrival; ``c`` per axis, the far window mean's error; ``K`` a 3-vector, the movement's direction and size) is
fitted by least squares to the gravity-free acceleration
(:func:`~imulog.process.segmentation.arrival.gravity_free`) relative to a rest window near the end of the gap,
from a little inside the phase (where the wrist's rotation is small) to that window, over a grid of ``t_end``
and ``T``. (A free line ``b t`` as well, for the tilt of a gyroscope bias error, let a ramp and a long
deceleration stand for a sharp stop: offsets went 1-2.6 s into plain rests.) The fitted arrival is kept when
it lies beyond the phase's first rest window (that window lay inside the movement), the fitted movement starts
after the phase's onset and the offset lies in its main deceleration (``profile_min_s`` of ``T`` or more before
the arrival), it decelerates along the phase's motion, its speed at the offset, ``|K| T int_0^s g`` (with
``profile_alone``, the default since issue 31's tenth round: its peak speed after the offset, ``s`` at most 1/2,
and the arrival need only lie after the offset: step 2's window can be a real rest after a slow last submovement
that steps 5-8 missed, when the hand moves at the offset as seen from that window too (:func:`still_from_window`),
and an offset at a dip between two submovements has little speed of the fitted one), stands
``n_sigma`` sd out of the velocity's noise (:func:`~imulog.process.segmentation.arrival.velocity_noise_mps`,
measured at the far window) over the time from the offset to the arrival, with the rest from the arrival to
the window's end as the rest window, and the profile integrated back from the far window stays within
``n_sigma`` sd of the velocity integrated from it (:func:`velocity_misfit`): a rest's drift after a stop is no
deceleration of the phase. Two more checks (issue 31, seventh round): the arrival does not lie in the search's
last block (the fit wanted it in the far window, which is then no rest), and the fitted profile explains the
phase's own last part, its residual there at most ``profile_residual_ratio`` times the residual over the rest
after the arrival (:func:`residual_ratio`): a phase that stops sharply, followed by a slow wander of the rest's
acceleration error (the tilt from the gyroscope's noise or its bias instability, referred to the far window),
is not one smooth movement. On by default since then (docs/accuracy.md).
Pure numpy; indices are sample indices.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from imulog.process.segmentation.arrival import STILL_SPEED_SD, gravity_free, velocity_noise_mps, white_noise
from imulog.process.segmentation.boundaries import quietest_window


class ProfileParams(Protocol):
    """The fields of :class:`~imulog.process.segmentation.hand.HandParams` that step 9 reads (a protocol, since
    ``hand`` imports this module): lengths in s, rates in Hz, levels in m/s^2."""

    rest_window_s: float
    n_sigma: float
    min_level_mps2: float
    quiet_s: float
    profile_rest_s: float
    profile_durations_s: tuple[float, float]
    profile_grid_hz: float
    profile_min_s: float
    profile_residual_ratio: float
    profile_alone: bool


_MAX_CELLS = 1 << 21  # candidate x sample cells per block (16 MB of float64)


def decel_shape(s: np.ndarray) -> np.ndarray:
    """Deceleration of a minimum-jerk movement over its last part, in units of ``60 D / T^2``: ``s - 3 s^2 + 2 s^3``
    for ``0 < s < 1`` (``s`` the time left to the arrival in units of ``T``; negative for ``s > 1/2``: the
    acceleration of its first half), 0 elsewhere."""
    s = np.asarray(s, dtype=float)
    return np.where((s > 0) & (s < 1), s * (1 - s) * (1 - 2 * s), 0.0)


def speed_left(s: float) -> float:
    """Speed of a minimum-jerk movement ``s`` (units of ``T``) before its arrival, in units of ``60 D / T``
    (``int_0^s g = s^2 / 2 - s^3 + s^4 / 2``; 1/32 at ``s = 1/2``, the peak ``1.875 D / T``)."""
    s = float(np.clip(s, 0.0, 1.0))
    return s * s / 2 - s**3 + s**4 / 2


def _gains(a: np.ndarray, e: np.ndarray, d: np.ndarray, earliest: float) -> tuple[np.ndarray, np.ndarray]:
    """Squared error (m/s^2)^2 that :func:`fit_arrival`'s model removes from ``a`` (n, 3) for each candidate arrival
    ``e`` (m,) and duration ``d`` (m,) (samples; -inf where the movement would start before ``earliest``) and its
    ``K`` (m, 3)."""
    n = len(a)
    i = np.arange(n, dtype=float)
    basis = np.ones((1, n)) / np.sqrt(n)
    yc = a - basis.T @ (basis @ a)  # (n, 3) without the constant
    gain, k = np.full(len(e), -np.inf), np.zeros((len(e), a.shape[1]))
    rows = max(1, _MAX_CELLS // n)
    for lo in range(0, len(e), rows):
        sl = slice(lo, lo + rows)
        h = decel_shape((e[sl, None] - i[None, :]) / np.maximum(d[sl], 1.0)[:, None])
        hb = h @ basis.T  # h's part in the baseline: yc has none, so h @ yc is the residual's
        hh = np.einsum("ij,ij->i", h, h) - np.einsum("ij,ij->i", hb, hb)
        r = h @ yc  # (m, 3)
        ok = (hh > 0) & (e[sl] - d[sl] >= earliest)
        with np.errstate(divide="ignore", invalid="ignore"):
            gain[sl] = np.where(ok, np.einsum("ij,ij->i", r, r) / hh, -np.inf)
            k[sl] = np.where(ok[:, None], r / hh[:, None], 0.0)
    return gain, k


def _pairs(ends: np.ndarray, durations: list, earliest: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every (arrival, duration) of ``ends`` x ``durations`` (None: ``T = arrival - earliest``) whose movement starts
    at ``earliest`` or later, and the index of each pair's duration."""
    e = np.tile(ends, len(durations))
    d = np.concatenate([ends - earliest if dur is None else np.full(len(ends), float(dur)) for dur in durations])
    ok = e - d >= earliest  # the movement starts after ``earliest``: the others are not computed
    return e[ok], d[ok], np.repeat(np.arange(len(durations)), len(ends))[ok]


def fit_arrival(
    a: np.ndarray, durations: np.ndarray, first: int, last: int, earliest: float = -np.inf, step: int = 1
) -> tuple[float, float, np.ndarray] | None:
    """Least-squares fit of the last movement's deceleration to ``a`` (n, 3) m/s^2 (time order, the rest at the end).

    Model per axis ``c + K g((i_end - i) / T)`` (:func:`decel_shape`; ``i`` the sample index), ``i_end``
    over the samples ``first .. last`` and ``T`` over ``durations`` (samples), the movement starting (``i_end - T``)
    at ``earliest`` or later (and, with a finite ``earliest``, ``T = i_end - earliest``: the phase as one
    movement). Returns ``(i_end, T, K)`` (K in m/s^2, a 3-vector: ``60 D / T^2`` times the direction of ``-a`` at
    the arrival, i.e. along ``-d`` for a movement along ``d``) of the smallest error; None when nothing fits.
    With ``step`` > 1 the grid is searched on block means of ``step`` samples first (``a`` is low-passed: the
    cost falls with ``step^2``), then, for the three best durations, at every sample within 3 blocks of their
    best arrival; the best is refined over 5 durations between its grid neighbours, within a block."""
    n = len(a)
    if n < 8 or last < first:
        return None
    grid = np.asarray(durations, dtype=float)
    durs = [*grid, *([None] if np.isfinite(earliest) else [])]
    step = max(1, min(int(step), n // 8))
    ends = np.arange(max(int(first), 1), min(int(last), n - 1) + 1, dtype=float)
    if len(ends) == 0:
        return None
    if step > 1:  # coarse: block means, the blocks aligned to the rest (the array's end)
        m = n // step
        blocks = a[n - m * step :].reshape(m, step, a.shape[1]).mean(axis=1)
        off = n - m * step + 0.5 * (step - 1)  # sample index of block 0's centre
        coarse = np.arange(np.ceil((first - off) / step), (last - off) // step + 1)
        coarse = coarse[(coarse >= 1) & (coarse <= m - 1)]
        cd = [None if dur is None else dur / step for dur in durs]
        e, d, which = _pairs(coarse, cd, (earliest - off) / step)
        gain = _gains(blocks, e, d, (earliest - off) / step)[0]
        best = np.full(len(durs), -np.inf)
        np.maximum.at(best, which, gain)
        e_list, d_list = [], []
        for j in np.argsort(-best)[:3]:  # the three best durations, every sample within 3 blocks of their best
            if np.isfinite(best[j]):
                c = off + e[(which == j) & (gain == best[j])][0] * step
                near = ends[np.abs(ends - c) <= 3 * step]
                e_list.append(near)
                d_list.append(near - earliest if durs[j] is None else np.full(len(near), durs[j]))
        if not e_list:
            return None
        e, d = np.concatenate(e_list), np.concatenate(d_list)
    else:
        e, d, _ = _pairs(ends, durs, earliest)
    gain, k = _gains(a, e, d, earliest)
    j = int(np.argmax(gain))
    if not np.isfinite(gain[j]):
        return None
    # between the grid's durations (a duration 6 % off moves the arrival by ~1 % of T): 5 more around the best
    ratio = np.sqrt(grid[1] / grid[0]) if len(grid) > 1 and grid[0] > 0 else 1.0
    around = ends[np.abs(ends - e[j]) <= step]
    e2, d2, _ = _pairs(around, list(d[j] * np.geomspace(1 / ratio, ratio, 5)), earliest)
    gain2, k2 = _gains(a, e2, d2, earliest)
    i2 = int(np.argmax(gain2))
    if gain2[i2] > gain[j]:
        return float(e2[i2]), float(d2[i2]), k2[i2]
    return float(e[j]), float(d[j]), k[j]


def profile_model(a: np.ndarray, i_end: float, dur: float) -> np.ndarray:
    """The model ``c + K g`` (n, 3) m/s^2 refitted by least squares to ``a`` (n, 3) m/s^2 for the arrival ``i_end``
    and duration ``dur`` (samples)."""
    n = len(a)
    i = np.arange(n, dtype=float)
    design = np.c_[np.ones(n), decel_shape((i_end - i) / max(dur, 1.0))]
    return design @ np.linalg.lstsq(design, a, rcond=None)[0]


def velocity_misfit(a: np.ndarray, v: np.ndarray, i_end: float, dur: float, dt: float) -> np.ndarray:
    """``|v - v_model|`` (n,) m/s: the velocity ``v`` (n, 3) integrated back from the rest at the array's end minus the
    fitted model's (:func:`profile_model`) integrated the same way."""
    model = profile_model(a, i_end, dur)
    v_model = -np.cumsum(model[::-1], axis=0)[::-1] * dt  # as gravity_free integrates back from the rest
    return np.linalg.norm(v - v_model, axis=1)


def residual_ratio(a: np.ndarray, i_end: float, dur: float, inside: int, arrival: int) -> float:
    """rms of the fit's residual (:func:`profile_model`) over the phase's part ``a[:inside]`` divided by its rms over
    the rest ``a[arrival:]`` (inf when that rest is empty): about 1 when the profile explains the phase's last part
    to within the rest's noise, several when the phase stops more sharply than the profile does."""
    res = a - profile_model(a, i_end, dur)
    if inside < 1 or arrival >= len(a):
        return np.inf
    rest = float(np.sqrt(np.mean(res[arrival:] ** 2)))
    return float(np.sqrt(np.mean(res[:inside] ** 2))) / max(rest, 1e-12)


def profile_end(
    acc, gyr, dt, lo: int, onset: int, end: int, window: int, stop: int, params: ProfileParams, rate_hz: float, raw
) -> int:
    """Offset (exclusive sample index) at the arrival of the phase's last movement fitted as one smooth profile,
    or ``end`` (the current offset) when the fit does not stand out of the noise (see the module docstring).

    ``acc``/``gyr`` the low-passed accelerometer (m/s^2) and gyroscope (rad/s), ``raw`` the unfiltered ones,
    ``lo`` where the fit starts (inside the phase, where the wrist's rotation is small), ``onset`` the phase's
    onset (where its last movement can start at the earliest), ``window`` the start of the rest window steps 2-8
    used, ``stop`` the next phase's guard, ``params`` a :class:`~imulog.process.segmentation.hand.HandParams`
    (``profile_rest_s``: the far window's length, s; ``profile_durations_s``: the range of ``T``, s)."""
    if params.profile_rest_s <= 0 or raw is None:
        return end
    length = int(round(params.profile_rest_s * rate_hz))
    quiet = max(1, int(round(params.quiet_s * rate_hz)))
    if stop - end < length + 4 * quiet:
        return end
    t_lo, t_hi = params.profile_durations_s
    hi = min(stop, end + int(round(t_hi * rate_hz)) + 2 * length)  # an arrival is at most t_hi after the offset
    rest = quietest_window(acc, max(end + 2 * quiet, hi - 2 * length), hi, length)  # near the gap's end
    if rest is None or rest[1] - rest[0] < length // 2:
        return end
    durations = np.unique(np.round(np.geomspace(t_lo, t_hi, 24) * rate_hz))
    lo = max(0, min(int(lo), end - quiet))
    a, v, _ = gravity_free(acc, gyr, dt, rest, lo, rest[0])
    step = max(1, int(round(rate_hz / params.profile_grid_hz)))
    fit = fit_arrival(a, durations, end - lo + 1, rest[0] - lo - 2 * quiet, onset - lo, step)
    if fit is None:
        return end
    i_end, dur, k = fit
    t_end = lo + int(np.ceil(i_end))
    s_end = (t_end - end) / dur
    # after the offset (tied to step 2's window: beyond its start), the offset inside the fitted movement's main deceleration (at half its peak
    # speed or more: a window there takes the deceleration for a bias); the fit's own spread (0.1-0.3 s) is larger
    # than the last 0.1-0.3 s a sensor cannot resolve, which it does not extend (see docs/accuracy.md)
    if (
        t_end <= max(end, end if params.profile_alone else window)
        or not params.profile_min_s <= s_end < 1.0
        or dur > t_hi * rate_hz
    ):
        return end
    # an arrival in the search's last block is the search's limit, not an arrival: the fit wanted it in the far
    # window, which is then no rest (the next movement starting early)
    if t_end > rest[0] - 2 * quiet - step:
        return end
    # the profile explains the phase's own last part: a phase that stops sharply at the offset, with a slow wander
    # of the rest's acceleration error after it (a tilt from the gyroscope's noise or bias instability) fitted as
    # the deceleration, leaves a residual inside the phase several times the rest's
    if residual_ratio(a, i_end, dur, end - lo, t_end - lo) > params.profile_residual_ratio:
        return end
    u = v[end - lo] / max(float(np.linalg.norm(v[end - lo])), 1e-12)
    if float(k @ u) >= 0:  # K g opposes the motion while it decelerates (an arrival)
        return end
    w0, w1 = rest
    acc_sd = max(white_noise(raw[0], w0, w1), params.min_level_mps2 / params.n_sigma)  # a quantised sensor
    gyr_sd = white_noise(raw[1], w0, w1)
    s_peak = min(s_end, 0.5) if params.profile_alone else s_end
    # at the offset, extrapolated from the rest (judged alone: the fitted movement's peak after the offset)
    speed = float(np.linalg.norm(k)) * dur * dt * speed_left(s_peak)
    sd = velocity_noise_mps(np.array([(t_end - end) * dt]), dt, (w1 - t_end) * dt, acc_sd, gyr_sd)[0]
    if speed < params.n_sigma * sd:
        return end
    # the fitted profile explains the velocity from the offset to the rest within that velocity's noise
    tau = (rest[0] - lo - np.arange(end - lo, rest[0] - lo)) * dt
    sd_v = velocity_noise_mps(tau, dt, (w1 - w0) * dt, acc_sd, gyr_sd)
    miss = velocity_misfit(a, v, i_end, dur, dt)[end - lo :]
    if np.any(miss > params.n_sigma * sd_v):
        return end
    if params.profile_alone and t_end <= window and still_from_window(acc, gyr, dt, raw, end, window, params, rate_hz):
        return end
    return t_end


def still_from_window(
    acc: np.ndarray,
    gyr: np.ndarray,
    dt: float,
    raw: tuple[np.ndarray, np.ndarray],
    end: int,
    window: int,
    params: ProfileParams,
    rate_hz: float,
) -> bool:
    """Whether the hand is still at the offset ``end`` as seen from step 2's rest window starting at ``window``: the
    velocity integrated back from that window (m/s) within :data:`STILL_SPEED_SD` sd of its noise there. A movement fitted
    (from the far window) across a phase that stopped at its offset, with step 2's window in the rest after it,
    is not the phase's; a slow last submovement that steps 5-8 missed moves at several sd from that window too.
    ``acc``/``gyr`` (N, 3) the low-passed accelerometer (m/s^2) and gyroscope (rad/s), ``raw`` the unfiltered ones,
    ``dt`` the sample interval (s), ``end``/``window`` sample indices."""
    near = (window, window + max(3, int(round(params.rest_window_s * rate_hz))))
    if near[0] <= end:
        return False
    v2 = gravity_free(acc, gyr, dt, near, end, near[0])[1][0]
    acc_sd = max(white_noise(raw[0], *near), params.min_level_mps2 / params.n_sigma)
    tau = np.array([(near[0] - end) * dt])
    sd = velocity_noise_mps(tau, dt, (near[1] - near[0]) * dt, acc_sd, white_noise(raw[1], *near))[0]
    return bool(np.linalg.norm(v2) <= STILL_SPEED_SD * sd)


def explains_last_part(
    acc: np.ndarray,
    gyr: np.ndarray,
    dt: float,
    window: tuple[int, int],
    lo: int,
    onset: int,
    end: int,
    arrival: int,
    params: ProfileParams,
    rate_hz: float,
) -> bool:
    """Whether one minimum-jerk deceleration arriving at ``arrival`` (sample index, before the rest ``window``)
    explains the phase's last part ``[lo, end)`` within the window's noise: the model of :func:`fit_arrival` with its
    arrival fixed there (``T`` over ``profile_durations_s`` and from ``onset``), fitted to the gravity-free
    acceleration relative to ``window`` over ``[lo, window[0])``, leaves a residual over ``[lo, end)`` whose rms is at
    most ``profile_residual_ratio`` x the window's acceleration noise (m/s^2, :func:`gravity_free`'s). A phase that
    stops sharply at ``end``, followed by a ramp of the window mean's error integrated back, is not one smooth
    deceleration to ``arrival`` (issue 31 twelfth round). ``acc``/``gyr`` low-passed, (N, 3), m/s^2 and rad/s."""
    lo = max(0, min(int(lo), end - 1))
    a, _, noise = gravity_free(acc, gyr, dt, window, lo, window[0])
    n = len(a)
    t_lo, t_hi = params.profile_durations_s
    durations = np.unique(np.round(np.geomspace(t_lo, t_hi, 24) * rate_hz))
    i0 = min(max(int(arrival) - lo, 1), n - 1)
    fit = fit_arrival(a, durations, i0, i0, onset - lo)
    if fit is None or end <= lo:
        return False
    res = a[: end - lo] - profile_model(a, fit[0], fit[1])[: end - lo]
    return float(np.sqrt(np.mean(res**2))) <= params.profile_residual_ratio * max(noise, 1e-12)
