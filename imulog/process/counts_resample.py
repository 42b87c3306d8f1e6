"""ActiLife's resampler to 30 Hz for the ActiGraph counts at 40, 50, 70, 80 and 100 Hz (pure numerics, g).

ActiLife (and ActiGraph's own reference implementation, the ``agcounts`` package, whose ``extract.py`` describes
the steps; Neishabouri et al. 2022, Sci Rep 12:11958, describe the rest of the counts pipeline) brings a rate that
is not a multiple of 30 Hz to 30 Hz in three steps, with the rational factors 30/rate = L/M (3/4, 3/5, 3/7, 3/8,
3/10):

1. upsample by L by inserting L-1 zeros after each sample;
2. low-pass the upsampled signal with a first-order IIR, the bilinear transform of a one-pole analogue filter whose
   cut-off is the input's Nyquist frequency:
   ``y[n] = g (u[n] + u[n-1]) - c y[n-1]`` with ``g = L pi / (pi + 2 L)`` (the factor L restores the gain the
   zeros removed) and ``c = (pi - 2 L) / (pi + 2 L)``, starting from rest (``u[-1] = y[-1] = 0``);
3. keep every M-th sample, the first one included.

This filter attenuates little above 15 Hz, so the counts carry aliasing at these rates (Brønd et al. 2015,
"Sampling frequency affects ActiGraph activity counts"); the rule is reproduced because the counts are defined by
what ActiLife computes. imulog's implementation is its own, written from that description (agcounts is GPL-3.0 and
is not a dependency).
"""

from __future__ import annotations

import numpy as np

#: rates (Hz) ActiLife accepts that are not multiples of 30 Hz: they use this resampler
ACTILIFE_RESAMPLED_RATES_HZ = (40.0, 50.0, 70.0, 80.0, 100.0)


def is_actilife_resampled(rate_hz: float) -> bool:
    """True when ActiLife brings ``rate_hz`` to 30 Hz with :func:`actilife_to_30hz` (40, 50, 70, 80, 100 Hz)."""
    return any(abs(rate_hz - r) < 1e-9 for r in ACTILIFE_RESAMPLED_RATES_HZ)


def actilife_lowpass_coefficients(up: int) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of ActiLife's first-order anti-imaging low-pass at L = ``up`` times the input rate (see module)."""
    g = up * np.pi / (np.pi + 2 * up)
    c = (np.pi - 2 * up) / (np.pi + 2 * up)
    return np.array([g, g]), np.array([1.0, c])


def actilife_to_30hz(acc_g: np.ndarray, up: int, down: int) -> np.ndarray:
    """Acceleration (N, 3) g resampled by ``up``/``down`` as ActiLife does (zeros, one-pole low-pass from rest,
    every ``down``-th sample from the first), (ceil(N up / down), 3) g. Not rounded: the counts filter rounds to
    1 mg."""
    from scipy.signal import lfilter

    a = np.asarray(acc_g, dtype=np.float64)
    u = np.zeros((len(a) * up,) + a.shape[1:])
    u[::up] = a
    b_lp, a_lp = actilife_lowpass_coefficients(up)
    return lfilter(b_lp, a_lp, u, axis=0)[::down]
