"""Step 2 of :mod:`~imulog.process.segmentation.hand`: where a phase's rest window lies in the gap next to it.

A window of the rest next to a phase gives the static specific force (the sensor's gravity reading and bias) and
the noise that the accelerometer steps measure the hand's motion against; it must lie where the hand is still.
Pure numpy; intervals are half-open sample ranges ``[start, end)``.
"""

from __future__ import annotations

import numpy as np


def rest_window(lo: int, hi: int, length: int, reach: int, from_end: bool):
    """``[a, a + length)`` in the gap ``[lo, hi)``: centred at the gap's middle or, in a longer gap, ``reach``
    samples from the phase (``lo`` side; the ``hi`` side when ``from_end``); None below 3 samples.
    The middle of a rest is farthest from both phases (the hand is most surely still there); a nearer window
    in a long rest keeps the velocity integrated from it accurate."""
    lo, hi = max(0, int(lo)), int(hi)
    length = min(int(length), hi - lo)
    if length < 3:
        return None
    centre = (lo + hi) // 2
    if hi - lo > 2 * reach:
        centre = hi - reach if from_end else lo + reach
    a = int(np.clip(centre - length // 2, lo, hi - length))
    return a, a + length


def still_window(acc: np.ndarray, lo: int, hi: int, length: int, reach: int, from_end: bool, n_sigma: float = 2.5):
    """:func:`rest_window`, moved away from the phase (up to the gap's middle) when it is not still.

    The window ``reach`` from the phase's gyroscope boundary lies in the rest only if that boundary is right;
    a slow last submovement (the wrist no longer turning) can still be under way there. Of the windows between
    the default position and the gap's middle, the quietest (smallest acceleration variance, summed over the
    axes) is the surest rest (the middle itself can lie in a calibration wave); the one nearest the phase is
    taken whose mean specific force (m/s^2) is within ``n_sigma`` x the quietest's noise (per-axis robust sd,
    rms over the axes; half the motion level) of the quietest's mean (a hand still decelerating into it is not
    still; a rest drifting at 1-2 cm/s, whose acceleration stays under 0.04 m/s^2, is left as it is) and whose
    variance is at most twice the smallest: the default position whenever it is as still as the quietest; else
    half a window beyond the first such window (the quietest when none is)."""
    w = rest_window(lo, hi, length, reach, from_end)
    if w is None or hi - lo <= 2 * reach:
        return w
    length = w[1] - w[0]
    mid = (lo + hi) // 2 - length // 2
    first, last = (mid, w[0]) if from_end else (w[0], mid)
    if last <= first:
        return w
    seg = np.asarray(acc[first : last + length], dtype=float)
    c1 = np.concatenate([np.zeros((1, 3)), np.cumsum(seg, axis=0)])
    c2 = np.concatenate([np.zeros((1, 3)), np.cumsum(seg**2, axis=0)])
    s1, s2 = c1[length:] - c1[:-length], c2[length:] - c2[:-length]
    var = (s2 - s1**2 / length).sum(axis=1) / length
    quiet = first + int(np.argmin(var))  # the surest rest: the quietest window of the range
    ref = np.asarray(acc[quiet : quiet + length], dtype=float)
    centre = np.median(ref, axis=0)
    noise = float(np.sqrt(np.mean((1.4826 * np.median(np.abs(ref - centre), axis=0)) ** 2)))
    shift = np.linalg.norm(s1 / length - ref.mean(axis=0), axis=1)
    ok = np.flatnonzero((var <= 2.0 * var.min()) & (shift <= n_sigma * noise))
    if len(ok) == 0:
        return quiet, quiet + length
    a = first + int(ok[-1] if from_end else ok[0])
    if a == w[0]:  # the default position is still
        return w
    # half a window further: the test averages over the window, so its near edge may still see a tail's end
    a = max(a - length // 2, mid) if from_end else min(a + length // 2, mid)
    return a, a + length
