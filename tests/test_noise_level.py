"""The white-noise estimator of still periods (imulog.process.noise_level, benchmarks/device_noise.py): it recovers
a known level from a simulated still recording, finds the still windows of a recording that also moves, and reads
the real files through the converters."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from imulog.process.noise_level import StillParams, noise_level, smallest_step, still_windows
from imulog.simulate import imu_model

RATE = 114.9
PARAMS = StillParams(window_s=1.0)


def _still_imu(seconds: float, params: imu_model.ImuParams, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Accelerometer (m/s^2) and gyroscope (rad/s) of the simulator's IMU model lying still (gravity only)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    t = np.arange(n) / RATE
    device = imu_model.draw_device(params, rng)
    f = np.tile([0.0, 0.0, imu_model.EARTH_G], (n, 1))
    ch = imu_model.measure(f, np.zeros((n, 3)), np.tile([20.0, 0.0, -40.0], (n, 1)), t, params, device, rng)
    return ch["acc"].si, ch["gyr"].si


def test_recovers_the_simulators_white_noise_from_a_still_recording():
    params = imu_model.ImuParams()  # 0.02 m/s^2 and 0.1 deg/s per sample, quantised, bias random walk
    acc, gyr = _still_imu(60.0, params)
    windows = still_windows(gyr, RATE, PARAMS)
    assert len(windows) >= 50  # noise alone: nearly every 1-s window is within twice the quietest
    lv = noise_level(acc, RATE, windows, PARAMS)
    # quantisation (0.732 mg LSB) adds (0.0072 / sqrt 12)^2: 0.0201 m/s^2
    assert lv.sd == pytest.approx(0.02, rel=0.05)
    assert lv.density_white == pytest.approx(0.02 / np.sqrt(RATE / 2), rel=0.05)
    assert lv.density_band == pytest.approx(0.02 / np.sqrt(RATE / 2), rel=0.1)  # white: the band reads the same
    assert not lv.quantisation_limited
    assert lv.step == pytest.approx(params.acc_lsb_ug * 1e-6 * imu_model.G0, rel=1e-6)
    lg = noise_level(gyr, RATE, windows, PARAMS)
    assert np.degrees(lg.sd) == pytest.approx(0.1, rel=0.05)


def test_still_windows_skip_the_moving_part_and_the_level_stays():
    acc, gyr = _still_imu(60.0, imu_model.ImuParams(acc_noise_mps2=0.01, gyr_noise_dps=0.05), seed=2)
    n = len(acc)
    t = np.arange(n) / RATE
    moving = t >= 30.0  # the second half turns and shakes at 0.7 Hz
    gyr[moving] += np.radians(20.0) * np.sin(2 * np.pi * 0.7 * t[moving])[:, None]
    acc[moving] += 0.5 * np.sin(2 * np.pi * 0.7 * t[moving])[:, None]
    windows = still_windows(gyr, RATE, PARAMS)
    assert len(windows) >= 25
    assert np.all(windows[:, 1] <= int(30.0 * RATE) + 1)
    assert noise_level(acc, RATE, windows, PARAMS).sd == pytest.approx(0.01, rel=0.08)


def test_a_noise_under_the_lsb_is_reported_as_quantisation_limited():
    rng = np.random.default_rng(3)
    q = 9.80665 / 64  # an E4-like 1/64 g step (m/s^2)
    n = int(30 * RATE)
    true = np.array([0.3, -0.2, 9.81 / q]) * q + np.array([0.5, 0.5, 0.5]) * q  # half-way between two codes
    acc = np.round((true + rng.normal(0.0, 0.02, (n, 3))) / q) * q  # 0.02 m/s^2 of noise, under the step
    lv = noise_level(acc, RATE, still_windows(acc, RATE, PARAMS), PARAMS)
    assert lv.step == pytest.approx(q, rel=1e-6)
    assert lv.quantisation_limited
    assert smallest_step(np.array([[0.0], [0.25], [0.75], [0.25]])) == pytest.approx(0.25)


def test_device_noise_reads_real_files_through_the_converters(shared_data):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from device_noise import measure_stream
    from imulog.converters.registry import convert_file

    path = shared_data / "broad" / "05_undisturbed_slow_rotation_with_breaks_B.hdf5"
    if not path.exists():
        pytest.skip("BROAD trial not in ../shared/data")
    m = measure_stream(convert_file(path).imus[0])
    assert m is not None and m["rate_hz"] == pytest.approx(285.714, rel=1e-3)
    assert m["windows"] >= 60  # the dataset's rests and breaks: about 100 s still
    # myon aktos-t at rest: about 5.5 mg and 0.095 deg/s per sample (benchmarks/device_noise.py)
    assert 3e-3 * imu_model.G0 < m["acc"].sd < 8e-3 * imu_model.G0
    assert 0.05 < np.degrees(m["gyr"].sd) < 0.2


def test_the_grids_device_noise_conditions_read_as_the_median_device():
    """``device-noise`` (imulog.simulate.grid.DEVICE_CONDITIONS) simulates the median real device's noise: the same
    estimator reads 0.033 m/s^2 and 0.062 deg/s per sample from a still recording of it (1.6x / 0.6x the default)."""
    from dataclasses import fields

    from imulog.simulate.grid import DEVICE_CONDITIONS, condition

    names = {f.name for f in fields(imu_model.ImuParams)}
    for name in DEVICE_CONDITIONS:
        overrides = {k: v for k, v in condition(name).items() if k in names}
        assert set(overrides) == {"acc_noise_mps2", "gyr_noise_dps"}, name
    acc, gyr = _still_imu(
        60.0, imu_model.ImuParams(**{k: condition("device-noise")[k] for k in names & set(condition("device-noise"))})
    )
    windows = still_windows(gyr, RATE, PARAMS)
    assert noise_level(acc, RATE, windows, PARAMS).sd == pytest.approx(0.033, rel=0.05)
    assert np.degrees(noise_level(gyr, RATE, windows, PARAMS).sd) == pytest.approx(0.062, rel=0.05)
