"""Movement smoothness from a velocity profile: number of speed peaks, normalised jerk, LDLJ, SPARC.

All functions take one movement's velocity ``v`` (N, D) in m/s (or (N,) speed) sampled at ``rate_hz``;
speed ``|v|``, acceleration and jerk are obtained by central differences (``numpy.gradient``).

* **Number of velocity peaks** (Rohrer et al. 2002): local maxima of the speed profile. A smooth point-to-point
  reach has 1; stroke survivors' reaches start as many sub-movements and merge as they recover. imulog counts
  maxima whose height exceeds ``min_height_fraction`` of the peak speed and whose prominence exceeds
  ``min_prominence_fraction`` of the peak speed (both imulog choices, 0.1 and 0.05; Rohrer et al. counted raw
  maxima of low-pass filtered speed).
* **Normalised jerk** (Teulings et al. 1997; used for stroke by Rohrer et al. 2002)::

      NJ = sqrt( 0.5 * integral |d^3x/dt^3|^2 dt * T^5 / L^2 )     (dimensionless; T duration s, L path length m)

  1-D minimum-jerk reach: NJ = sqrt(360) = 18.97 (independent of amplitude and duration).
* **Log dimensionless jerk** (Balasubramanian et al. 2012; 2015 velocity form)::

      LDLJ = -ln( T^3 / v_peak^2 * integral |d^2v/dt^2|^2 dt )      (higher = smoother)

  1-D minimum-jerk reach: -ln(720 / 1.875^2) = -5.32.
* **SPARC**, spectral arc length (Balasubramanian et al. 2012, 2015): arc length of the normalised Fourier
  magnitude spectrum of the speed profile up to the adaptive cut-off frequency ``f_c`` where the spectrum last
  exceeds ``amplitude_threshold``, bounded by ``max_cutoff_hz``; zero-padded to ``2^(ceil(log2 N) + padlevel)``
  points. Published defaults: ``padlevel = 4``, ``max_cutoff_hz = 10 Hz``, ``amplitude_threshold = 0.05``.
  Dimensionless, negative; closer to 0 is smoother (1 s minimum-jerk reach at 100-1000 Hz: -1.41).

References: Rohrer B. et al., "Movement smoothness changes during stroke recovery", J Neurosci 22(18), 2002.
Teulings H.-L. et al., "Parkinsonism reduces coordination of fingers, wrist, and arm in fine motor control",
Exp Neurol 146, 1997. Hogan N., Sternad D., "Sensitivity of smoothness measures to movement duration, amplitude,
and arrests", J Motor Behavior 41(6), 2009. Balasubramanian S. et al., "A robust and sensitive metric for
quantifying movement smoothness", IEEE TBME 59(8), 2012; "On the analysis of movement smoothness", J
NeuroEngineering Rehabil 12:112, 2015.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class VelocityPeakParams:
    """Peak counting: minimum height and prominence as fractions of the movement's peak speed (imulog choice)."""

    min_height_fraction: float = 0.1
    min_prominence_fraction: float = 0.05


@dataclass(frozen=True)
class SparcParams:
    """SPARC parameters; published defaults of Balasubramanian et al. 2015."""

    padlevel: int = 4
    max_cutoff_hz: float = 10.0
    amplitude_threshold: float = 0.05


def speed(velocity: np.ndarray) -> np.ndarray:
    """|v| of (N, D) velocity, or the absolute value of an (N,) signal; m/s."""
    v = np.asarray(velocity, dtype=np.float64)
    if v.ndim == 1:
        return np.abs(v)
    if v.ndim != 2:
        raise ValueError(f"velocity must be (N,) or (N, D), got shape {v.shape}")
    return np.sqrt((v * v).sum(axis=1))


def _check(v: np.ndarray, rate_hz: float, min_len: int = 3) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    if v.ndim == 1:
        v = v[:, None]
    if v.shape[0] < min_len:
        raise ValueError(f"need at least {min_len} samples, got {v.shape[0]}")
    if not np.isfinite(v).all():
        raise ValueError("velocity contains NaN or inf; interpolate gaps first")
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
    return v


def velocity_peaks(velocity: np.ndarray, params: VelocityPeakParams | None = None) -> int:
    """Number of local maxima of the speed profile (Rohrer et al. 2002), see the module docstring."""
    p = params or VelocityPeakParams()
    s = speed(velocity)
    if len(s) < 3 or not np.isfinite(s).all():
        raise ValueError("need at least 3 finite samples")
    top = s.max()
    if top <= 0:
        return 0
    # plateau-aware local maxima: rising into i, then falling after a run of equal values
    d = np.diff(s)
    nz = np.flatnonzero(d != 0)
    if len(nz) < 2:
        return 0
    sgn = np.sign(d[nz])
    turn = np.flatnonzero((sgn[:-1] > 0) & (sgn[1:] < 0))
    peaks = nz[turn] + 1  # first sample of the (possibly flat) top
    count = 0
    for i in peaks:
        h = s[i]
        if h < p.min_height_fraction * top:
            continue
        # prominence: height above the higher of the two minima reached before a higher sample on each side
        left = s[:i][::-1]
        hi = np.flatnonzero(left > h)
        lmin = left[: hi[0]].min() if len(hi) else left.min()
        right = s[i + 1 :]
        hi = np.flatnonzero(right > h)
        rmin = right[: hi[0]].min() if len(hi) else right.min()
        if h - max(lmin, rmin) >= p.min_prominence_fraction * top:
            count += 1
    return count


def normalized_jerk(position_or_velocity: np.ndarray, rate_hz: float, *, is_velocity: bool = True) -> float:
    """Normalised jerk ``sqrt(0.5 * int |jerk|^2 dt * T^5 / L^2)`` (Teulings et al. 1997), dimensionless."""
    x = _check(position_or_velocity, rate_hz, 5)
    dt = 1.0 / rate_hz
    v = x if is_velocity else np.gradient(x, dt, axis=0, edge_order=2)
    jerk = np.gradient(np.gradient(v, dt, axis=0, edge_order=2), dt, axis=0, edge_order=2)
    duration = (len(v) - 1) * dt
    path = float(np.trapezoid(speed(v), dx=dt))
    if path <= 0:
        raise ValueError("movement has zero path length")
    integral = float(np.trapezoid((jerk * jerk).sum(axis=1), dx=dt))
    return float(np.sqrt(0.5 * integral * duration**5 / path**2))


def log_dimensionless_jerk(velocity: np.ndarray, rate_hz: float) -> float:
    """LDLJ ``-ln(T^3 / v_peak^2 * int |d^2v/dt^2|^2 dt)`` (Balasubramanian et al. 2015), dimensionless."""
    v = _check(velocity, rate_hz, 5)
    dt = 1.0 / rate_hz
    jerk = np.gradient(np.gradient(v, dt, axis=0, edge_order=2), dt, axis=0, edge_order=2)
    duration = (len(v) - 1) * dt
    vpeak = speed(v).max()
    if vpeak <= 0:
        raise ValueError("movement has zero speed")
    integral = float(np.trapezoid((jerk * jerk).sum(axis=1), dx=dt))
    return float(-np.log(duration**3 / vpeak**2 * integral))


def sparc(velocity: np.ndarray, rate_hz: float, params: SparcParams | None = None) -> float:
    """Spectral arc length of the speed profile (Balasubramanian et al. 2015); dimensionless, <= 0."""
    p = params or SparcParams()
    s = speed(_check(velocity, rate_hz, 3))
    n_fft = int(2 ** (np.ceil(np.log2(len(s))) + p.padlevel))
    freq = np.arange(n_fft) * rate_hz / n_fft
    mag = np.abs(np.fft.fft(s, n_fft))
    if mag.max() <= 0:
        raise ValueError("movement has zero speed")
    mag = mag / mag.max()
    keep = freq <= p.max_cutoff_hz
    f_sel, m_sel = freq[keep], mag[keep]
    above = np.flatnonzero(m_sel >= p.amplitude_threshold)
    f_sel, m_sel = f_sel[above[0] : above[-1] + 1], m_sel[above[0] : above[-1] + 1]
    if len(f_sel) < 2:
        return 0.0
    df = np.diff(f_sel) / (f_sel[-1] - f_sel[0])
    return float(-np.sum(np.sqrt(df * df + np.diff(m_sel) ** 2)))


@dataclass(frozen=True)
class Smoothness:
    """All smoothness indicators of one movement (see the module docstring)."""

    duration_s: float
    path_length_m: float
    peak_speed_m_s: float
    velocity_peaks: int
    normalized_jerk: float
    ldlj: float
    sparc: float


def smoothness(
    velocity: np.ndarray,
    rate_hz: float,
    *,
    peak_params: VelocityPeakParams | None = None,
    sparc_params: SparcParams | None = None,
) -> Smoothness:
    """Every indicator for one movement's (N, D) velocity in m/s at ``rate_hz``."""
    v = _check(velocity, rate_hz, 5)
    dt = 1.0 / rate_hz
    s = speed(v)
    return Smoothness(
        duration_s=(len(v) - 1) * dt,
        path_length_m=float(np.trapezoid(s, dx=dt)),
        peak_speed_m_s=float(s.max()),
        velocity_peaks=velocity_peaks(v, peak_params),
        normalized_jerk=normalized_jerk(v, rate_hz),
        ldlj=log_dimensionless_jerk(v, rate_hz),
        sparc=sparc(v, rate_hz, sparc_params),
    )
