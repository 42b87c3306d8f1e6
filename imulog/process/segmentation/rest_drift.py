"""How the velocity integrated over a real rest drifts, per trial, from the trial's own still rests (issue 31 point 1).

Step 8 of :mod:`~imulog.process.segmentation.hand` verifies step 2's rest window before it extends an offset over a
slow last part: the velocity integrated forward from the window must stay under a limit for ``rest_check_s``. The
limit was fixed (half ``velocity_level_mps``, 1.5 cm/s) while a still hand's integrated velocity depends on the
sensor and the trial (the window mean's error, the tilt from the gyroscope's noise and bias, the hand's residual
velocity): on the simulated ``stroke-slow`` trials real rests read 1.5-1.9 cm/s, 3.0-3.6 sd of the white-noise
model of :func:`~imulog.process.segmentation.arrival.velocity_noise_mps` (eleventh round, docs/accuracy.md).

The trial's own rests say what a still hand reads: in every gap between two phases long enough for a window and
the check, the quietest window of ``window_s`` (:func:`~imulog.process.segmentation.boundaries.quietest_window`,
the surest rest of the gap) and the largest speed (m/s) of the velocity integrated from it over ``check_s`` into the
gap (forward, or backward where the gap has no room after the window). Over a still hand that speed is the norm of
three axes' drift; its per-axis sd is the median over the gaps divided by :data:`CHI3_MEDIAN` (a median keeps the
gaps whose "rest" still holds part of a slow phase from setting it, while they are fewer than half), and a rest
reads under :data:`~imulog.process.segmentation.arrival.STILL_SPEED_SD` sd of it 95 % of the time.
Pure numpy; indices are sample indices, intervals half-open.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process.segmentation.arrival import STILL_SPEED_SD, gravity_free
from imulog.process.segmentation.boundaries import quietest_window

# median of the norm of a 3-D standard normal vector (chi with 3 degrees of freedom): sd per axis = median / this
CHI3_MEDIAN = 1.5382


@dataclass(frozen=True)
class RestDriftParams:
    """Where the drift of a still hand is measured (units in the names).

    window_s: the rest window's length (s), as step 2's.
    check_s: how long (s) the velocity is integrated from the window, as step 8's check.
    guard_s: the window and the integration keep this distance (s) from the phases.
    min_rests: fewer gaps with room for a window and the check give no model (None).
    n_sd: the limit a still hand's speed stays under, in sd per axis of the model (2.795: 95 % of a 3-D normal).
    """

    window_s: float = 0.5
    check_s: float = 1.5
    guard_s: float = 0.05
    min_rests: int = 5
    n_sd: float = STILL_SPEED_SD


@dataclass(frozen=True)
class RestDrift:
    """A trial's model of a still hand's integrated velocity over ``check_s``.

    sd_mps: per-axis sd (m/s) of the velocity a still hand reaches within ``check_s`` of a rest window.
    rests: how many of the trial's gaps it was measured on.
    check_s: the integration span (s) it holds for.
    """

    sd_mps: float
    rests: int
    check_s: float

    def limit_mps(self, n_sd: float) -> float:
        """The speed (m/s) a still hand's integrated velocity stays under: ``n_sd`` sd per axis."""
        return n_sd * self.sd_mps


def still_speeds(
    acc: np.ndarray, gyr: np.ndarray, dt_s: float, gaps: list[tuple[int, int]], length: int, check: int
) -> np.ndarray:
    """Largest speed (m/s) of the velocity integrated over ``check`` samples from the quietest window of ``length``
    samples of each gap ``[lo, hi)`` with room for both (``acc`` m/s^2 and ``gyr`` rad/s low-passed, (N, 3)):
    forward when the gap has room after the window, else backward."""
    out = []
    for lo, hi in gaps:
        if hi - lo < length + check:
            continue
        w = quietest_window(acc, lo, hi, length)
        if w is None or w[1] - w[0] < length:
            continue
        if w[1] + check <= hi:
            v = gravity_free(acc, gyr, dt_s, w, w[1], w[1] + check)[1]
        elif w[0] - check >= lo:
            v = gravity_free(acc, gyr, dt_s, w, w[0] - check, w[0])[1]
        else:  # the quietest window in the gap's middle: integrate into the longer side
            v = (
                gravity_free(acc, gyr, dt_s, w, w[1], hi)[1]
                if hi - w[1] >= w[0] - lo
                else gravity_free(acc, gyr, dt_s, w, lo, w[0])[1]
            )
        out.append(float(np.linalg.norm(v, axis=1).max()))
    return np.asarray(out, dtype=float)


def rest_drift(
    acc: np.ndarray,
    gyr: np.ndarray,
    rate_hz: float,
    starts: np.ndarray,
    ends: np.ndarray,
    bounds: tuple[int, int],
    params: RestDriftParams = RestDriftParams(),
) -> RestDrift | None:
    """The trial's :class:`RestDrift` from the gaps between its phases ``[starts, ends)`` (time-ordered sample
    indices) within ``bounds`` (the recording's ``[first, n)``), None with fewer than ``min_rests`` usable gaps."""
    guard = int(round(params.guard_s * rate_hz))
    length = max(3, int(round(params.window_s * rate_hz)))
    check = max(1, int(round(params.check_s * rate_hz)))
    edges = [int(bounds[0]) - guard, *np.asarray(ends, dtype=int), int(bounds[1]) + guard]
    nexts = [*np.asarray(starts, dtype=int), int(bounds[1]) + guard]
    gaps = [(edges[i] + guard, nexts[i] - guard) for i in range(len(nexts))]
    speeds = still_speeds(acc, gyr, 1.0 / rate_hz, gaps, length, check)
    if len(speeds) < max(1, params.min_rests):
        return None
    return RestDrift(float(np.median(speeds)) / CHI3_MEDIAN, len(speeds), params.check_s)


def check_limit(
    acc: np.ndarray,
    gyr: np.ndarray,
    rate_hz: float,
    starts: np.ndarray,
    ends: np.ndarray,
    bounds: tuple[int, int],
    params: RestDriftParams,
    fixed_mps: float,
) -> float | None:
    """Step 8's rest-check limit (m/s): ``n_sd`` sd of the trial's :func:`rest_drift` where that is more than
    ``fixed_mps`` (the fixed limit), else ``fixed_mps``; None without a model. The trial's rests raise the fixed
    limit where a still hand reads more; they never lower it (a lower limit refused a real rest's window reading
    1.45 cm/s on a development trial, docs/accuracy.md, issue 31 eleventh round)."""
    model = rest_drift(acc, gyr, rate_hz, starts, ends, bounds, params)
    return None if model is None else max(model.limit_mps(params.n_sd), float(fixed_mps))
