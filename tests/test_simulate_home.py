"""`imulog simulate home`: days of wrist data as an Axivity .cwa, generated minute by minute."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConvertOptions
from imulog.converters.axivity import CONVERTER as AXIVITY
from imulog.converters.registry import detect

from imulog.cli import cli
from imulog.simulate.home import HomeParams, iter_minutes, minute_signals, write_home_cwa

G0 = 9.80665


def test_minutes_are_independent_and_continuous():
    from datetime import datetime

    p = HomeParams(seed=5, rate_hz=50.0)
    start = datetime.fromisoformat(p.start)
    acc_a, gyr_a, _ = minute_signals(p, 10, start)
    acc_b, _, _ = minute_signals(p, 10, start)
    np.testing.assert_array_equal(acc_a, acc_b)  # any minute can be made on its own, identically
    prev, _, _ = minute_signals(p, 9, start)
    jump = np.abs(acc_a[0] - prev[-1]).max()
    typical = np.abs(np.diff(acc_a, axis=0)).max()
    assert jump < 3 * typical + 0.02  # postures blend: no step at the minute boundary
    norm = np.linalg.norm(acc_a, axis=1)
    assert np.all(np.abs(norm - 1.0) < 0.05)  # a still-ish wrist measures about 1 g


def test_cwa_round_trip_across_midnight(tmp_path):
    p = HomeParams(days=2 / 24, rate_hz=25.0, start="2024-03-04T23:00:00", seed=2)
    path = tmp_path / "home.cwa"
    truth = write_home_cwa(path, p)
    assert detect(path).name == AXIVITY.name
    rec = AXIVITY.convert(path)
    imu = rec.imus[0]
    acc = np.concatenate([a for _, a, _, _ in iter_minutes(p)])
    gyr = np.concatenate([g for _, _, g, _ in iter_minutes(p)])
    assert len(imu) == len(acc) == 2 * 3600 * 25
    np.testing.assert_allclose(imu.acc / G0, acc, atol=0.5 / 4096 + 1e-9)  # int16 at 4096 LSB/g
    np.testing.assert_allclose(np.degrees(imu.gyr), gyr, atol=0.5 * 2000 / 32768 + 1e-9)
    dt = np.diff(imu.t_ns)
    # no jump at midnight (RTC date rollover); the default (skdh's) rule drops the fraction of the block's second,
    # so a block start can be a sample early and a step 1 ms off: within one sample of the simulator's clock
    assert abs(np.median(dt) - 40e6) < 1e3 and dt.min() >= 39e6 and dt.max() <= 41e6
    assert np.abs(imu.t_ns - np.arange(len(imu)) * 40_000_000).max() <= 40e6
    # OpenMovement's rule, which keeps the fraction, gives the simulator's clock to 0.1 ms
    om = AXIVITY.convert(path, ConvertOptions(extra={"cwa_times": "openmovement"})).imus[0]
    np.testing.assert_allclose(om.t_ns, np.arange(len(om)) * 40_000_000, atol=1e5, rtol=0)
    assert rec.metadata["imulog.trial"]["start_time"].startswith("2024-03-04T23:00:00")
    # night: few moving minutes
    assert (truth > 0).mean() < 0.2


def test_cli_writes_and_converts(tmp_path):
    out = tmp_path / "sim"
    result = CliRunner().invoke(
        cli, ["simulate", "home", "-o", str(out), "--days", "0.01", "--set", "rate_hz=25", "--seed", "1"]
    )
    assert result.exit_code == 0, result.output
    cwa = out / "home_s00_t00.cwa"
    truth = np.load(out / "home_s00_t00_truth.npz")["moving_s_per_minute"]
    assert len(truth) == round(0.01 * 1440)
    result = CliRunner().invoke(cli, ["convert", str(cwa), "-o", str(tmp_path / "home.mcap")])
    assert result.exit_code == 0, result.output
    again = CliRunner().invoke(cli, ["simulate", "home", "-o", str(out), "--days", "0.01"])
    assert again.exit_code != 0 and "exists; add --overwrite to replace it" in again.output  # the trial is there
    bad = CliRunner().invoke(cli, ["simulate", "home", "-o", str(tmp_path / "other"), "--set", "rate_hz=30"])
    assert bad.exit_code != 0 and "not a CWA rate" in bad.output
    bad = CliRunner().invoke(cli, ["simulate", "r2g", "-o", str(out), "--days", "1"])
    assert bad.exit_code != 0 and "--days applies to the home protocol only" in bad.output


@pytest.mark.parametrize("rate", [12.5, 100.0])
def test_rates(rate, tmp_path):
    p = HomeParams(days=1 / 1440, rate_hz=rate)
    write_home_cwa(tmp_path / "x.cwa", p)
    rec = AXIVITY.convert(tmp_path / "x.cwa")
    assert len(rec.imus[0]) == int(60 * rate) // 40 * 40
