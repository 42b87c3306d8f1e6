"""Double-threshold movement detector of Bai et al. (Sensors 2023, 23:360), after the speech end-point detector.

The gyroscope signal is cut into short frames. Per frame ``i``:

* short-time energy ``E_i = mean(|gyr|^2)`` over the frame ((rad/s)^2; the paper sums, we average so that
  thresholds do not depend on the frame length);
* zero-crossing rate ``Z_i``: fraction of consecutive sample pairs whose sign changes, averaged over the
  three axes after removing each axis' static bias (1/sample).

A movement is seeded where ``E > T1`` (high threshold: excludes noise), extended on both sides while
``E > T2`` (low threshold: includes every real movement), then extended by at most ``zcr_extension_s`` while
``Z < T3`` (a still sensor shows noise that crosses zero often; a slow movement does not). Everything outside
movements is a zero-velocity interval.

T1, T2 and T3 were found by trial and error in the paper (values not published); the defaults here are for a
wrist or hand IMU (T1 = (0.5 rad/s)^2, T2 = (0.1 rad/s)^2, T3 = 0.2) and are documented in docs/segmentation.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.param_rules import check_rules
from imulog.process.segmentation.dynamos import runs


@dataclass(frozen=True)
class DoubleThresholdParams:
    """Parameters of :func:`double_threshold`.

    frame_s: frame length (s); hop_s: frame step (s).
    t1: high energy threshold ((rad/s)^2); t2: low energy threshold ((rad/s)^2), ``t2 < t1``.
    t3: zero-crossing-rate threshold (sign changes per sample pair, 0..1).
    zcr_extension_s: longest extension (s) of a movement by the zero-crossing criterion.
    min_movement_s: movements shorter than this (s) are dropped; min_rest_s: shorter rests are closed.
    """

    frame_s: float = 0.1
    hop_s: float = 0.05
    t1: float = 0.25
    t2: float = 0.01
    t3: float = 0.2
    zcr_extension_s: float = 0.25
    min_movement_s: float = 0.1
    min_rest_s: float = 0.0
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def frame_features(gyr_rad_s: np.ndarray, rate_hz: float, frame_s: float, hop_s: float):
    """Frame starts (samples), short-time energy ((rad/s)^2) and zero-crossing rate (per sample pair)."""
    gyr = np.asarray(gyr_rad_s, dtype=float)
    if gyr.ndim == 1:
        gyr = gyr[:, None]
    gyr = np.where(np.isfinite(gyr), gyr, 0.0)
    n = len(gyr)
    frame = max(2, int(round(frame_s * rate_hz)))
    hop = max(1, int(round(hop_s * rate_hz)))
    starts = np.arange(0, max(n - frame, 0) + 1, hop)
    sq = np.concatenate([[0.0], np.cumsum(np.sum(gyr**2, axis=1))])
    energy = (sq[starts + frame] - sq[starts]) / frame
    # bias: per-axis median of the quietest 10 % of samples
    norm = np.linalg.norm(gyr, axis=1)
    quiet = norm <= np.quantile(norm, 0.1) if n else np.zeros(0, bool)
    bias = np.median(gyr[quiet], axis=0) if quiet.any() else np.zeros(gyr.shape[1])
    sign = np.signbit(gyr - bias)
    change = np.concatenate([np.zeros((1, gyr.shape[1])), (sign[1:] != sign[:-1])]).mean(axis=1)
    cc = np.concatenate([[0.0], np.cumsum(change)])
    zcr = (cc[starts + frame] - cc[starts + 1]) / (frame - 1)
    return starts, energy, zcr


def double_threshold(
    gyr_rad_s: np.ndarray, rate_hz: float, params: DoubleThresholdParams = DoubleThresholdParams()
) -> tuple[np.ndarray, np.ndarray]:
    """Movements ``[start, end)`` (samples) from a gyroscope signal (N, 3) rad/s; see the module docstring."""
    if params.t2 >= params.t1:
        raise ValueError(f"T2 ({params.t2}) must be below T1 ({params.t1})")
    n = len(gyr_rad_s)
    starts, energy, zcr = frame_features(gyr_rad_s, rate_hz, params.frame_s, params.hop_s)
    if len(starts) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    frame = max(2, int(round(params.frame_s * rate_hz)))
    hop = max(1, int(round(params.hop_s * rate_hz)))
    low_s, low_e = runs(energy > params.t2)
    ext = int(round(params.zcr_extension_s * rate_hz / hop))
    moving = np.zeros(len(energy), dtype=bool)
    for a, b in zip(low_s, low_e, strict=True):
        if not np.any(energy[a:b] > params.t1):
            continue  # never reached the high threshold: noise
        k = 0
        while k < ext and a - 1 >= 0 and zcr[a - 1] < params.t3 and energy[a - 1] <= params.t2:
            a -= 1
            k += 1
        k = 0
        while k < ext and b < len(energy) and zcr[b] < params.t3 and energy[b] <= params.t2:
            b += 1
            k += 1
        moving[a:b] = True
    fs, fe = runs(moving)
    start = starts[fs]
    end = np.minimum(starts[fe - 1] + frame, n)
    # frames overlap: movement samples are those covered by centre-aligned hops
    start = np.minimum(start + (frame - hop) // 2, n)
    end = np.maximum(end - (frame - hop) // 2, start)
    return clean_intervals(start, end, rate_hz, params.min_movement_s, params.min_rest_s)


def clean_intervals(
    start: np.ndarray, end: np.ndarray, rate_hz: float, min_length_s: float, min_gap_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Close gaps shorter than ``min_gap_s`` then drop intervals shorter than ``min_length_s`` (s)."""
    s, e = list(np.asarray(start, dtype=np.int64)), list(np.asarray(end, dtype=np.int64))
    if min_gap_s > 0 and s:
        ms, me = [s[0]], [e[0]]
        for a, b in zip(s[1:], e[1:], strict=True):
            if a - me[-1] < min_gap_s * rate_hz:
                me[-1] = max(me[-1], b)
            else:
                ms.append(a)
                me.append(b)
        s, e = ms, me
    s, e = np.asarray(s, dtype=np.int64), np.asarray(e, dtype=np.int64)
    keep = (e - s) >= min_length_s * rate_hz
    return s[keep], e[keep]
