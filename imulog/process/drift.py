"""Drift removal after double integration: high-pass filtering and wavelet trend removal (Bai et al. 2023).

Both act on a position signal ``pos_m`` (N,) or (N, D) in m sampled at ``rate_hz`` (uniform), typically
the output of :func:`imulog.process.integration.double_integrate`.

* High-pass (Bai 3.3): cut-off 0.3 Hz. Bai designed the filter in MATLAB's Filter Designer without
  giving its order; we use a Butterworth of order 2 run forwards and backwards (zero phase, so an
  effective order 4 and no delay).
* Wavelet (Bai 3.2 / 4.2): ``db6`` decomposition to level 9; the drift trend is the reconstruction from
  D8, D9 and A9 only; the corrected position is the signal minus that trend. When the signal is too
  short for the requested level, the level is lowered to PyWavelets' maximum useful level and the
  trend is taken from the same number of top detail levels (here 2) plus the approximation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pywt
from scipy import signal

from imulog.param_rules import check_rules


@dataclass(frozen=True)
class HighpassParams:
    """Zero-phase Butterworth high-pass. cutoff_hz: -3 dB frequency (Hz); order: per pass."""

    cutoff_hz: float = 0.3
    order: int = 2
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def highpass(x: np.ndarray, rate_hz: float, params: HighpassParams = HighpassParams()) -> np.ndarray:
    """High-pass filter ``x`` (N,) or (N, D) along time; returns the same shape and units."""
    a = np.asarray(x, dtype=np.float64)
    if not 0 < params.cutoff_hz < rate_hz / 2:
        raise ValueError(f"cutoff {params.cutoff_hz} Hz must lie in (0, {rate_hz / 2}) Hz")
    sos = signal.butter(params.order, params.cutoff_hz, btype="highpass", fs=rate_hz, output="sos")
    padlen = min(3 * (2 * len(sos) + 1) * 2, a.shape[0] - 1)
    return signal.sosfiltfilt(sos, a, axis=0, padlen=max(padlen, 0))


@dataclass(frozen=True)
class WaveletParams:
    """Wavelet trend removal. trend_details: how many of the coarsest detail levels join the approximation."""

    wavelet: str = "db6"
    level: int = 9
    trend_details: int = 2  # D8 and D9 at level 9
    mode: str = "symmetric"
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def wavelet_effective_level(n: int, params: WaveletParams = WaveletParams()) -> int:
    """Decomposition level actually used for a signal of ``n`` samples (<= params.level)."""
    max_level = pywt.dwt_max_level(n, pywt.Wavelet(params.wavelet).dec_len)
    return max(1, min(params.level, max_level))


def wavelet_trend(x: np.ndarray, params: WaveletParams = WaveletParams()) -> np.ndarray:
    """Low-frequency trend of ``x`` (N,) or (N, D): reconstruction from A_L and the top detail levels."""
    a = np.asarray(x, dtype=np.float64)
    squeeze = a.ndim == 1
    if squeeze:
        a = a[:, None]
    level = wavelet_effective_level(len(a), params)
    out = np.empty_like(a)
    for j in range(a.shape[1]):
        coeffs = pywt.wavedec(a[:, j], params.wavelet, mode=params.mode, level=level)
        # coeffs = [A_L, D_L, D_{L-1}, ..., D_1]; keep A_L and the first trend_details details
        kept = [c if i <= params.trend_details else np.zeros_like(c) for i, c in enumerate(coeffs)]
        out[:, j] = pywt.waverec(kept, params.wavelet, mode=params.mode)[: len(a)]
    return out[:, 0] if squeeze else out


def wavelet_detrend(x: np.ndarray, params: WaveletParams = WaveletParams()) -> np.ndarray:
    """``x`` minus its wavelet trend (Bai: position rebuilt from D1..D7)."""
    return np.asarray(x, dtype=np.float64) - wavelet_trend(x, params)
