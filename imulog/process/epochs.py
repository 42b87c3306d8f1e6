"""Epoch summaries of wrist acceleration as home-monitoring studies report them (pure numerics, units in g).

* **ENMO** (Euclidean norm minus one, negative values set to 0) and **MAD** (mean amplitude deviation of the norm
  about its epoch mean), mean over each epoch (van Hees et al. 2013; Vähä-Ypyä et al. 2015);
* **auto-calibration** to local gravity from still 10-s epochs (van Hees et al. 2014, as GGIR and actipy do): an
  offset and a scale per axis fitted so that still epochs lie on the unit sphere;
* **non-wear** by the van Hees 2013 rule: a 60-min window is non-wear when at least 2 of the 3 axes have a standard
  deviation below 13 mg or at least 2 have a value range below 50 mg; windows move in 15-min blocks;
* **ActiGraph counts** by the published algorithm (Brønd et al. 2017; exact coefficients in Neishabouri et al.
  2022, Sci Rep 12:11958, Table 1): resample to 30 Hz as ActiLife does (:mod:`imulog.process.counts_resample`),
  band-pass IIR, scale, rectify, threshold, 10 Hz, epoch sum.

Every function here works on one window of samples plus small state, so the step
(:mod:`imulog.steps.epochs`) applies them window by window in bounded memory.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

#: Neishabouri et al. 2022, Table 1 (the band-pass filter ActiLife applies at 30 Hz); b = input, a = output
COUNTS_B = np.array(
    [-0.009341062898525, -0.025470289659360, -0.004235264826105, 0.044152415456420, 0.036493718347760]
    + [-0.011893961934740, -0.022917390623150, -0.006788163862310, 0.0]
)
COUNTS_A = np.array(
    [1.0, -3.63367395910957, 5.03689812757486, -3.09612247819666, 0.50620507633883, 0.32421701566682]
    + [-0.15685485875559, 0.0194913020589, 0.0]
)
#: ADC scaling of the ActiGraph (3 V over 4096 levels against 2.6 V per 256, times 237.5): 17.127404
COUNTS_SCALE = (3.0 / 4096.0) / (2.6 / 256.0) * 237.5
COUNTS_RATE_HZ = 30
COUNTS_DEADBAND = 4.0  # values under this (after scaling) are 0
COUNTS_CEILING = 128.0  # and over this are clipped


def norm_g(acc_g: np.ndarray) -> np.ndarray:
    """Euclidean norm of (N, 3) acceleration, g."""
    a = np.asarray(acc_g, dtype=np.float64)
    return np.sqrt((a * a).sum(axis=1))


def epoch_enmo_mad(acc_g: np.ndarray, samples_per_epoch: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ENMO g, MAD g, fraction of finite samples) per whole epoch of ``samples_per_epoch`` samples.

    ``acc_g`` (N, 3) starts at an epoch boundary; a trailing partial epoch is summarised over its samples.
    Missing samples (NaN) are left out; an epoch without any is NaN.
    """
    r = norm_g(acc_g)
    n = len(r)
    k = -(-n // samples_per_epoch)
    pad = np.full(k * samples_per_epoch, np.nan)
    pad[:n] = r
    e = pad.reshape(k, samples_per_epoch)
    ok = np.isfinite(e)
    count = ok.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        enmo = np.where(ok, np.maximum(e - 1.0, 0.0), 0.0).sum(axis=1) / count
        mean = np.where(ok, e, 0.0).sum(axis=1) / count
        mad = np.where(ok, np.abs(e - mean[:, None]), 0.0).sum(axis=1) / count
    expected = np.full(k, samples_per_epoch, dtype=np.float64)
    expected[-1] = n - (k - 1) * samples_per_epoch
    return enmo, mad, count / expected


# ----------------------------------------------------------------------------------------- block statistics
@dataclass
class AxisStats:
    """Per-axis count, mean, sum of squared deviations, min and max of consecutive blocks (arrays (B, 3))."""

    n: np.ndarray
    mean: np.ndarray
    m2: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @classmethod
    def of_blocks(cls, acc_g: np.ndarray, samples_per_block: int) -> AxisStats:
        """Statistics of ``acc_g`` (N, 3) cut into blocks of ``samples_per_block`` (the last may be partial)."""
        n = len(acc_g)
        k = -(-n // samples_per_block)
        pad = np.full((k * samples_per_block, 3), np.nan)
        pad[:n] = acc_g
        b = pad.reshape(k, samples_per_block, 3)
        ok = np.isfinite(b)
        cnt = ok.sum(axis=1).astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(ok, b, 0.0).sum(axis=1) / cnt
            m2 = np.where(ok, (b - mean[:, None, :]) ** 2, 0.0).sum(axis=1)
        lo = np.where(ok, b, np.inf).min(axis=1)
        hi = np.where(ok, b, -np.inf).max(axis=1)
        return cls(cnt, mean, m2, lo, hi)

    @classmethod
    def concat(cls, parts: list[AxisStats]) -> AxisStats:
        if not parts:
            z = np.zeros((0, 3))
            return cls(z, z, z, z, z)
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("n", "mean", "m2", "lo", "hi")))

    def windows(self, blocks: int) -> tuple[np.ndarray, np.ndarray]:
        """(SD g, range g) per axis of every run of ``blocks`` consecutive blocks, (B - blocks + 1, 3); combined
        exactly from the block statistics (Chan et al.'s pairwise update)."""
        k = len(self.n) - blocks + 1
        if k <= 0:
            return np.zeros((0, 3)), np.zeros((0, 3))
        n = np.zeros((k, 3))
        mean = np.zeros((k, 3))
        m2 = np.zeros((k, 3))
        lo = np.full((k, 3), np.inf)
        hi = np.full((k, 3), -np.inf)
        for j in range(blocks):
            nb, mb, m2b = self.n[j : j + k], self.mean[j : j + k], self.m2[j : j + k]
            mb = np.where(nb > 0, mb, 0.0)
            m2b = np.where(nb > 0, m2b, 0.0)
            tot = n + nb
            with np.errstate(invalid="ignore", divide="ignore"):
                delta = mb - mean
                mean = np.where(tot > 0, mean + delta * nb / tot, 0.0)
                m2 = m2 + m2b + np.where(tot > 0, delta * delta * n * nb / tot, 0.0)
            n = tot
            lo = np.minimum(lo, self.lo[j : j + k])
            hi = np.maximum(hi, self.hi[j : j + k])
        with np.errstate(invalid="ignore", divide="ignore"):
            sd = np.where(n > 1, np.sqrt(m2 / np.maximum(n - 1, 1)), np.nan)
        return sd, hi - lo


def nonwear_blocks(
    stats: AxisStats, *, window_blocks: int = 4, sd_g: float = 0.013, range_g: float = 0.050, axes: int = 2
) -> np.ndarray:
    """Non-wear flag per block (van Hees et al. 2013): every block inside a window of ``window_blocks`` blocks in
    which at least ``axes`` axes have SD < ``sd_g`` or at least ``axes`` axes have range < ``range_g``.

    A recording shorter than one window is one window. Blocks without samples are not flagged (they are gaps).
    """
    nb = len(stats.n)
    w = min(window_blocks, nb)
    flags = np.zeros(nb, dtype=bool)
    if nb == 0:
        return flags
    sd, rng = stats.windows(w)
    still = ((sd < sd_g).sum(axis=1) >= axes) | ((rng < range_g).sum(axis=1) >= axes)
    for j in range(w):
        flags[j : j + len(still)] |= still
    return flags & (stats.n.sum(axis=1) > 0)


def choi_nonwear(
    counts_per_min: np.ndarray, *, window_min: int = 90, allowance_min: int = 2, stream_min: int = 30
) -> np.ndarray:
    """Non-wear flag per 60-s epoch from its counts (Choi et al. 2011, MSSE 43(2):357-364).

    Non-wear is a run of at least ``window_min`` minutes of zero counts, which may hold interruptions of at most
    ``allowance_min`` minutes of non-zero counts when the ``stream_min`` minutes on each side of the interruption
    are zero. ``counts_per_min`` is (M,) (the vector magnitude or one axis); a missing minute (NaN) counts as zero.
    scikit-digital-health's ``CountWearDetection`` applies the same rule with runs of more than (not at least)
    90 minutes.
    """
    from imulog.process.gaps import runs_of

    c = np.nan_to_num(np.asarray(counts_per_min, dtype=np.float64), nan=0.0)
    active = c > 0
    candidate = ~active
    bursts = runs_of(active)
    for k, (a, b) in enumerate(bursts):  # an allowed interruption: short, with zero runs of stream_min around it
        zeros_before = a - (bursts[k - 1][1] if k else 0)
        zeros_after = (bursts[k + 1][0] if k + 1 < len(bursts) else len(c)) - b
        if b - a <= allowance_min and zeros_before >= stream_min and zeros_after >= stream_min:
            candidate[a:b] = True
    flags = np.zeros(len(c), dtype=bool)
    for a, b in runs_of(candidate):
        if b - a >= window_min:
            flags[a:b] = True
    return flags


# ------------------------------------------------------------------------------------------- calibration
@dataclass(frozen=True)
class Calibration:
    """Per-axis ``offset`` (g) and ``scale``: calibrated = (raw + offset) * scale; with the fit's quality."""

    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    applied: bool = False
    reason: str = ""
    still_epochs: int = 0
    error_before_mg: float | None = None
    error_after_mg: float | None = None

    def apply(self, acc_g: np.ndarray) -> np.ndarray:
        if not self.applied:
            return np.asarray(acc_g, dtype=np.float64)
        return (np.asarray(acc_g, dtype=np.float64) + np.asarray(self.offset)) * np.asarray(self.scale)

    def to_dict(self) -> dict:
        return {
            "offset_g": [round(v, 6) for v in self.offset],
            "scale": [round(v, 6) for v in self.scale],
            "applied": self.applied,
            "reason": self.reason,
            "still_epochs": self.still_epochs,
            "error_before_mg": None if self.error_before_mg is None else round(self.error_before_mg, 3),
            "error_after_mg": None if self.error_after_mg is None else round(self.error_after_mg, 3),
        }


def still_epoch_means(acc_g: np.ndarray, samples_per_epoch: int, sd_g: float = 0.013) -> np.ndarray:
    """Means (M, 3) of the epochs whose three axes all have SD < ``sd_g`` (van Hees 2014: 10-s epochs, 13 mg)."""
    s = AxisStats.of_blocks(acc_g, samples_per_epoch)
    with np.errstate(invalid="ignore", divide="ignore"):
        sd = np.sqrt(s.m2 / np.maximum(s.n - 1, 1))
    full = (s.n == samples_per_epoch).all(axis=1)
    keep = full & (sd < sd_g).all(axis=1) & (np.abs(s.mean) < 2.0).all(axis=1)
    return s.mean[keep]


def fit_calibration(
    means: np.ndarray, *, min_epochs: int = 72, spread_g: float = 0.3, iterations: int = 1000, tol: float = 1e-10
) -> Calibration:
    """Offset and scale per axis that put still-epoch means on the unit sphere (van Hees et al. 2014).

    Needs ``min_epochs`` still epochs with each axis reaching beyond +-``spread_g`` (otherwise the fit is not
    determined and nothing is applied, with the reason). Iterates: project each point on the sphere, regress each
    axis's target on its value (weighted, outliers down-weighted), until the offset and scale settle; the fit is
    kept only if it lowers the mean distance to the sphere.
    """
    m = np.asarray(means, dtype=np.float64).reshape(-1, 3)
    before = float(np.mean(np.abs(norm_g(m) - 1.0))) * 1000 if len(m) else None
    if len(m) < min_epochs:
        return Calibration(
            reason=f"{len(m)} still epochs, need {min_epochs}", still_epochs=len(m), error_before_mg=before
        )
    if not ((m.min(axis=0) < -spread_g) & (m.max(axis=0) > spread_g)).all():
        return Calibration(
            reason=f"still epochs do not reach +-{spread_g} g on every axis",
            still_epochs=len(m),
            error_before_mg=before,
        )
    offset, scale = np.zeros(3), np.ones(3)
    weights = np.ones(len(m))
    for _ in range(iterations):
        cal = (m + offset) * scale
        target = cal / norm_g(cal)[:, None]
        new_off, new_scale = np.zeros(3), np.ones(3)
        for j in range(3):  # target_j = (m_j + off_j) * scale_j = scale_j * m_j + scale_j * off_j
            x = np.column_stack([np.ones(len(m)), m[:, j]])
            sw = np.sqrt(weights)
            coef, *_ = np.linalg.lstsq(x * sw[:, None], target[:, j] * sw, rcond=None)
            new_scale[j] = coef[1]
            new_off[j] = coef[0] / coef[1]
        residual = np.abs(norm_g((m + new_off) * new_scale) - 1.0)
        weights = 1.0 / np.maximum(residual, 0.01)
        weights /= weights.mean()
        change = np.abs(new_off - offset).sum() + np.abs(new_scale - scale).sum()
        offset, scale = new_off, new_scale
        if change < tol:
            break
    after = float(np.mean(np.abs(norm_g((m + offset) * scale) - 1.0))) * 1000
    if before is not None and after >= before:
        return Calibration(
            reason="the fit did not lower the error", still_epochs=len(m), error_before_mg=before, error_after_mg=after
        )
    return Calibration(tuple(map(float, offset)), tuple(map(float, scale)), True, "fitted", len(m), before, after)


# ------------------------------------------------------------------------------------------------ counts
def counts_factors(rate_hz: float) -> tuple[int, int]:
    """(up, down) integer factors taking ``rate_hz`` to 30 Hz; ValueError for a rate that is not rational."""
    f = Fraction(COUNTS_RATE_HZ) / Fraction(rate_hz).limit_denominator(1000)
    if abs(float(f) * rate_hz - COUNTS_RATE_HZ) > 1e-9 or f.numerator > 1000:
        raise ValueError(f"ActiGraph counts: cannot resample {rate_hz} Hz to 30 Hz by integer factors")
    return f.numerator, f.denominator


def to_30hz(acc_g: np.ndarray, rate_hz: float) -> np.ndarray:
    """Acceleration at 30 Hz, (M, 3) g, as ActiLife computes it where it accepts the rate: every k-th sample at
    30 k Hz (30, 60, 90 Hz), ActiLife's own resampler at 40, 50, 70, 80 and 100 Hz
    (:mod:`imulog.process.counts_resample`); at other rates (no reference exists) polyphase resampling
    (anti-aliased). See docs/epochs.md."""
    from scipy.signal import resample_poly

    from imulog.process.counts_resample import actilife_to_30hz, is_actilife_resampled

    up, down = counts_factors(rate_hz)
    a = np.asarray(acc_g, dtype=np.float64)
    if up == 1:
        return a[::down]
    if is_actilife_resampled(rate_hz):
        return actilife_to_30hz(a, up, down)
    return resample_poly(a, up, down, axis=0, padtype="line")  # no step at the edges


class CountsFilter:
    """The counts band-pass filter over consecutive 30 Hz pieces: state carried, so pieces give what the whole
    signal gives. Its first sample sets the initial state (a step from rest is not counted)."""

    def __init__(self) -> None:
        self.zi: np.ndarray | None = None

    def __call__(self, acc30_g: np.ndarray) -> np.ndarray:
        """Rectified, thresholded, floored values at 30 Hz (ActiGraph units), (M, 3)."""
        from scipy.signal import lfilter, lfilter_zi

        x = np.round(np.asarray(acc30_g, dtype=np.float64), 3)  # ActiLife's input resolution (Neishabouri 2022)
        if not len(x):
            return np.zeros((0, 3))
        if self.zi is None:
            self.zi = lfilter_zi(COUNTS_B, COUNTS_A)[:, None] * x[0][None, :]
        y, self.zi = lfilter(COUNTS_B, COUNTS_A, x, axis=0, zi=self.zi)
        y = np.abs(y * COUNTS_SCALE)
        y[y < COUNTS_DEADBAND] = 0.0
        return np.floor(np.minimum(y, COUNTS_CEILING))


def counts_per_epoch(trimmed30: np.ndarray, epoch_s: float) -> np.ndarray:
    """Counts per epoch per axis from :class:`CountsFilter` output starting at an epoch boundary: 10 Hz as the mean
    of each 3 samples floored to an integer (the device's 10 Hz values are integers), summed per epoch (a partial
    10 Hz sample at the end is dropped), (E, 3)."""
    n10 = len(trimmed30) // 3
    ten = np.floor(trimmed30[: 3 * n10].reshape(n10, 3, -1).mean(axis=1))
    per = int(round(epoch_s * 10))
    k = -(-n10 // per)
    pad = np.zeros((k * per, ten.shape[1]))
    pad[:n10] = ten
    return pad.reshape(k, per, -1).sum(axis=1)
