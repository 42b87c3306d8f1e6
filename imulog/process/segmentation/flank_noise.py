"""The low-passed noise's correlation in step 7's flank fit (issue 31 point 1, fourteenth round).

Step 1 low-passes the accelerometer with a zero-phase 2nd-order Butterworth filter whose cut-off is lowered for a
noisy sensor (:func:`~imulog.process.segmentation.boundaries.adaptive_cutoff_hz`: 25 Hz at the simulator's noise,
about 12 Hz at the median real device's), so the noise left in the gravity-free acceleration is white noise
filtered twice by that filter: its autocorrelation is known from the filter alone. An ordinary least-squares
hinge fit treats each sample's noise as independent, so a dip or bump of the low-passed noise lasting a
correlation time (twice as long at 12 Hz as at 25 Hz) counts as that many independent samples and can pass for
the rest's level and the flank's start (the thirteenth round's diagnosis). A generalised least-squares fit
weighs the residual with the inverse of the noise's covariance: here that of the filtered white noise plus a
white floor at its spectral level at step 1's nominal cut-off (frequencies above it are not trusted more than
those at it; without a floor the fit would undo the filter entirely). Pure numpy/scipy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FlankNoiseParams:
    """The noise model of step 7's generalised least-squares flank fit.

    cutoff_hz: the accelerometer's low-pass cut-off (Hz) of step 1 (the trial's, after the adaptation to its
        noise).
    rate_hz: the sampling rate (Hz).
    band_hz: the highest frequency (Hz) the fit trusts: the noise's covariance gets a white floor at the filtered
        noise's spectral level there, ``|H(band_hz)|^4`` of the white noise's variance per sample
        (:func:`floor`); step 1's nominal cut-off (``HandParams.cutoff_hz``, 25 Hz) by default, so that the fit
        weighs the band the adaptation filtered out against the noise (12-25 Hz at the devices' noise) by its
        noise, and at a cut-off the adaptation did not lower the floor is the filter's half-power level (0.25).
    order: the Butterworth filter's order (step 1's: 2).
    """

    cutoff_hz: float
    rate_hz: float
    band_hz: float = 25.0
    order: int = 2


def floor(params: FlankNoiseParams) -> float:
    """The white floor's variance in units of the white input noise's variance per sample (dimensionless): the
    zero-phase (twice applied) Butterworth filter's power ``|H(f)|^4 = (1 + (f / f_c)^(2 order))^-2`` at
    ``f = min(band_hz, rate_hz / 2)``."""
    f = min(params.band_hz, params.rate_hz / 2)
    return float((1.0 + (f / params.cutoff_hz) ** (2 * params.order)) ** -2)


def impulse_response(params: FlankNoiseParams, tail: float = 1e-4) -> np.ndarray:
    """The zero-phase filter's impulse response (``sosfiltfilt`` of a Butterworth low-pass at ``cutoff_hz``):
    symmetric, odd length, summing to 1, cut where it stays under ``tail`` of its peak; ``[1.0]`` when the cut-off
    is at or above the Nyquist frequency (step 1 then does not filter)."""
    if not params.cutoff_hz or params.cutoff_hz >= params.rate_hz / 2:
        return np.ones(1)
    from scipy.signal import butter, sosfiltfilt  # lazy: scipy.signal costs ~0.5 s to import

    sos = butter(params.order, params.cutoff_hz, btype="low", fs=params.rate_hz, output="sos")
    half = 8 * int(np.ceil(params.rate_hz / params.cutoff_hz))  # the response decays well within it
    impulse = np.zeros(2 * half + 1)
    impulse[half] = 1.0
    h = sosfiltfilt(sos, impulse)
    keep = int(np.flatnonzero(np.abs(h) >= tail * np.abs(h).max()).max()) - half
    return h[half - keep : half + keep + 1]


def filtered_correlation(params: FlankNoiseParams, lags: int) -> np.ndarray:
    """Autocovariance (lags ``0 .. lags - 1`` samples) of unit-variance white noise after the zero-phase filter
    of step 1, in units of the white noise's variance: its :func:`impulse_response` correlated with itself (1 at
    lag 0 and 0 elsewhere without a filter)."""
    h = impulse_response(params)
    full = np.correlate(h, h, mode="full")[len(h) - 1 :]
    out = np.zeros(max(int(lags), 1))
    out[: min(len(out), len(full))] = full[: len(out)]
    return out


def whitener(params: FlankNoiseParams, n: int, apart: int = 0) -> np.ndarray:
    """(n + apart, n + apart) matrix ``W`` with ``W C W^T = I`` for the covariance ``C`` of ``n`` consecutive samples
    of the low-passed noise plus the white floor (:class:`FlankNoiseParams`): ``W y`` has white residuals, so an
    ordinary least-squares fit of ``W y`` is the generalised least-squares fit of ``y``. ``apart`` > 0: as many
    samples before them from elsewhere (the rest window's), independent of the ``n``: ``W`` block-diagonal."""
    from scipy.linalg import cholesky, solve_triangular, toeplitz  # lazy, as scipy.signal

    out = np.zeros((n + apart, n + apart))
    r = filtered_correlation(params, max(n, apart))
    for lo, m in ((0, apart), (apart, n)):
        if m > 0:
            low = cholesky(toeplitz(r[:m]) + floor(params) * np.eye(m), lower=True)
            out[lo : lo + m, lo : lo + m] = solve_triangular(low, np.eye(m), lower=True)
    return out
