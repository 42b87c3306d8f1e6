"""Phase boundaries that follow the hand, not only the wrist's rotation (an imulog addition, issue 19).

The R2G thesis defines the phases by what the hand does: reach and grasp the bottle, lift it to the mouth,
return it to the table, return the hand to its start (3.2.1), with a static period of about four seconds
between them. DynAMoS and :mod:`~imulog.process.segmentation.boundaries` see only the gyroscope, so a phase
ends when the wrist stops *rotating*. In real reaching the forearm's rotation (pronation to a side grasp,
tilting the bottle) often finishes before the hand arrives, and a slow or corrective approach barely rotates
at all; the phase then ends early (the thesis's subject 6: "a residual velocity before and after DynAMoS
identified phases").

After the gyroscope refinement, every onset (offset) is moved further out while the *hand* still moves:

1. the accelerometer is low-passed per axis (zero-phase, 2nd order, ``cutoff_hz``, lowered for a noisy
   sensor like the gyroscope's, :func:`~imulog.process.segmentation.boundaries.adaptive_cutoff_hz`);
2. a rest window of ``rest_window_s`` in the adjacent gap (at its middle, or ``rest_distance_s`` from the phase
   in a long rest; moved further out when it is not still,
   :func:`~imulog.process.segmentation.rest_window.still_window`) gives the static
   specific force ``f_rest`` (mean, the sensor's gravity reading and bias) and the noise
   (per-axis 1.4826 MAD, rms over the axes);
3. between the boundary and the rest window the specific force is rotated into the rest window's sensor
   frame with the bias-corrected gyroscope integrated from the window (the rotation of the summed rotation
   vector) and ``a = R f - f_rest`` is the gravity-free acceleration (m/s^2; a sensor bias cancels, a slow
   tilt is compensated);
4. the velocity ``v`` (m/s) is ``a`` integrated from the rest window (where the hand is still: a
   zero-velocity update), so it is consistent with ZUPT;
5. the hand moves where ``|a| > n_sigma x noise`` (at least ``min_level_mps2``), or where
   ``|v| > velocity_level_mps`` while ``|a|`` is above half that level (a slow tail still decelerating; a rest's
   slow drift, the thesis's residual velocity, barely accelerates and is not taken), or where
   ``|v| > cruise_velocity_mps`` (overlapping submovements of a slow phase cruise between them with next to
   no acceleration: issue 31); before an onset both speed criteria count only where the speed also stands
   ``n_sigma`` sd out of the velocity's own noise (``walk_noise``, :func:`speed_in_noise`: far from the window the
   integrated velocity's drift reaches the fixed levels, issue 31 twelfth round); runs shorter than ``min_run_s``
   are noise; from the gyroscope
   boundary the onset (offset) walks outward over moving samples and stops at the first run of
   ``quiet_s`` without motion; a move beyond ``max_shift_s`` is not trusted (the "rest" is not a rest) and
   the gyroscope boundary stays;
6. motion that resumes within ``continuation_s`` after the offset with ``|a|`` of at least
   ``continuation_n_level`` x the level for ``min_run_s`` and settles before the rest window (a
   translation-only correction after a pause) extends the phase, as :mod:`boundaries` does for rotations.
   (Until issue 31 the level was 10 % of the phase's peak ``|f - f_rest|``, which gravity dominates once the
   wrist has turned: 0.5-1.3 m/s^2, above a slow last submovement's 0.1-0.7 m/s^2, whose phase then ended
   0.55-0.82 s early.) A dip of ``|a|`` is bridged to the next run above ``bridge_n_level`` x the level when
   the speed stays above ``velocity_level_mps`` in between (the hand never stopped) or, after a pause, when
   the resumed motion moves faster than ``cruise_velocity_mps`` (``resume_cruise``: a slow last submovement, not
   a rest's drift); a continuation that settles before the rest window extends the phase even beyond
   ``max_shift_s`` (``settled_beyond_shift``; the bound is on the walk of step 5, issue 31 point 1);
7. the boundary moves on to where its acceleration flank (or, for a phase too slow for the accelerometer, its
   speed flank) extrapolates to rest (:mod:`~imulog.process.segmentation.flanks`, issue 31); with
   ``flank_rest_level`` (an option) the acceleration flank's rest level is zero to the rest window's precision;
   with ``flank_noise`` (an option) the line is a generalised least-squares fit that weighs the low-passed
   noise's correlation (:mod:`~imulog.process.segmentation.flank_noise`);
8. a slow last part at ``velocity_level_mps`` or more with next to no acceleration (the wrist stopped turning,
   the hand still arriving: up to 3 s) extends the offset when the rest window is verified as a rest (the
   velocity integrated forward from it stays under half that speed for ``rest_check_s``; with ``rest_drift``, an
   option, under what the trial's own still rests read if more, :mod:`~imulog.process.segmentation.rest_drift`)
   and the hand never
   slowed under half that speed between the offset and that part (a rest's drift follows a stop and a window in
   a drift fails the check); a slower last part, under that speed, where its speed stands ``n_sigma`` sd out of
   the velocity's own noise (:func:`~imulog.process.segmentation.arrival.slow_tail_end`); with ``slow_inside`` (an
   option) also one that the offset lies inside of, applied after step 9 when step 9 did not move the offset and
   one smooth deceleration to it explains the phase's last part
   (:func:`~imulog.process.segmentation.arrival.inside_last_part`);
9. the phase's last movement is fitted as one minimum-jerk deceleration from inside the phase to a rest window
   near the gap's end (:mod:`~imulog.process.segmentation.speed_profile`): when its arrival lies after the offset
   (with ``profile_alone``, the default since issue 31's tenth round; else beyond the rest window of step 2, since a
   window inside a steadily decelerating last part passes as a rest), starts after the
   onset, covers the offset, stands out of the velocity's noise (its peak speed after the offset; else its speed
   at the offset), lies before the search's last block and explains
   the phase's own last part (its residual there at most ``profile_residual_ratio`` x the rest's), the offset
   moves to it (on by default since issue 31's seventh round; ``profile_rest_s = 0`` turns it off; the phases step
   runs it on the drinking task only, :func:`~imulog.process.segmentation.pipeline.hand_params`);
10. with ``gyro_floor`` (an option, off): an onset (offset) that no step moved, the gyroscope's own, loses the
    samples at it that are at the gyroscope's noise floor in the rest window, up to the filtered noise's
    correlation time and as far as the phase's own flank of step 7 agrees
    (:mod:`~imulog.process.segmentation.noise_floor`).

Pure numpy/scipy; intervals are half-open sample ranges ``[start, end)``.
"""

from __future__ import annotations

import numpy as np

from imulog.process.segmentation.arrival import gravity_free, slow_tail_end, velocity_noise_mps, white_noise
from imulog.process.segmentation.boundaries import BoundaryParams, adaptive_cutoff_hz, lowpass_axes
from imulog.process.segmentation.flank_noise import FlankNoiseParams
from imulog.process.segmentation.flanks import combined_t0, flank_zero, speed_flank_zero
from imulog.process.segmentation.gaps import gap_bounds
from imulog.process.segmentation.hand_params import HandParams
from imulog.process.segmentation.noise_floor import trim_unmoved
from imulog.process.segmentation.rest_drift import RestDriftParams, check_limit
from imulog.process.segmentation.rest_window import still_window
from imulog.process.segmentation.speed_profile import explains_last_part, profile_end


def fill_gaps(x: np.ndarray) -> np.ndarray:
    """Per-axis linear interpolation over NaN samples (missing samples of a stream with gaps)."""
    x = np.array(x, dtype=float)
    for j in range(x.shape[1]):
        bad = ~np.isfinite(x[:, j])
        if bad.any() and not bad.all():
            x[bad, j] = np.interp(np.flatnonzero(bad), np.flatnonzero(~bad), x[~bad, j])
    return x


def sustained(mask: np.ndarray, min_run: int) -> np.ndarray:
    """``mask`` without its True runs shorter than ``min_run`` samples (isolated noise exceedances)."""
    mask = np.asarray(mask, dtype=bool)
    if min_run <= 1 or not mask.any():
        return mask
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    out = mask.copy()
    for a, b in zip(starts, ends, strict=True):
        if b - a < min_run:
            out[a:b] = False
    return out


def _walk(moving: np.ndarray, start: int, quiet: int) -> int:
    """Index one past the last moving sample reachable from ``start`` without a quiet run of ``quiet``."""
    last = start - 1
    for i in range(start, len(moving)):
        if moving[i]:
            last = i
        elif i - last > quiet:
            break
    return last + 1


def _extend_offset(
    a_norm, v_norm, b_local, level, vlevel, quiet, cont, cont_level, min_run, cruise=0.0, bridge=1.5, resume=False
) -> tuple[int, int]:
    """Offset (exclusive, local index) after walking out of the phase and over translation-only corrections.

    A correction continues the phase when its ``|a|`` reaches ``cont_level`` (a sub-movement after a pause)
    or, with ``bridge`` > 0, when it reaches ``bridge`` x the ``level`` (a submovement, not a noise run in a rest
    drifting at a few cm/s) and the speed stayed above ``vlevel`` all the way from
    the walk's end to it (the hand never stopped: overlapping submovements of a slow phase, whose
    acceleration passes through zero between them) or, with ``resume``, when its speed on the walk from it exceeds
    ``cruise`` (a last submovement after a pause, not a rest's drift); in every case only when it settles before
    the rest. Returns the offset and the first walk's end (local indices; ``max_shift_s`` bounds the walk)."""
    moving = a_norm > level
    if vlevel > 0:  # a tail at speed that still decelerates; a rest's slow drift barely accelerates
        moving |= (v_norm > vlevel) & (a_norm > 0.5 * level)
    if cruise > 0:
        moving |= v_norm > cruise
    moving = sustained(moving, min_run)
    j = walked = _walk(moving, b_local, quiet)
    strong = sustained(a_norm >= cont_level, min_run)
    active = sustained(a_norm > bridge * level, min_run) if bridge > 0 and vlevel > 0 else None
    while cont > 0:
        big = np.flatnonzero(strong[j : j + cont])
        nxt = j + int(big[0]) if len(big) else None
        if active is not None:
            run = np.flatnonzero(active[j : j + cont])
            r0 = j + int(run[0]) if len(run) else None
            # the hand never stopped, or it resumed faster than the cruise speed (after a pause: a last
            # submovement, not a rest's drift, which stays under it)
            if r0 is not None and (
                np.all(v_norm[j:r0] > vlevel)
                or (resume and cruise > 0 and v_norm[r0 : _walk(moving, r0, quiet)].max(initial=0.0) > cruise)
            ):
                nxt = r0 if nxt is None else min(nxt, r0)
        if nxt is None:
            break
        k = _walk(moving, nxt, quiet)
        if k >= len(moving) or k <= j:  # never settles before the rest: not a correction of this phase
            break
        j = k
    return j, walked


def _extrapolated(
    a: np.ndarray,
    v: np.ndarray,
    first: int,
    inner: int,
    level: float,
    params: HandParams,
    rate_hz: float,
    flank: list | None = None,
    cutoff_hz: float | None = None,
) -> int:
    """Onset (local index into ``a`` and ``v``, time order from the rest) at the start of its acceleration flank
    (:func:`~imulog.process.segmentation.flanks.flank_zero`, searched from ``first``, the onset the level gave)
    or, for a movement too slow for its acceleration to clear the noise, of its speed
    (:func:`~imulog.process.segmentation.flanks.speed_flank_zero`), or at ``inner`` (the gyroscope's onset) if
    that is earlier; ``first`` when there is no such flank. Never before the array's start (the rest window).
    ``flank``: a list that gets the flank's own start (first sample after ``t0``, not bounded by ``inner``);
    ``cutoff_hz``: step 1's cut-off (Hz), for ``flank_noise`` (the low-passed noise's correlation)."""
    if params.flank_top_n_level <= 0:
        return first
    span = int(round(params.flank_search_s * rate_hz))
    back = int(round(params.max_extrapolation_s * rate_hz))
    smooth = max(1, int(round(0.05 * rate_hz)))
    spread: list[float] | None = [] if params.flank_combine else None  # each fit's sd of t0, for combined_t0
    prior = int(round(params.rest_window_s * rate_hz)) if params.flank_rest_level else 0  # the window's mean
    noise = (
        FlankNoiseParams(cutoff_hz, rate_hz, params.flank_noise_band_hz) if params.flank_noise and cutoff_hz else None
    )
    z = flank_zero(a, first, level, params.flank_top_n_level * level, span, back, smooth, spread, prior, noise)
    if (z is None or params.flank_combine) and params.velocity_level_mps > 0:
        fit = int(round(params.speed_fit_s * rate_hz))
        zs = speed_flank_zero(v, first, params.velocity_level_mps, fit, spread)
        z = zs if z is None or spread is None else combined_t0(z, zs, spread, first, back)
    if z is None:
        return first
    if flank is not None:
        flank.append(max(int(np.ceil(z)), 0))
    return int(min(inner, max(int(np.ceil(z)), 0)))  # the first sample after t0


def _offset(
    acc,
    gyr,
    dt,
    post,
    lo: int,
    b0: int,
    stop: int,
    params: HandParams,
    rate_hz: float,
    raw=None,
    flank=None,
    limit: float | None = None,
    inside: list | None = None,
    cutoff_hz: float | None = None,
) -> int:
    """Offset (exclusive sample index) of the phase whose gyroscope offset is ``b0``, with the rest window ``post``
    after it (steps 5-8 of the module docstring); ``b0`` without a usable window. ``lo``: where the velocity
    integration may start (inside the phase); ``stop``: the next phase's guard; ``raw``: the unfiltered
    (accelerometer, gyroscope) for the velocity's noise of step 8; ``flank``: a list that gets the exclusive end
    (sample index) where the offset's own flank reaches rest, not bounded by the gyroscope's offset; ``limit``: step
    8's rest check (m/s, the trial's :mod:`~imulog.process.segmentation.rest_drift`; None: the fixed one); ``inside``:
    a list that gets step 8's offset after a last part the offset lies inside of (``slow_inside``), not applied here;
    ``cutoff_hz``: step 1's cut-off (Hz, for ``flank_noise``)."""
    length = post[1] - post[0] if post is not None else 0
    quiet = max(1, int(round(params.quiet_s * rate_hz)))
    min_run = max(1, int(round(params.min_run_s * rate_hz)))
    for _ in range(3):  # a "rest" the hand still accelerates into is none: the next still window after it
        if post is None or post[0] <= b0:
            break
        a_all, v_all, noise = gravity_free(acc, gyr, dt, post, lo, post[0])
        a, v = a_all[b0 - lo :], v_all[b0 - lo :]
        level = max(params.n_sigma * noise, params.min_level_mps2)
        an, vn = np.linalg.norm(a, axis=1), np.linalg.norm(v, axis=1)
        if not sustained(an > level, min_run)[-quiet:].any():
            break
        later = still_window(acc, post[1], stop, length, length, False, 0.5 * params.n_sigma)
        if later is None or later[0] <= post[0]:
            break
        post = later
    if post is None or post[0] <= b0:
        return b0
    end = b0
    j, walked = _extend_offset(
        an,
        vn,
        0,
        level,
        params.velocity_level_mps,
        quiet,
        int(round(params.continuation_s * rate_hz)),
        params.continuation_n_level * level,
        min_run,
        params.cruise_velocity_mps,
        params.bridge_n_level,
        params.resume_cruise,
    )
    # the walk from the gyroscope's offset is trusted up to max_shift_s; motion after it that settles before the
    # rest window (a correction after a pause) is the phase's, however far the walk went
    shift = int(round(params.max_shift_s * rate_hz))
    if 0 < j <= shift or (params.settled_beyond_shift and walked <= shift < j):
        end = b0 + j
    m = len(a_all)  # the offset's flank, time reversed: from the rest into the phase
    own: list[int] = []
    end = (
        lo
        + m
        - _extrapolated(a_all[::-1], v_all[::-1], m - (end - lo), m - (b0 - lo), level, params, rate_hz, own, cutoff_hz)
    )
    if flank is not None:
        flank.extend(lo + m - z for z in own)
    return slow_tail_end(acc, gyr, dt, post, lo, end, stop, params, rate_hz, raw, limit, inside)


def speed_in_noise(v: np.ndarray, window: tuple[int, int], raw, dt: float, params: HandParams) -> np.ndarray:
    """Speed (m/s) of the velocity ``v`` (N, 3) integrated forward from the rest ``window`` (sample ``i`` of ``v``
    is ``(i + 1) dt`` s after it), scaled down where ``n_sigma`` sd of the velocity's noise there (measured at the
    window in the unfiltered ``raw`` (accelerometer, gyroscope), :func:`velocity_noise_mps`) exceeds
    ``velocity_level_mps``: compared with the fixed speed levels, it stands out of the noise as well."""
    w0, w1 = window
    acc_sd = max(white_noise(raw[0], w0, w1), params.min_level_mps2 / params.n_sigma)  # a quantised sensor
    tau = (np.arange(len(v)) + 1) * dt
    sd = velocity_noise_mps(tau, dt, (w1 - w0) * dt, acc_sd, white_noise(raw[1], w0, w1))
    level = params.velocity_level_mps
    return np.linalg.norm(v, axis=1) * (level / np.maximum(level, params.n_sigma * sd))


def cutoff_params(params: HandParams) -> BoundaryParams:
    """The accelerometer's cut-off adaptation expressed as :class:`BoundaryParams` (levels in m/s^2)."""
    return BoundaryParams(
        cutoff_hz=params.cutoff_hz,
        target_level_rad_s=params.target_level_mps2,
        min_cutoff_hz=params.min_cutoff_hz,
        n_sigma=params.n_sigma,
    )


def accelerometer_cutoff_hz(acc_mps2: np.ndarray, rate_hz: float, params: HandParams) -> float:
    """Low-pass cut-off (Hz) of the accelerometer, lowered for a noisy sensor (see ``adaptive_cutoff_hz``)."""
    return adaptive_cutoff_hz(acc_mps2, rate_hz, cutoff_params(params))


def refine_with_accelerometer(
    acc_mps2: np.ndarray,
    gyr_rad_s: np.ndarray,
    rate_hz: float,
    start: np.ndarray,
    end: np.ndarray,
    params: HandParams = HandParams(),
    *,
    cutoff_hz: float | None = None,
    bounds: tuple[int, int] | None = None,
    movements: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Onsets/offsets of time-ordered, non-overlapping phases moved outward while the hand still moves.

    ``acc_mps2`` (N, 3) specific force m/s^2 and ``gyr_rad_s`` (N, 3) rad/s in the sensor frame at
    ``rate_hz``; ``start``/``end`` the (gyroscope-refined) phases. A boundary never crosses the neighbouring
    phase nor the rest window between them. See the module docstring.

    For a piece of a longer recording: ``cutoff_hz`` is the recording's accelerometer cut-off (Hz,
    :func:`accelerometer_cutoff_hz`) and ``bounds`` as in
    :func:`~imulog.process.segmentation.boundaries.refine_phase_boundaries`. ``movements``: the detector's
    movements that overlap no phase (starts, ends; :func:`~imulog.process.segmentation.gaps.unphased_movements`),
    which end the rest next to a phase with ``params.movement_gaps``.
    """
    s = np.array(start, dtype=np.int64)
    e = np.array(end, dtype=np.int64)
    if not params.enabled or len(s) == 0 or acc_mps2 is None:
        return s, e
    raw = fill_gaps(acc_mps2)  # a missing sample must not look like a jump to 0 m/s^2
    cut = accelerometer_cutoff_hz(raw, rate_hz, params) if cutoff_hz is None else cutoff_hz
    acc = lowpass_axes(raw, rate_hz, cut)
    gyr_raw = fill_gaps(gyr_rad_s)
    gyr_cut = min(25.0, 0.45 * rate_hz)
    gyr = lowpass_axes(gyr_raw, rate_hz, gyr_cut)
    dt = 1.0 / rate_hz
    first, n = bounds if bounds is not None else (0, len(acc))
    length = max(3, int(round(params.rest_window_s * rate_hz)))
    guard = int(round(params.guard_s * rate_hz))
    quiet = max(1, int(round(params.quiet_s * rate_hz)))
    min_run = max(1, int(round(params.min_run_s * rate_hz)))
    reach = int(round(params.rest_distance_s * rate_hz))
    shift = int(round(params.max_shift_s * rate_hz))
    cont = int(round(params.continuation_s * rate_hz))
    order = np.argsort(s, kind="stable")
    ss, ee = s[order].copy(), e[order].copy()
    out_s, out_e = ss.copy(), ee.copy()
    fits = []  # per phase: where step 9's fit starts and step 2's rest window after it
    drift = None  # step 8's rest check from the trial's own still rests
    if params.rest_drift:
        drift_params = RestDriftParams(params.rest_window_s, params.rest_check_s, params.guard_s)
        drift = check_limit(acc, gyr, rate_hz, ss, ee, (first, n), drift_params, 0.5 * params.velocity_level_mps)
    rests = []  # per phase: step 2's rest windows before and after it
    for k in range(len(ss)):
        a0, b0 = int(ss[k]), int(ee[k])
        prev_end = int(out_e[k - 1]) if k > 0 else first
        next_start = int(ss[k + 1]) if k + 1 < len(ss) else n
        if params.movement_gaps:  # a movement that is no phase (the calibration wave) ends the rest too
            prev_end, next_start = gap_bounds(prev_end, next_start, a0, b0, movements)
        post = still_window(acc, b0 + guard, min(next_start, n) - guard, length, reach, False, 0.5 * params.n_sigma)
        pre = still_window(acc, prev_end + guard, a0 - guard, length, reach, True, 0.5 * params.n_sigma)
        inside = int(round(params.flank_search_s * rate_hz))  # the flank can lie inside the gyroscope's phase
        lo = max(a0, b0 - inside)
        stop = min(next_start, n) - guard
        flank_end: list[int] = []
        flank_start: list[int] = []
        held: list = []  # step 8's offset after a last part the offset lies inside of, and its window (slow_inside)
        out_e[k] = _offset(
            acc, gyr, dt, post, lo, b0, stop, params, rate_hz, (raw, gyr_raw), flank_end, drift, held, cut
        )
        reach_in = int(round(params.speed_reach_s * rate_hz))  # a slow start reaches the speed level late
        hi = max(a0, min(int(out_e[k]), a0 + max(inside, reach_in)))
        for _ in range(3):  # likewise before the onset
            if pre is None or pre[1] >= a0:
                break
            a_all, v_all, noise = gravity_free(acc, gyr, dt, pre, pre[1], hi)
            a, v = a_all[: a0 - pre[1]], v_all[: a0 - pre[1]]
            level = max(params.n_sigma * noise, params.min_level_mps2)
            an, vn = np.linalg.norm(a, axis=1)[::-1], np.linalg.norm(v, axis=1)[::-1]
            if not sustained(an > level, min_run)[-quiet:].any():
                break
            earlier = still_window(acc, prev_end + guard, pre[0], length, length, True, 0.5 * params.n_sigma)
            if earlier is None or earlier[1] >= pre[1]:
                break
            pre = earlier
        if pre is not None and pre[1] < a0:
            if params.walk_noise and params.velocity_level_mps > 0:  # the speed out of its own noise
                vn = speed_in_noise(v, pre, (raw, gyr_raw), dt, params)[::-1]
            i, _ = _extend_offset(
                an,
                vn,
                0,
                level,
                params.velocity_level_mps,
                quiet,
                cont,
                np.inf,
                min_run,
                params.cruise_velocity_mps,
                params.bridge_n_level,
            )
            if 0 < i <= shift:
                out_s[k] = a0 - i
            own: list[int] = []
            out_s[k] = pre[1] + _extrapolated(
                a_all, v_all, int(out_s[k]) - pre[1], a0 - pre[1], level, params, rate_hz, own, cut
            )
            flank_start = [pre[1] + z for z in own]
        fits.append((lo, post[0] if post is not None else None, held[0] if held else (None, None)))
        rests.append((pre, post, flank_start[-1] if flank_start else None, flank_end[-1] if flank_end else None))
    # step 9, once every onset is known: the next phase's bounds the rest
    for k, (lo, window, (last, near)) in enumerate(fits):
        stop = (int(out_s[k + 1]) if k + 1 < len(ss) else n) - guard
        end = int(out_e[k])
        if window is not None and end < window < stop:
            end = profile_end(acc, gyr, dt, lo, int(out_s[k]), end, window, stop, params, rate_hz, (raw, gyr_raw))
        # step 8's offset after a slow last part the offset lies inside of, when step 9 did not move the offset and
        # one smooth deceleration to it explains the phase's last part
        if (
            end == out_e[k]
            and last is not None
            and explains_last_part(acc, gyr, dt, near, lo, int(out_s[k]), end, last, params, rate_hz)
        ):
            end = last
        out_e[k] = max(int(out_e[k]), end)
    if params.gyro_floor:  # step 10: the gyroscope's boundaries that no step moved, trimmed to its noise floor
        trim_unmoved(gyr, int(np.ceil(rate_hz / (2.0 * gyr_cut))), ss, ee, out_s, out_e, rests)
    s[order], e[order] = out_s, out_e
    return s, e
