"""True rests for velocity resets: the gyroscope's stillness confirmed by the accelerometer (issue 32).

A segmentation's static mask comes from the angular rate: a hand that stops turning while it still translates
(a chain pushed along a table, an arm sliding) looks static to it. A velocity reset there is wrong by the
whole velocity of the translation. A sample is a *true rest* when, in addition, the gravity-free acceleration
agrees, within a centred window of ``window_s``:

* its variation is at the accelerometer's noise: the windowed standard deviation (3D, ``sqrt`` of the summed
  per-axis variances) is below ``k_noise`` x the white-noise level (estimated from first differences) x
  ``sqrt(3)``, and at least ``min_std_mps2`` (quantisation and tremor of a resting hand);
* its mean is zero within ``max_mean_mps2``: the specific force equals gravity (a resting sensor measures
  gravity only; a 1 deg tilt error of the orientation leaves 0.17 m/s^2).

With the orientation, the longer window's variation is also measured on the specific force in the sensor frame,
and the smaller of the two counts: a resting sensor's specific force is constant in its own frame whatever the
orientation filter does, while the gravity-free acceleration of a sensor with a gyroscope bias ramps during a
rest as the filter's tilt drifts (0 -> 1.5 m/s^2 over a 3 s rest of the grid's ``uncalibrated`` sensor: the
1 s window dropped the middle of such rests). A candidate rest has a still gyroscope, so a glide varies the
specific force in both frames alike. Over the short window the drift stays below the noise, and the short test
keeps the gravity-free acceleration alone.

A constant-velocity translation has neither a variation nor a mean; hand motion does not keep one for long,
and the window sees its start and end. All functions are pure numpy; accelerations in m/s^2, times in s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.numeric import moving_mean
from imulog.param_rules import check_rules
from imulog.process.rest_runs import static_runs


@dataclass(frozen=True)
class RestParams:
    """Parameters of :func:`true_rests`.

    enabled: gate the static mask with the accelerometer (off: the mask as given).
    window_s: centred window (s) over which the acceleration must stay still.
    long_window_s: a second, longer centred window (s) cut to each candidate rest (None: off).
    k_noise: allowed windowed standard deviation in units of the white-noise level (per axis).
    min_std_mps2: floor of that threshold (m/s^2).
    max_mean_mps2: largest windowed mean of the gravity-free acceleration (m/s^2) at a rest (None: off; the
        residual gravity of an uncalibrated sensor reaches 0.5 m/s^2 at true rests).
    short_max_mean_mps2: the same limit for candidate rests shorter than ``short_s`` (s) only (None: off): a
        tenth of a second of nearly constant acceleration mid-movement is no rest (a foot's 0.3 s stance with
        the residual gravity of a 6D filter during gait is not judged by it).
    mean_relative: the short candidates' limit is at least this many times the 90th percentile of the windowed
        mean at the candidates that are not short (the recording's residual gravity at rest; None: the fixed
        limit). A foot's 25-100 ms stance during gait keeps 2-4 m/s^2 where its longer stances keep up to
        1.3-1.7 m/s^2; a hand's rest keeps < 0.1 m/s^2, an uncalibrated sensor's up to 0.5 m/s^2. (The same
        limit on every candidate dropped true rests' edges on the drinking grid: ZUPT +0.13 cm in x at 50 Hz.)
    long_dilate: a sample is still for the long window when any 1-s window of its candidate run that holds it
        is still (not only the centred one): a true rest beside motion inside one candidate run is kept.
    min_rest_s: rests shorter than this (s) are not rests.
    """

    enabled: bool = True
    window_s: float = 0.25
    long_window_s: float | None = 1.0
    k_noise: float = 3.0
    min_std_mps2: float = 0.06
    max_mean_mps2: float | None = None
    short_max_mean_mps2: float | None = 0.6
    short_s: float = 0.2
    mean_relative: float | None = 3.0
    min_rest_s: float = 0.0
    long_dilate: bool = True
    run_mean: bool = True
    run_mean_max_s: float = 1.0
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def white_noise_mps2(acc_mps2: np.ndarray) -> float:
    """Per-axis white-noise standard deviation (m/s^2) from first differences (robust: median absolute
    deviation / sqrt 2, median over axes); smooth motion hardly contributes at IMU rates."""
    a = np.asarray(acc_mps2, dtype=np.float64).reshape(len(acc_mps2), -1)
    d = np.diff(a, axis=0)
    d = d[np.all(np.isfinite(d), axis=1)]
    if len(d) < 3:
        return 0.0
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0) * 1.4826
    return float(np.median(mad) / np.sqrt(2.0))


def sensor_frame_force(acc_global_mps2: np.ndarray, q_s2g: np.ndarray, gravity_mps2: float = 9.80665) -> np.ndarray:
    """Specific force (N, 3) m/s^2 in the sensor frame from the gravity-free global acceleration and the
    sensor-to-global orientation (N, 4) w,x,y,z used to compute it (an error in ``gravity_mps2`` adds a
    constant while the sensor does not turn)."""
    from imulog.process import quaternion as quat

    a = np.asarray(acc_global_mps2, dtype=np.float64)
    return quat.rotate_inverse(np.asarray(q_s2g, dtype=np.float64), a + np.array([0.0, 0.0, gravity_mps2]))


def _window_std(a0: np.ndarray, w: int) -> np.ndarray:
    """3D standard deviation of ``a0`` (N, D) over a centred window of ``w`` samples."""
    mean = moving_mean(a0, w)
    return np.sqrt(np.maximum(moving_mean(a0**2, w) - mean**2, 0.0).sum(axis=1))


def _run_std(a: np.ndarray, mask: np.ndarray, w: int) -> np.ndarray:
    """3D standard deviation of ``a`` (N, D) over a centred window of ``w`` samples cut to the True run of
    ``mask`` that holds each sample (inf outside runs)."""
    n = len(a)
    out = np.full(n, np.inf)
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    c1 = np.vstack([np.zeros((1, a.shape[1])), np.cumsum(a, axis=0)])
    c2 = np.vstack([np.zeros((1, a.shape[1])), np.cumsum(a**2, axis=0)])
    for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        i = np.arange(s, e)
        lo = np.clip(i - w // 2, s, e)
        hi = np.clip(i - w // 2 + w, s, e)
        k = np.maximum(hi - lo, 1)[:, None]
        m = (c1[hi] - c1[lo]) / k
        out[s:e] = np.sqrt(np.maximum((c2[hi] - c2[lo]) / k - m**2, 0.0).sum(axis=1))
    return out


def _short_and_accelerating(mean: np.ndarray, cand: np.ndarray, w: int, limit: float) -> np.ndarray:
    """Samples of candidate runs shorter than ``w`` whose windowed mean acceleration exceeds ``limit`` (m/s^2)
    anywhere in the run (the whole run is then no rest)."""
    out = np.zeros(len(cand), dtype=bool)
    d = np.diff(np.concatenate([[0], cand.astype(np.int8), [0]]))
    norm = np.linalg.norm(mean, axis=1)
    for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        if e - s < w and norm[s:e].max() > limit:
            out[s:e] = True
    return out


def _accelerating_runs(a0: np.ndarray, still: np.ndarray, limit: float, max_samples: int) -> np.ndarray:
    """Samples of the True runs of ``still`` shorter than ``max_samples`` whose mean acceleration (3D norm of the
    run's mean vector, m/s^2) exceeds ``limit`` (the whole run is then no rest)."""
    out = np.zeros(len(still), dtype=bool)
    for s, e in static_runs(still):
        if e - s < max_samples and np.linalg.norm(a0[s:e].mean(axis=0)) > limit:
            out[s:e] = True
    return out


def _long_runs(mask: np.ndarray, min_samples: int) -> np.ndarray:
    """The True runs of ``mask`` at least ``min_samples`` long."""
    out = np.zeros(len(mask), dtype=bool)
    for s, e in static_runs(mask, min_samples):
        out[s:e] = True
    return out


def accelerometer_still(
    acc_global_mps2: np.ndarray,
    rate_hz: float,
    params: RestParams = RestParams(),
    candidates: np.ndarray | None = None,
    orientation: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) bool: the gravity-free acceleration (N, 3) m/s^2 is still (variation at noise, mean near zero)
    within the centred window. With ``orientation`` (N, 4) sensor-to-global, the longer window's variation is
    the smaller of the global and the sensor-frame one (:func:`sensor_frame_force`). NaN samples are never
    still."""
    a = np.asarray(acc_global_mps2, dtype=np.float64).reshape(len(acc_global_mps2), -1)
    ok = np.all(np.isfinite(a), axis=1)
    a0 = np.where(ok[:, None], a, 0.0)
    frames = [(a0, ok)]  # (values, valid) per frame the long window is measured in
    if orientation is not None:
        f = sensor_frame_force(a, orientation)
        ok_f = ok & np.all(np.isfinite(f), axis=1)  # no orientation: the gravity-free frame alone
        frames.append((np.where(ok_f[:, None], f, 0.0), ok_f))
    w = max(int(round(params.window_s * rate_hz)), 1)
    mean = moving_mean(a0, w)
    sigma = white_noise_mps2(a[ok]) if ok.any() else 0.0
    limit = max(params.k_noise * sigma * np.sqrt(a.shape[1]), params.min_std_mps2)
    still = _window_std(a0, w) <= limit
    if params.max_mean_mps2 is not None:
        still &= np.linalg.norm(mean, axis=1) <= params.max_mean_mps2
    still &= moving_mean((~ok).astype(float)[:, None], w)[:, 0] == 0
    # every sample of a still window is still (the centred test alone would cut w/2 off each end of a rest)
    still = moving_mean(still.astype(float)[:, None], w)[:, 0] > 0
    if params.long_window_s and candidates is not None:
        # a slow translation (a glide while the wrist stops turning) varies little within window_s but much
        # within a second; the longer window is cut to each candidate rest, so short rests (a foot's stance,
        # a 0.3 s pause) are judged on their own samples
        cand = np.asarray(candidates, dtype=bool)
        wl = max(int(round(params.long_window_s * rate_hz)), 1)
        long_still = np.min([_run_std(x, cand & v, wl) for x, v in frames], axis=0) <= limit
        if params.long_dilate:
            # a rest beside motion inside one candidate run: a still 1-s window holds it
            long_still = cand & (moving_mean(long_still.astype(float)[:, None], wl)[:, 0] > 0)
        still &= cand & long_still
        if params.short_max_mean_mps2 is not None:
            # the specific force must equal gravity within what this recording's own rests leave (a 6D filter's
            # tilt error during gait leaves 1-2 m/s^2 at a foot's stance, an uncalibrated sensor 0.5 m/s^2 at a
            # hand's rest): the level is the windowed mean at candidates that are no short ones
            ws = max(int(round(params.short_s * rate_hz)), 1)
            long_cand = _long_runs(cand, ws)
            level = np.linalg.norm(mean[still & long_cand], axis=1)
            limit_mean = params.short_max_mean_mps2
            if params.mean_relative and len(level):
                limit_mean = max(limit_mean, params.mean_relative * float(np.percentile(level, 90)))
            # a very short candidate is judged on few samples: a tenth of a second of nearly constant
            # acceleration mid-movement passes the variation tests, so it must also be near zero as a whole
            still &= ~_short_and_accelerating(mean, cand, ws, limit_mean)
            if params.run_mean:  # a rest is still, not just slow: no run keeps accelerating as a whole
                still &= ~_accelerating_runs(a0, still, limit_mean, int(round(params.run_mean_max_s * rate_hz)))
    return still


def _drop_short(mask: np.ndarray, min_samples: int) -> np.ndarray:
    out = mask.copy()
    if min_samples <= 1 or not out.any():
        return out
    d = np.diff(np.concatenate([[0], out.astype(np.int8), [0]]))
    for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        if e - s < min_samples:
            out[s:e] = False
    return out


def true_rests(
    static_mask: np.ndarray,
    acc_global_mps2: np.ndarray,
    rate_hz: float,
    params: RestParams = RestParams(),
    orientation: np.ndarray | None = None,
) -> np.ndarray:
    """The static mask (N,) bool restricted to samples where the accelerometer agrees
    (:func:`accelerometer_still`; ``orientation`` (N, 4) sensor-to-global of ``acc_global_mps2`` adds the
    sensor frame), rests shorter than ``min_rest_s`` dropped."""
    static = np.asarray(static_mask, dtype=bool)
    if not params.enabled:
        return static.copy()
    rest = static & accelerometer_still(acc_global_mps2, rate_hz, params, candidates=static, orientation=orientation)
    return _drop_short(rest, int(round(params.min_rest_s * rate_hz)))


def rest_report(static_mask: np.ndarray, rests: np.ndarray, rate_hz: float) -> dict:
    """What the accelerometer gate removed: static samples (s) before and after, and static runs that lost
    every sample (a turning pause during translation)."""
    s0, s1 = np.asarray(static_mask, bool), np.asarray(rests, bool)
    d = np.diff(np.concatenate([[0], s0.astype(np.int8), [0]]))
    runs = list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))
    lost = sum(1 for a, b in runs if not s1[a:b].any())
    return {
        "static_s": round(float(s0.sum() / rate_hz), 3),
        "rest_s": round(float(s1.sum() / rate_hz), 3),
        "static_runs": len(runs),
        "static_runs_not_rests": int(lost),
    }
