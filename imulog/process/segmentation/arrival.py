"""The velocity integrated from a rest window, its noise, and a phase's slow last part measured against it.

Step 8 of :mod:`~imulog.process.segmentation.hand` (issue 31 point 1).

The velocity ``v`` integrated from a rest window (a zero-velocity update) carries errors that grow with the time
``tau`` (s) from the window: the accelerometer's white noise summed (a random walk, ``sigma_a^2 dt tau``), the
window mean's error integrated (``sigma_a^2 dt / T_w tau^2`` for a window of ``T_w`` s) and gravity leaking in
through the gyroscope's noise, the tilt error growing as a random walk plus the window's bias error
(``g sigma_g sqrt(dt) tau^1.5 / sqrt(3)`` and ``g sigma_g sqrt(dt / T_w) tau^2 / 2``). ``sigma_a`` and ``sigma_g``
are the white noise per sample measured at the window itself (robust sd of the sample-to-sample differences of
the unfiltered signals). A slow last part of a phase (the hand arriving at 0.5-3 cm/s, under any fixed speed level
for seconds, issue 31) is motion where the speed integrated back from a verified rest stands out of that bound.
Pure numpy; indices are sample indices.
"""

from __future__ import annotations

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.segmentation.flanks import first_motion

GRAVITY_MPS2 = 9.81
# the speed (in sd per axis of the velocity's noise) that a still hand's 3-axis velocity noise stays under 95 % of
# the time: sqrt of the chi-square 95 % quantile with 3 degrees of freedom (issue 31, tenth round)
STILL_SPEED_SD = 2.795


def gravity_free(
    acc: np.ndarray, gyr: np.ndarray, dt_s: float, window: tuple[int, int], lo: int, hi: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """Gravity-free acceleration (m/s^2) and velocity (m/s) over ``[lo, hi)`` relative to a rest ``window``.

    Specific force rotated into the window's sensor frame (bias-corrected gyroscope integrated from the window,
    small-angle), minus the window's median; velocity integrated from zero at the window (ZUPT). Also returns
    the rest noise (m/s^2, rms over the axes of the per-axis robust sd)."""
    w0, w1 = window
    f_rest = np.mean(acc[w0:w1], axis=0)  # the mean: a median of quantised samples is off by up to LSB/2
    noise = float(np.sqrt(np.mean((1.4826 * np.median(np.abs(acc[w0:w1] - f_rest), axis=0)) ** 2)))
    bias = np.median(gyr[w0:w1], axis=0)
    w = (gyr - bias) * dt_s
    if hi <= w0:  # stretch before the window (an offset): integrate backwards from the window's start
        idx = np.arange(lo, w0)
        theta = -np.cumsum(w[idx][::-1], axis=0)[::-1]
        f = quat.rotate(quat.from_rotation_vector(theta), acc[idx])
        a = f - f_rest
        v = -np.cumsum(a[::-1], axis=0)[::-1] * dt_s
    else:  # stretch after the window (an onset): integrate forwards from the window's end
        idx = np.arange(w1, hi)
        theta = np.cumsum(w[idx], axis=0)
        f = quat.rotate(quat.from_rotation_vector(theta), acc[idx])
        a = f - f_rest
        v = np.cumsum(a, axis=0) * dt_s
    return a, v, noise


def white_noise(x: np.ndarray, w0: int, w1: int) -> float:
    """White noise per sample of ``x[w0:w1]`` (units of ``x``; rms over the axes of the per-axis robust sd of the
    sample-to-sample differences divided by sqrt(2): a slow motion or drift in the window cancels)."""
    d = np.diff(np.asarray(x[w0:w1], dtype=float), axis=0)
    if len(d) < 2:
        return 0.0
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return float(np.sqrt(np.mean((1.4826 * mad / np.sqrt(2.0)) ** 2)))


def velocity_noise_mps(
    tau_s: np.ndarray, dt_s: float, window_s: float, acc_noise_mps2: float, gyr_noise_rad_s: float
) -> np.ndarray:
    """sd (m/s, per axis) of the velocity integrated ``tau_s`` (s, array) from a rest window of ``window_s`` (s)
    from an accelerometer and a gyroscope with white noise ``acc_noise_mps2`` and ``gyr_noise_rad_s`` per sample
    at a sample interval ``dt_s`` (see the module docstring)."""
    tau = np.maximum(np.asarray(tau_s, dtype=float), 0.0)
    w = max(float(window_s), dt_s)
    acc = acc_noise_mps2**2 * dt_s * (tau + tau**2 / w)
    tilt = (GRAVITY_MPS2 * gyr_noise_rad_s) ** 2 * dt_s * (tau**3 / 3.0 + tau**4 / (4.0 * w))
    return np.sqrt(acc + tilt)


def slow_tail_end(
    acc, gyr, dt, post, lo, end, stop, params, rate_hz, raw=None, limit_mps: float | None = None, inside=None
) -> int:
    """Offset (exclusive sample index) at the end of a slow last part of the phase, or ``end`` (the current one).

    ``acc``/``gyr`` the low-passed accelerometer (m/s^2) and gyroscope (rad/s), ``raw`` the unfiltered ones (for
    the noise; None: the fixed levels only), ``params`` a :class:`~imulog.process.segmentation.hand.HandParams`.
    A window counts as a rest only when the velocity integrated forward from it stays under half
    ``velocity_level_mps`` for ``rest_check_s`` (up to ``stop``): a window in a slow tail or in a rest's drift
    moves at a few cm/s and the hand slows or speeds up after it. The last time before it that the speed
    integrated back from it reaches ``velocity_level_mps`` is motion, and the offset moves to where that speed
    flank reaches zero (:func:`~imulog.process.segmentation.flanks.first_motion`, time reversed). With ``raw``,
    a slower last part counts where its speed stands ``n_sigma`` sd out of the velocity's noise
    (:func:`velocity_noise_mps`, measured at the window) when the window is a rest within that noise, and only
    when the offset lies in that part, under the speed level, the flank's run inside the phase (a window moving
    in a rest's drift sees the stop before the drift as a speed of several sd right from the window). Later
    windows are not tried: a window in a rest's drift fails the check, and one after the drift verifies and
    takes the drift for a slow last part (issue 31).
    ``lo``: where the velocity integration may start (inside the phase); ``limit_mps``: the check's limit (m/s)
    instead of half ``velocity_level_mps`` (the trial's own rests, :mod:`~imulog.process.segmentation.rest_drift`);
    ``inside``: a list that gets, with ``params.slow_inside``, the offset (exclusive sample index) at the end of a
    slow last part that the offset lies inside of (:func:`inside_last_part`) and the window it was measured from,
    for the caller to check and apply when step 9 does not move the offset (the offset returned is without it)."""
    check = int(round(params.rest_check_s * rate_hz))
    vlevel = params.velocity_level_mps
    if check <= 0 or vlevel <= 0 or post[0] <= end:
        return end
    min_run = max(1, int(round(params.min_run_s * rate_hz)))
    fit = int(round(params.speed_fit_s * rate_hz))
    if min(stop, post[1] + check) - post[1] < check // 2:
        return end
    _, v_fwd, _ = gravity_free(acc, gyr, dt, post, post[1], min(stop, post[1] + check))
    fwd = np.linalg.norm(v_fwd, axis=1)
    m = post[0] - lo  # samples integrated back from the window
    v_back, z = None, None
    if fwd.max() < (0.5 * vlevel if limit_mps is None else limit_mps):
        v_back = gravity_free(acc, gyr, dt, post, lo, post[0])[1][::-1]
        z = first_motion(v_back, vlevel, min_run, m - (end - lo), check, fit)
    if z is None and raw is not None:  # against the velocity's noise, measured at the window
        w0, w1 = post
        acc_sd = max(white_noise(raw[0], w0, w1), params.min_level_mps2 / params.n_sigma)  # a quantised sensor
        tau = (np.arange(max(m, len(fwd))) + 1) * dt  # time from the window (s)
        sd = velocity_noise_mps(tau, dt, (w1 - w0) * dt, acc_sd, white_noise(raw[1], w0, w1))
        if np.all(fwd < params.n_sigma * sd[: len(fwd)]):  # a rest within the noise: an offset in the last part
            if v_back is None:
                v_back = gravity_free(acc, gyr, dt, post, lo, post[0])[1][::-1]
            z = first_motion(v_back, params.n_sigma, min_run, m - (end - lo), check, fit, scale=sd[:m])
            if z is None and params.slow_inside and inside is not None:
                zi = inside_last_part(v_back, sd[:m], params.n_sigma, min_run, m - (end - lo), check, fit)
                if zi is not None:
                    inside.append((max(end, lo + m - int(np.ceil(zi))), post))
    return end if z is None else max(end, lo + m - int(np.ceil(z)))


def inside_last_part(
    v_back: np.ndarray,
    sd: np.ndarray,
    n_sigma: float,
    min_run: int,
    until: int,
    near: int,
    fit: int,
    drop_sd: float = STILL_SPEED_SD,
) -> float | None:
    """Where a slow last part that the offset lies *inside* reaches the rest (local sample index, time reversed:
    from step 8's verified window back into the phase), or None.

    ``v_back`` (m, 3) m/s the velocity integrated back from the window, ``sd`` (m,) m/s its noise per axis
    (:func:`velocity_noise_mps`), ``until`` the offset. The hand moves at the offset at ``n_sigma`` sd or more (but
    under step 8's fixed level, which found nothing), so the offset lies inside the last part, not after it: the
    flank of :func:`~imulog.process.segmentation.flanks.first_motion` against the noise, its run allowed to hold the
    offset. A rest's drift seen from a window moving with it is a constant speed from the stop to the drift's
    start; a last part decelerates: from the offset to half-way to the flank's start the speed must have fallen by
    ``drop_sd`` sd of the noise at half-way (default: 95 % of a still hand's 3-axis speed, as
    :data:`STILL_SPEED_SD`). ``near``, ``fit``: as
    :func:`~imulog.process.segmentation.flanks.first_motion`'s."""
    z = first_motion(v_back, n_sigma, min_run, until, near, fit, scale=sd, late_only=False)
    if z is None or z >= until:
        return None
    speed = np.linalg.norm(v_back, axis=1)
    mid = int(round(0.5 * (z + until)))
    if speed[until] - speed[mid] < drop_sd * sd[mid]:
        return None
    return z
