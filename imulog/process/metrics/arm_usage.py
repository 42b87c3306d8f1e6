"""Impaired-arm usage from a 3-axis accelerometer (Doshi 2011, thesis chapter 4.2).

A sample counts as *arm use* on an axis when its change from the previous sample exceeds the sensor's noise
level; a sample counts as overall use when any axis does. Usage is the number of such samples divided by the
number of samples in the recording, in percent (Appendix A.1 divides by the sample count ``N``, not ``N - 1``)::

    use_j[i]   = |a_j[i] - a_j[i-1]| > noise_level          (i = 1 .. N-1, j = x, y, z; use_j[0] = False)
    usage_j    = 100 * sum_i use_j[i] / N                    [%]
    usage      = 100 * sum_i (use_x[i] or use_y[i] or use_z[i]) / N   [%]

Reference: R. Doshi, "Wearable inertial sensor based tracking of the impaired arm of stroke survivors",
M.S. thesis, Colorado State University, 2011, sections 4.2.2-4.2.3 and Appendix A.1 (threshold 0.022 g for the
WiTilt v2.5 / MMA7260Q board; Table 4.1). The noise level is a property of the sensor: estimate it from a static
recording with :func:`estimate_noise_level` (Doshi: sensor still for about 30 min, sampled at >= 10 Hz; he
considered the standard deviation and the peak amplitude of the noise and preferred the peak amplitude).

Any sampling rate: the threshold is on the change between samples 0.1 s apart (Doshi's board sampled at 10 Hz),
so a change per sample means ten times less at 100 Hz and the same movement counts as ~10x less use (a
simulated 115 Hz drinking trial: 1.3 % instead of 19 %). With the time stamps given, :func:`arm_usage` first brings the signal
to the threshold's rate (``ArmUsageParams.reference_rate_hz``, 10 Hz): the mean of each 0.1 s window of the
recording (a low-pass and decimation in one), then the rule above on consecutive windows; each sample takes its
window's result. A window counts when at least half its samples are valid (NaN = gap); percentages are of the
valid windows, i.e. of the recorded time. Recordings at or below the reference rate are used as they are.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from imulog.numeric import finite_rows, median_int

STANDARD_GRAVITY = 9.80665  # m/s^2 per g

NoiseStatistic = Literal["peak", "std", "diff_peak", "diff_std"]


@dataclass(frozen=True)
class ArmUsageParams:
    """Parameters of the arm-usage metric.

    noise_level_g: threshold on the change of each axis between consecutive samples at ``reference_rate_hz``, in g.
        Published default 0.022 g (Doshi 2011, section 4.2.3, WiTilt v2.5 in the +-2 g range at 10 Hz).
        Re-estimate it for another sensor with :func:`estimate_noise_level`.
    reference_rate_hz: the rate at which ``noise_level_g`` applies (Doshi: 10 Hz); faster recordings are averaged
        to it before thresholding (module docstring).
    """

    noise_level_g: float = 0.022
    reference_rate_hz: float = 10.0

    def __post_init__(self) -> None:
        if not np.isfinite(self.noise_level_g) or self.noise_level_g < 0:
            raise ValueError(f"noise_level_g must be a finite value >= 0, got {self.noise_level_g}")
        if not np.isfinite(self.reference_rate_hz) or self.reference_rate_hz <= 0:
            raise ValueError(f"reference_rate_hz must be positive, got {self.reference_rate_hz}")


@dataclass(frozen=True)
class ArmUsage:
    """Result of :func:`arm_usage`.

    per_axis_percent: (3,) usage of x, y, z in % of the valid samples (windows at the reference rate).
    overall_percent: usage of any axis, in the same %.
    active: (N, 3) bool per input sample, True where the axis changed by more than the noise level since the
        previous sample (or, resampled, where the sample's window changed since the previous window).
    rate_hz: the rate the threshold was applied at (the reference rate, or the input's when not resampled).
    """

    per_axis_percent: np.ndarray
    overall_percent: float
    active: np.ndarray
    rate_hz: float | None = None

    @property
    def active_any(self) -> np.ndarray:
        """(N,) bool: sample counted as arm use on at least one axis."""
        return self.active.any(axis=1)


def _as_acc(acc_g: np.ndarray) -> np.ndarray:
    a = np.asarray(acc_g, dtype=np.float64)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] < 2:
        raise ValueError(f"acceleration must be (N, C) with N >= 2 samples, got shape {np.shape(acc_g)}")
    return a


def acc_to_g(acc_m_s2: np.ndarray) -> np.ndarray:
    """Convert m/s^2 (the archive's unit) to g (the unit of Doshi's thresholds)."""
    return np.asarray(acc_m_s2, dtype=np.float64) / STANDARD_GRAVITY


def adc_to_g(counts: np.ndarray, *, zero_count: float = 512.0, counts_per_g: float = 256.0) -> np.ndarray:
    """Raw 10-bit ADC counts of the WiTilt board to g: ``(counts - zero_count) / counts_per_g``.

    Defaults: Doshi 2011 section 4.2.1 (10-bit ADC, 0-1023 counts, centred on 512, 256 counts per g at +-2 g).
    """
    return (np.asarray(counts, dtype=np.float64) - zero_count) / counts_per_g


def to_reference_rate(
    acc_g: np.ndarray, t_ns: np.ndarray, rate_hz: float = 10.0, origin_ns: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Means of consecutive ``1 / rate_hz`` windows (by time stamp) and each sample's window index.

    Windows start at ``origin_ns`` (default: the first sample; a part of a longer recording passes the window
    edge at or before its first sample so that its windows are the recording's). Returns ``(windows (M, C),
    index (N,))``; a window with fewer than half its expected samples valid is NaN (a gap), and windows without
    any sample (a time gap) are NaN rows too.
    """
    a = _as_acc(acc_g)
    t = np.asarray(t_ns, dtype=np.int64)
    if len(t) != len(a):
        raise ValueError(f"t_ns has {len(t)} samples, acceleration {len(a)}")
    width_ns = 1e9 / rate_hz
    origin = int(t[0]) if origin_ns is None else int(origin_ns)
    if origin > t[0]:
        raise ValueError("origin_ns must be at or before the first sample")
    index = ((t - origin) // width_ns).astype(np.int64)
    m = int(index[-1]) + 1
    finite = finite_rows(a)
    counts = np.bincount(index, minlength=m).astype(np.float64)
    if finite.all():  # no gap: the same sums without copying every sample out (most windows of a recording)
        valid, kept, a_kept = counts, index, a
    else:
        kept, a_kept = index[finite], a[finite]
        valid = np.bincount(kept, minlength=m).astype(np.float64)
    sums = np.column_stack([np.bincount(kept, a_kept[:, j], minlength=m) for j in range(a.shape[1])])
    expected = np.median(counts[counts > 0]) if np.any(counts > 0) else 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        windows = sums / valid[:, None]
    windows[valid < 0.5 * expected] = np.nan
    return windows, index


def arm_usage(
    acc_g: np.ndarray,
    params: ArmUsageParams | None = None,
    *,
    t_ns: np.ndarray | None = None,
    origin_ns: int | None = None,
) -> ArmUsage:
    """Per-axis and overall arm usage (%) of an (N, 3) acceleration in g; see the module docstring.

    With ``t_ns`` (int64 ns) the signal is first averaged to ``params.reference_rate_hz`` when it is faster, so the
    result does not depend on the sampling rate; without, the samples are taken as being at the reference rate.
    ``origin_ns``: where the averaging windows start (see :func:`to_reference_rate`).
    NaN samples are gaps: never use, and not counted in the percentages.
    """
    p = params or ArmUsageParams()
    a = _as_acc(acc_g)
    index = None
    rate = None
    if t_ns is not None:
        dt = np.diff(np.asarray(t_ns, dtype=np.int64))
        median = median_int(dt) if len(dt) else 0.0
        if median <= 0:
            raise ValueError("t_ns must increase")
        rate = 1e9 / median  # nominal rate: insensitive to dropped samples
        if rate > 1.5 * p.reference_rate_hz:
            a, index = to_reference_rate(a, t_ns, p.reference_rate_hz, origin_ns)
            rate = p.reference_rate_hz
    active = np.zeros(a.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        active[1:] = np.abs(np.diff(a, axis=0)) > p.noise_level_g  # NaN compares False: a gap is not use
    n = max(1, int(finite_rows(a).sum()))
    return ArmUsage(
        per_axis_percent=100.0 * active.sum(axis=0) / n,
        overall_percent=float(100.0 * active.any(axis=1).sum() / n),
        active=active if index is None else active[index],
        rate_hz=rate,
    )


@dataclass(frozen=True)
class NoiseLevel:
    """Noise statistics of a static recording, per axis, in g.

    peak: max |a - mean(a)| (Doshi's "peak amplitude" of the noise w).
    std: standard deviation of a.
    diff_peak: max |a[i] - a[i-1]| (the largest sample-to-sample change seen at rest: with it as threshold, the
        static recording itself shows 0 % usage).
    diff_std: standard deviation of a[i] - a[i-1] (sqrt(2) * std for white noise).
    """

    peak: np.ndarray
    std: np.ndarray
    diff_peak: np.ndarray
    diff_std: np.ndarray
    n_samples: int

    def threshold_g(self, statistic: NoiseStatistic = "peak") -> float:
        """One threshold for all axes: the largest per-axis value of ``statistic``, in g."""
        values = {"peak": self.peak, "std": self.std, "diff_peak": self.diff_peak, "diff_std": self.diff_std}
        if statistic not in values:
            raise ValueError(f"unknown noise statistic {statistic!r}; use one of {', '.join(values)}")
        return float(np.max(values[statistic]))


def estimate_noise_level(static_acc_g: np.ndarray) -> NoiseLevel:
    """Noise statistics (g) of a recording with the sensor at rest (Doshi 2011 section 4.2.2).

    The static segment's mean (gravity and offset ``o`` of eq. 4.1) is removed per axis; NaN samples are
    ignored. Use ``.threshold_g("peak")`` as :class:`ArmUsageParams` ``noise_level_g`` (Doshi's choice) or
    ``"diff_peak"`` for a threshold that the static recording never exceeds.
    """
    a = _as_acc(static_acc_g)
    finite = np.isfinite(a).all(axis=1)
    a = a[finite]
    if a.shape[0] < 2:
        raise ValueError("static recording has fewer than 2 finite samples")
    centred = a - a.mean(axis=0)
    d = np.diff(a, axis=0)
    return NoiseLevel(
        peak=np.abs(centred).max(axis=0),
        std=a.std(axis=0),
        diff_peak=np.abs(d).max(axis=0),
        diff_std=d.std(axis=0),
        n_samples=int(a.shape[0]),
    )
