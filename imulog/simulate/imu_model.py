"""LSM9DS1-like IMU error model (the BlueBuddy sensor of the R2G thesis).

True sensor-frame signals (specific force m/s^2, body angular velocity rad/s, magnetic field uT)
go through: scale + axis misalignment, constant bias + bias random walk, white noise, full-scale
clipping and ADC quantisation. The output is in the file units a BlueBuddy-style export uses
(acc g, gyr dps, mag uT) as exact decimal integers, so the text file reproduces them exactly.
Parameter sources are in docs/simulate.md.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

G0 = 9.80665  # m/s^2 per g: the datasheet's (and the converters') unit g
EARTH_G = 9.81  # m/s^2: the gravity the simulated world has (brief; Turin ~9.806)


@dataclass(frozen=True)
class ImuParams:
    acc_range_g: float = 16.0  # LSM9DS1 FS_XL = ±16 g
    gyr_range_dps: float = 2000.0  # LSM9DS1 FS_G = ±2000 dps
    mag_range_gauss: float = 4.0  # LSM9DS1 FS_M = ±4 gauss
    acc_lsb_ug: int = 732  # datasheet sensitivity at ±16 g: 0.732 mg/LSB
    gyr_lsb_mdps: int = 70  # datasheet sensitivity at ±2000 dps: 70 mdps/LSB
    mag_lsb_nT: int = 14  # datasheet sensitivity at ±4 gauss: 0.14 mgauss/LSB = 14 nT
    acc_noise_mps2: float = 0.02  # white noise per sample (≈2 mg rms)
    gyr_noise_dps: float = 0.1  # white noise per sample (≈0.015 dps/sqrt(Hz) over ~50 Hz)
    mag_noise_uT: float = 0.3  # white noise per sample
    acc_bias_sd_mps2: float = 0.05  # constant bias per axis (residual after factory trim)
    gyr_bias_sd_dps: float = 0.5  # constant bias per axis
    acc_bias_rw_mps2_per_sqrt_s: float = 2e-4  # bias random walk
    gyr_bias_rw_dps_per_sqrt_s: float = 5e-3
    acc_bias_drift_mps2: float = 0.0  # warm-up drift of the bias per axis (sd of its final change), 0 = none
    gyr_bias_drift_dps: float = 0.0  # ... of the gyroscope bias
    bias_drift_tau_s: float = 300.0  # time constant of the warm-up drift (exponential approach)
    scale_sd: float = 0.005  # scale factor error per axis (0.5 %)
    misalignment_sd_deg: float = 0.3  # non-orthogonality of the axes
    mag_hard_iron_sd_uT: float = 8.0  # per axis
    mag_soft_iron_sd: float = 0.03  # symmetric perturbation of the identity
    drop_probability: float = 0.002  # a dropped burst starts at a sample with this probability
    drop_max_burst: int = 3  # 1..N consecutive samples lost
    quantize: bool = True

    @classmethod
    def ideal(cls) -> ImuParams:
        """No error of any kind (noise-free mode); values written with 9 decimals."""
        zero = {f.name: 0.0 for f in fields(cls) if f.name.endswith(("_noise_mps2", "_noise_dps", "_noise_uT"))}
        return replace(
            cls(),
            **zero,
            acc_bias_sd_mps2=0.0,
            gyr_bias_sd_dps=0.0,
            acc_bias_rw_mps2_per_sqrt_s=0.0,
            gyr_bias_rw_dps_per_sqrt_s=0.0,
            acc_bias_drift_mps2=0.0,
            gyr_bias_drift_dps=0.0,
            scale_sd=0.0,
            misalignment_sd_deg=0.0,
            mag_hard_iron_sd_uT=0.0,
            mag_soft_iron_sd=0.0,
            drop_probability=0.0,
            quantize=False,
        )


@dataclass(frozen=True)
class DeviceErrors:
    """The constant errors of one physical device (drawn once per seed)."""

    acc_matrix: np.ndarray  # (3, 3) scale + misalignment
    gyr_matrix: np.ndarray
    acc_bias_mps2: np.ndarray  # (3,)
    gyr_bias_rads: np.ndarray
    mag_soft_iron: np.ndarray  # (3, 3)
    mag_hard_iron_uT: np.ndarray  # (3,)

    def as_dict(self) -> dict:
        return {k: np.asarray(getattr(self, k)).tolist() for k in self.__dataclass_fields__}


def draw_device(params: ImuParams, rng: np.random.Generator) -> DeviceErrors:
    def matrix() -> np.ndarray:
        m = np.eye(3) + np.diag(rng.normal(0.0, params.scale_sd, 3))
        off = rng.normal(0.0, np.radians(params.misalignment_sd_deg), (3, 3))
        np.fill_diagonal(off, 0.0)
        return m + off

    soft = rng.normal(0.0, params.mag_soft_iron_sd, (3, 3))
    return DeviceErrors(
        acc_matrix=matrix(),
        gyr_matrix=matrix(),
        acc_bias_mps2=rng.normal(0.0, params.acc_bias_sd_mps2, 3),
        gyr_bias_rads=np.radians(rng.normal(0.0, params.gyr_bias_sd_dps, 3)),
        mag_soft_iron=np.eye(3) + 0.5 * (soft + soft.T),
        mag_hard_iron_uT=rng.normal(0.0, params.mag_hard_iron_sd_uT, 3),
    )


@dataclass
class QuantisedChannel:
    """File values ``q / 10**decimals`` in ``unit``; in-memory SI value = file value * ``si_factor``."""

    q: np.ndarray  # int64 (N, 3)
    decimals: int
    unit: str
    si_factor: float

    @property
    def file_values(self) -> np.ndarray:
        return self.q / float(10**self.decimals)

    @property
    def si(self) -> np.ndarray:
        return self.file_values * self.si_factor


def _quantise(
    values: np.ndarray, lsb_numer: int, decimals: int, full_scale: float, quantize: bool
) -> tuple[np.ndarray, int]:
    if not quantize:
        d = 9
        return np.round(np.clip(values, -full_scale, full_scale) * 10**d).astype(np.int64), d
    counts = np.round(values * 10**decimals / lsb_numer)
    limit = np.floor(full_scale * 10**decimals / lsb_numer)
    counts = np.clip(counts, -limit - 1, limit).astype(np.int64)  # int16-like asymmetric range
    return counts * lsb_numer, decimals


def random_walk(n: int, dt_s: np.ndarray, sigma_per_sqrt_s: float, rng: np.random.Generator) -> np.ndarray:
    if sigma_per_sqrt_s == 0.0 or n == 0:
        return np.zeros((n, 3))
    steps = rng.normal(0.0, 1.0, (n, 3)) * (sigma_per_sqrt_s * np.sqrt(dt_s))[:, None]
    steps[0] = 0.0
    return np.cumsum(steps, axis=0)


def measure(
    specific_force_mps2: np.ndarray,
    omega_rads: np.ndarray,
    mag_uT: np.ndarray,
    t_s: np.ndarray,
    params: ImuParams,
    device: DeviceErrors,
    rng: np.random.Generator,
) -> dict[str, QuantisedChannel]:
    """Apply the error model to true sensor-frame signals sampled at device times ``t_s``."""
    n = len(t_s)
    dt = np.diff(t_s, prepend=t_s[0] if n else 0.0)
    acc = specific_force_mps2 @ device.acc_matrix.T + device.acc_bias_mps2
    acc += random_walk(n, dt, params.acc_bias_rw_mps2_per_sqrt_s, rng)
    acc += rng.normal(0.0, 1.0, (n, 3)) * params.acc_noise_mps2
    gyr = omega_rads @ device.gyr_matrix.T + device.gyr_bias_rads
    gyr += random_walk(n, dt, np.radians(params.gyr_bias_rw_dps_per_sqrt_s), rng)
    gyr += rng.normal(0.0, 1.0, (n, 3)) * np.radians(params.gyr_noise_dps)
    if params.acc_bias_drift_mps2 > 0 or params.gyr_bias_drift_dps > 0:  # thermal warm-up (own stream)
        drift_rng = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0])
        shape = (1.0 - np.exp(-(t_s - (t_s[0] if n else 0.0)) / params.bias_drift_tau_s))[:, None]
        acc += shape * drift_rng.normal(0.0, params.acc_bias_drift_mps2, 3)
        gyr += shape * np.radians(drift_rng.normal(0.0, params.gyr_bias_drift_dps, 3))
    mag = mag_uT @ device.mag_soft_iron.T + device.mag_hard_iron_uT
    mag += rng.normal(0.0, 1.0, (n, 3)) * params.mag_noise_uT

    acc_q, acc_d = _quantise(acc / G0, params.acc_lsb_ug, 6, params.acc_range_g, params.quantize)
    gyr_q, gyr_d = _quantise(np.degrees(gyr), params.gyr_lsb_mdps, 3, params.gyr_range_dps, params.quantize)
    mag_q, mag_d = _quantise(mag, params.mag_lsb_nT, 3, params.mag_range_gauss * 100.0, params.quantize)
    return {
        "acc": QuantisedChannel(acc_q, acc_d, "g", G0),
        "gyr": QuantisedChannel(gyr_q, gyr_d, "dps", np.pi / 180.0),
        "mag": QuantisedChannel(mag_q, mag_d, "uT", 1.0),
    }


def dropped_mask(n: int, params: ImuParams, rng: np.random.Generator) -> np.ndarray:
    """True for samples the device loses (bursts of 1..drop_max_burst); first and last kept."""
    keep = np.ones(n, dtype=bool)
    if params.drop_probability <= 0 or n < 3:
        return keep
    starts = np.flatnonzero(rng.random(n) < params.drop_probability)
    lengths = rng.integers(1, params.drop_max_burst + 1, len(starts))
    for s, k in zip(starts, lengths, strict=True):
        keep[s : s + k] = False
    keep[0] = keep[-1] = True
    return keep
