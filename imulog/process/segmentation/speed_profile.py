"""A phase's last movement fitted with one smooth speed profile, its arrival extrapolated (issue 31 point 1).

Step 9 of :mod:`~imulog.process.segmentation.hand`. A slow phase's last part decelerates at a few hundredths of
m/s^2 for seconds: a 0.5-s rest window placed there takes the deceleration for the sensor's bias (a constant
acceleration and an accelerometer bias are the same thing to one window) and the velocity integrated from it
hardly moves, so the phase ends seconds early; and the last 0.1-0.3 s of a 5-6-s minimum-jerk phase move at
under 2 mm/s, below what the sensors resolve. What tells a deceleration from a rest is the jerk over seconds:
a minimum-jerk movement (Flash & Hogan 1985) of ``D`` m over ``T`` s decelerates as
``a(s) = -60 D / T^2 (s - 3 s^2 + 2 s^3)``, ``s`` the time left to the arrival in units of ``T``: the deceleration
fades linearly to zero at the arrival, then the hand rests.

The model ``a = c + b t + K g((t_end - t) / T)`` (``g(s) = s - 3 s^2 + 2 s^3`` on ``0 < s < 1``, 0 after the
arrival; ``c`` and ``b`` per axis: the rest's bias and the tilt of a gyroscope bias error growing linearly;
``K`` a 3-vector, the movement's direction) is fitted by least squares to the gravity-free acceleration
(:func:`~imulog.process.segmentation.arrival.gravity_free`) relative to a rest window near the end of the gap,
from the current offset to that window, over a grid of ``t_end`` and ``T``. The fitted arrival is kept when
the fitted movement covers the current offset (it is the phase's own last movement, not a rest's drift
starting after a stop), decelerates along the phase's motion, and its speed at the offset,
``|K| T int_0^s g``, stands ``n_sigma`` sd out of the velocity's noise
(:func:`~imulog.process.segmentation.arrival.velocity_noise_mps`, measured at that window) over the time
from the offset to the arrival, with the rest from the arrival to the window's end as the rest window.
Pure numpy; indices are sample indices.
"""

from __future__ import annotations

import numpy as np

from imulog.process.segmentation.arrival import gravity_free, velocity_noise_mps, white_noise
from imulog.process.segmentation.boundaries import quietest_window

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


def _grid_fit(yc, basis, i, ends, durations, earliest):
    """Best ``(gain, i_end, T, K)`` of :func:`fit_arrival`'s model over the candidate ``ends`` x ``durations`` (a
    ``None`` duration: ``T = i_end - earliest``); ``gain`` the squared error removed, (m/s^2)^2."""
    best = (-np.inf, None, None, None)
    rows = max(1, _MAX_CELLS // len(i))
    for dur in durations:
        for lo in range(0, len(ends), rows):
            e = ends[lo : lo + rows]
            d = e - earliest if dur is None else np.full(len(e), float(dur))
            h = decel_shape((e[:, None] - i[None, :]) / np.maximum(d, 1.0)[:, None])
            h = h - (h @ basis.T) @ basis
            hh = np.einsum("ij,ij->i", h, h)
            r = h @ yc  # (m, 3)
            with np.errstate(divide="ignore", invalid="ignore"):
                gain = np.where((hh > 0) & (e - d >= earliest), np.einsum("ij,ij->i", r, r) / hh, -np.inf)
            k = int(np.argmax(gain))
            if np.isfinite(gain[k]) and gain[k] > best[0]:
                best = (float(gain[k]), float(e[k]), float(d[k]), r[k] / hh[k])
    return best


def _baseline(n: int) -> np.ndarray:
    """Orthonormal rows spanning a constant and a line over ``n`` samples."""
    i = np.arange(n, dtype=float)
    return np.array([np.ones(n) / np.sqrt(n), (i - i.mean()) / max(float(np.linalg.norm(i - i.mean())), 1e-12)])


def fit_arrival(
    a: np.ndarray, durations: np.ndarray, first: int, last: int, earliest: float = -np.inf, step: int = 1
) -> tuple[float, float, np.ndarray] | None:
    """Least-squares fit of the last movement's deceleration to ``a`` (n, 3) m/s^2 (time order, the rest at the end).

    Model per axis ``c + b i + K g((i_end - i) / T)`` (:func:`decel_shape`; ``i`` the sample index), ``i_end``
    over the samples ``first .. last`` and ``T`` over ``durations`` (samples), the movement starting (``i_end - T``)
    at ``earliest`` or later (and, with a finite ``earliest``, ``T = i_end - earliest``: the phase as one
    movement). Returns ``(i_end, T, K)`` (K in m/s^2, a 3-vector: ``60 D / T^2`` times the direction of ``-a`` at
    the arrival, i.e. along ``-d`` for a movement along ``d``) of the smallest error; None when nothing fits.
    With ``step`` > 1 the grid is searched on block means of ``step`` samples (``a`` is low-passed: the cost falls
    with ``step^2``), then at every sample within 3 blocks of the best."""
    n = len(a)
    if n < 8 or last < first:
        return None
    whole = [None] if np.isfinite(earliest) else []
    durations = np.asarray(durations, dtype=float)
    step = max(1, min(int(step), n // 8))
    if step > 1:  # coarse: block means, the blocks aligned to the rest (the array's end)
        m = n // step
        blocks = a[n - m * step :].reshape(m, step, a.shape[1]).mean(axis=1)
        off = n - m * step + 0.5 * (step - 1)  # sample index of block 0's centre
        i = np.arange(m, dtype=float)
        basis = _baseline(m)
        ends = np.arange(
            max(1, int(np.ceil((first - off) / step))), min(m - 1, int((last - off) // step)) + 1, dtype=float
        )
        coarse = _grid_fit(
            blocks - basis.T @ (basis @ blocks), basis, i, ends, [*(durations / step), *whole], (earliest - off) / step
        )
        if coarse[1] is None:
            return None
        centre = off + coarse[1] * step  # the fine search: every sample within 3 blocks, every duration
        first, last = max(first, int(centre) - 3 * step), min(last, int(centre) + 3 * step)
    i = np.arange(n, dtype=float)
    basis = _baseline(n)
    ends = np.arange(max(int(first), 1), min(int(last), n - 1) + 1, dtype=float)
    best = _grid_fit(a - basis.T @ (basis @ a), basis, i, ends, [*durations, *whole], earliest)
    if best[1] is None:
        return None
    return best[1], best[2], best[3]


def velocity_misfit(a: np.ndarray, v: np.ndarray, i_end: float, dur: float, dt: float) -> np.ndarray:
    """``|v - v_model|`` (n,) m/s: the velocity ``v`` (n, 3) integrated back from the rest at the array's end minus the
    fitted model's (``c + b i + K g``, refitted by least squares for the arrival ``i_end`` and duration ``dur``,
    samples) integrated the same way."""
    n = len(a)
    i = np.arange(n, dtype=float)
    design = np.c_[np.ones(n), i - i.mean(), decel_shape((i_end - i) / max(dur, 1.0))]
    coef = np.linalg.lstsq(design, a, rcond=None)[0]
    model = design @ coef
    v_model = -np.cumsum(model[::-1], axis=0)[::-1] * dt  # as gravity_free integrates back from the rest
    return np.linalg.norm(v - v_model, axis=1)


def profile_end(
    acc, gyr, dt, lo: int, onset: int, end: int, window: int, stop: int, params, rate_hz: float, raw
) -> int:
    """Offset (exclusive sample index) at the arrival of the phase's last movement fitted as one smooth profile,
    or ``end`` (the current offset) when the fit does not stand out of the noise (see the module docstring).

    ``acc``/``gyr`` the low-passed accelerometer (m/s^2) and gyroscope (rad/s), ``raw`` the unfiltered ones,
    ``lo`` where the fit starts (inside the phase, where the wrist's rotation is small), ``onset`` the phase's onset, where its last movement can start at the earliest, ``stop`` the next
    phase's guard, ``params`` a :class:`~imulog.process.segmentation.hand.HandParams`
    (``profile_rest_s``: the reference window's length; ``profile_durations_s``: the range of ``T``)."""
    if params.profile_rest_s <= 0 or raw is None:
        return end
    length = int(round(params.profile_rest_s * rate_hz))
    quiet = max(1, int(round(params.quiet_s * rate_hz)))
    if stop - end < length + 4 * quiet:
        return end
    rest = quietest_window(acc, max(end + 2 * quiet, stop - 2 * length), stop, length)  # near the gap's end
    if rest is None or rest[1] - rest[0] < length // 2:
        return end
    t_lo, t_hi = params.profile_durations_s
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
    if t_end <= max(end, window) or s_end >= 1.0:  # beyond the rest window's start, covering the offset
        return end
    u = v[end - lo] / max(float(np.linalg.norm(v[end - lo])), 1e-12)
    if float(k @ u) >= 0:  # K g opposes the motion while it decelerates (an arrival)
        return end
    speed = float(np.linalg.norm(k)) * dur * dt * speed_left(s_end)
    w0, w1 = rest
    acc_sd = max(white_noise(raw[0], w0, w1), params.min_level_mps2 / params.n_sigma)  # a quantised sensor
    tau = np.array([(t_end - end) * dt])  # s extrapolated, from the rest after the arrival
    gyr_sd = white_noise(raw[1], w0, w1)
    sd = velocity_noise_mps(tau, dt, (w1 - t_end) * dt, acc_sd, gyr_sd)[0]
    if speed < params.n_sigma * sd:
        return end
    # the fitted profile explains the velocity from the offset to the rest within that velocity's noise
    tau = (rest[0] - lo - np.arange(end - lo, rest[0] - lo)) * dt
    sd_v = velocity_noise_mps(tau, dt, (w1 - w0) * dt, acc_sd, gyr_sd)
    miss = velocity_misfit(a, v, i_end, dur, dt)[end - lo :]
    if np.any(miss > params.n_sigma * sd_v):
        return end
    return t_end
