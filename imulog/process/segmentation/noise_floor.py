"""Gyroscope boundaries that the hand did not move, trimmed to the gyroscope's noise floor (issue 31 point 1).

Step 10 of :mod:`~imulog.process.segmentation.hand`, an option (``HandParams.gyro_floor``, off by default). The
gyroscope refinement (:mod:`~imulog.process.segmentation.boundaries`, step 3) walks a boundary outward past its
level crossing while ``r = |omega - b|`` keeps falling ("descend"); below the rest's own noise a fall is noise,
not the movement's flank. At 50 Hz the walk ends about a sample into the rest at each end (on the grid's
``rate-50hz`` condition 23 of the 24 phases outside 0.1 s had both ends within 0.1 s, the onset early and the
offset late, most of them the gyroscope's own boundaries). Where the accelerometer found the hand moving beyond
the gyroscope's boundary, its boundary stands; where it left the gyroscope's boundary as it was, the samples at
that boundary whose ``r`` is at or under the median ``r`` of the adjacent rest window (what the noise alone gives
half the time) are not motion, and the boundary moves inward past them when they are at most ``most`` samples
(the hand step bounds the trim by its own flank too). docs/accuracy.md (ninth round) has the figures.
Pure numpy; indices are sample indices, intervals half-open.
"""

from __future__ import annotations

import numpy as np


def rest_floor(gyr: np.ndarray, window: tuple[int, int]) -> tuple[np.ndarray, float]:
    """Bias (3,) rad/s (per-axis median) and noise floor (rad/s, median of ``|omega - b|``) of the low-passed
    gyroscope ``gyr`` (N, 3) rad/s over a rest ``window`` ``[w0, w1)``."""
    w = np.asarray(gyr[window[0] : window[1]], dtype=float)
    bias = np.median(w, axis=0)
    return bias, float(np.median(np.linalg.norm(w - bias, axis=1)))


def trim_onset(gyr: np.ndarray, start: int, end: int, window: tuple[int, int], most: int) -> int:
    """``start`` moved inward past the samples whose ``|omega - b|`` is at or under the noise floor of the rest
    ``window`` before the phase (:func:`rest_floor`), when there are at most ``most`` of them (a fall of the noise
    lasts about its correlation time; a longer stretch under the floor is the flank's slow start, kept)."""
    bias, floor = rest_floor(gyr, window)
    i = int(start)
    while i + 1 < end and np.linalg.norm(gyr[i] - bias) <= floor:
        i += 1
    return i if i - start <= most else int(start)


def trim_offset(gyr: np.ndarray, start: int, end: int, window: tuple[int, int], most: int) -> int:
    """``end`` (exclusive) moved inward past the samples whose ``|omega - b|`` is at or under the noise floor of
    the rest ``window`` after the phase (:func:`rest_floor`), when there are at most ``most`` of them (see
    :func:`trim_onset`)."""
    bias, floor = rest_floor(gyr, window)
    j = int(end)
    while j - 1 > start and np.linalg.norm(gyr[j - 1] - bias) <= floor:
        j -= 1
    return j if end - j <= most else int(end)


def trim_unmoved(gyr: np.ndarray, most: int, gyro_s, gyro_e, out_s: np.ndarray, out_e: np.ndarray, rests) -> None:
    """Step 10 in place on ``out_s``/``out_e`` (time-ordered phases, sample indices): an onset (offset) still at the
    gyroscope's ``gyro_s`` (``gyro_e``) is trimmed (:func:`trim_onset`, :func:`trim_offset`, at most ``most``
    samples; ``most``: the filtered noise's correlation time) as far as the phase's own flank agrees. ``rests``:
    per phase (rest window before, rest window after, the flank's own onset, its own offset), None where missing."""
    for k, (pre, post, hand_s, hand_e) in enumerate(rests):
        if pre is not None and hand_s is not None and hand_s > out_s[k] == gyro_s[k] and pre[1] <= out_s[k]:
            out_s[k] = min(trim_onset(gyr, int(out_s[k]), int(out_e[k]), pre, most), hand_s)
        if post is not None and hand_e is not None and hand_e < out_e[k] == gyro_e[k] and post[0] >= out_e[k]:
            out_e[k] = max(trim_offset(gyr, int(out_s[k]), int(out_e[k]), post, most), hand_e)
