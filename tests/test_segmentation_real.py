"""Zero-velocity / static detection on real recordings (../shared/data).

* gaitmap foot IMU (walking, 204.8 Hz): every stride between the provided stride borders must contain exactly
  one zero-velocity interval (the stance phase) and no stride border may fall in one. Detector settings are
  gaitmap's published NormZeroVelocityDetection defaults for the foot (70 deg/s, 0.15 s window), not ours.
* BROAD trials 05 and 14 (hand-moved IMU with three 10 s breaks, 285.7 Hz): the static mask of the gyro-norm
  baseline (default 0.1 rad/s, the R2G thesis static threshold) must agree with the dataset's ``movement``
  mask on >= 97 % of samples and find every break and rest with >= 90 % overlap.
"""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process.segmentation.double_threshold import double_threshold
from imulog.process.segmentation.dynamos import runs
from imulog.process.segmentation.zero_velocity import GyroNormStaticParams, gyro_norm_static, static_from_movements

GAITMAP_RATE_HZ = 204.8
GAITMAP_FOOT = GyroNormStaticParams(threshold_rad_s=np.deg2rad(70.0), window_s=0.15, min_static_s=0.05)


def stride_agreement(static: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> tuple[float, float]:
    """Fraction of strides with exactly one zero-velocity interval inside, fraction of borders in one."""
    zs, ze = runs(static)
    one = np.mean([np.sum((zs >= s) & (ze <= e)) == 1 for s, e in zip(starts, ends, strict=True)])
    borders = np.unique(np.r_[starts, ends])
    return float(one), float(static[borders].mean())


@pytest.fixture(scope="module")
def gaitmap(shared_data):
    pd = pytest.importorskip("pandas")
    folder = shared_data / "gaitmap_foot"
    imu = pd.read_csv(folder / "imu_sample.csv", header=[0, 1], index_col=0)
    strides = pd.read_csv(folder / "stride_borders_sample.csv")
    return imu, strides


@pytest.mark.parametrize("foot", ["left", "right"])
def test_gaitmap_zero_velocity_matches_stride_borders(gaitmap, foot):
    imu, strides = gaitmap
    gyr = np.deg2rad(imu[f"{foot}_sensor"][["gyr_x", "gyr_y", "gyr_z"]].to_numpy())  # file is deg/s
    mine = strides[strides.foot == foot]
    static = gyro_norm_static(gyr, GAITMAP_RATE_HZ, GAITMAP_FOOT)
    one, border_static = stride_agreement(static, mine.start.to_numpy(), mine.end.to_numpy())
    assert one >= 0.95
    assert border_static == 0.0
    # stance takes a plausible share of each stride (walking: roughly 25-45 % at zero velocity)
    share = np.mean([static[s:e].mean() for s, e in zip(mine.start, mine.end, strict=True)])
    assert 0.15 < share < 0.6


def _broad(shared_data, name):
    h5py = pytest.importorskip("h5py")
    with h5py.File(shared_data / "broad" / f"{name}.hdf5", "r") as f:
        return np.asarray(f["imu_gyr"]), np.asarray(f["movement"]).astype(bool), float(f.attrs["sampling_rate"])


@pytest.mark.parametrize(
    "name", ["05_undisturbed_slow_rotation_with_breaks_B", "14_undisturbed_slow_translation_with_breaks_B"]
)
def test_broad_static_intervals_match_movement_mask(shared_data, name):
    gyr, movement, rate = _broad(shared_data, name)
    truth_static = ~movement
    for static in (
        gyro_norm_static(gyr, rate),
        static_from_movements(len(gyr), *double_threshold(gyr, rate), rate, min_static_s=0.2),
    ):
        assert np.mean(static == truth_static) >= 0.97
        ts, te = runs(truth_static)
        assert len(ts) == 5  # rest, three breaks, rest
        for a, b in zip(ts, te, strict=True):
            assert static[a:b].mean() >= 0.9
