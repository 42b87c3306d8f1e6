"""Accelerometer/gyroscope calibration (thesis eqs. 2.1-2.5) against a known sensor model."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.model import ImuStream, Recording
from imulog.process import calibration as cal
from imulog.process import quaternion as Q

G = 9.80665
RATE = 100.0


@pytest.fixture(scope="module")
def sensor():
    rng = np.random.default_rng(7)
    return {
        "acc_kv": np.eye(3) + rng.normal(0, 0.02, (3, 3)),  # sensitivity x misalignment, eq. 2.1
        "acc_bias": rng.normal(0, 0.15, 3),
        "gyr_kv": np.eye(3) + rng.normal(0, 0.02, (3, 3)),
        "gyr_bias": rng.normal(0, 0.01, 3),
        "rng": rng,
    }


def _measure(s, acc_true, gyr_true, noise=True):
    rng = s["rng"]
    acc = acc_true @ s["acc_kv"].T + s["acc_bias"]
    gyr = gyr_true @ s["gyr_kv"].T + s["gyr_bias"]
    if noise:
        acc = acc + rng.normal(0, 0.02, acc.shape)
        gyr = gyr + rng.normal(0, 0.003, gyr.shape)
    return acc, gyr


def calibration_session(s):
    """Six static orientations (axis up / down) joined by 90/180-degree turns, then one full
    turn about each axis at 90 deg/s between static periods: true acc and gyr (rad/s)."""
    q = Q.IDENTITY.copy()
    accs, gyrs = [], []

    def hold(seconds):
        n = int(seconds * RATE)
        accs.append(np.tile(Q.rotate(Q.conjugate(q), [0, 0, G]), (n, 1)))
        gyrs.append(np.zeros((n, 3)))

    def turn(axis, angle, rate=np.pi / 2):
        nonlocal q
        n = int(round(abs(angle) / rate * RATE))
        w = np.zeros(3)
        w[axis] = np.sign(angle) * rate
        for _ in range(n):
            q = Q.multiply(q, Q.from_rotation_vector(w / RATE))
            accs.append(Q.rotate(Q.conjugate(q), [0, 0, G])[None])
            gyrs.append(w[None])

    # sensor z up, z down, x up/down, y up/down
    hold(4)
    turn(0, np.pi)  # z down
    hold(4)
    turn(0, -np.pi)
    turn(1, -np.pi / 2)  # x up
    hold(4)
    turn(1, np.pi)  # x down
    hold(4)
    turn(1, -np.pi / 2)
    turn(0, np.pi / 2)  # y up
    hold(4)
    turn(0, -np.pi)  # y down
    hold(4)
    turn(0, np.pi / 2)
    hold(4)
    # known full turns about each axis (one per axis, 4 s each)
    for axis in range(3):
        turn(axis, 2 * np.pi)
        hold(3)
    return np.vstack(accs), np.vstack(gyrs)


def test_six_position_closed_form(sensor):
    ap = np.column_stack([G * sensor["acc_kv"][:, i] + sensor["acc_bias"] for i in range(3)])
    am = np.column_stack([-G * sensor["acc_kv"][:, i] + sensor["acc_bias"] for i in range(3)])
    c = cal.accelerometer_six_position(ap, am, G)
    assert np.allclose(c.bias, sensor["acc_bias"])
    assert np.allclose(c.matrix, np.linalg.inv(sensor["acc_kv"]))


def test_calibration_from_a_session_recovers_the_sensor(sensor):
    from imulog.steps.calibrate import calibration_from_arrays

    acc_true, gyr_true = calibration_session(sensor)
    acc, gyr = _measure(sensor, acc_true, gyr_true)
    t = np.arange(len(acc)) * int(1e9 / RATE)
    c = calibration_from_arrays(t, acc, gyr, angle_rad=2 * np.pi)
    assert c.info["rotations"] >= 3
    assert np.abs(c.acc.bias - sensor["acc_bias"]).max() < 0.01  # m/s^2
    assert np.abs(c.acc.matrix - np.linalg.inv(sensor["acc_kv"])).max() < 0.005
    assert np.abs(c.gyr.bias - sensor["gyr_bias"]).max() < 0.001  # rad/s
    assert np.abs(c.gyr.matrix - np.linalg.inv(sensor["gyr_kv"])).max() < 0.01
    # applying it: calibrated readings match the truth far better than raw ones
    a_cal, g_cal = cal.apply(c, acc, gyr)
    assert np.sqrt(np.mean((a_cal - acc_true) ** 2)) < 0.3 * np.sqrt(np.mean((acc - acc_true) ** 2))
    assert np.sqrt(np.mean((g_cal - gyr_true) ** 2)) < 0.5 * np.sqrt(np.mean((gyr - gyr_true) ** 2))


def test_missing_orientation_is_named(sensor):
    acc = np.tile([0.0, 0.0, G], (1000, 1))
    with pytest.raises(ValueError, match=r"\+x"):
        cal.six_position_means(acc, [(0, 500), (500, 1000)])
    with pytest.raises(ValueError, match="three independent"):
        cal.gyroscope_from_rotations(np.zeros((10, 3)), [(np.ones((10, 3)), np.array([1.0, 0, 0]))], RATE)


def test_calibrate_cli_round_trip(sensor, tmp_path):
    acc_true, gyr_true = calibration_session(sensor)
    acc, gyr = _measure(sensor, acc_true, gyr_true)
    t = np.arange(len(acc)) * int(1e9 / RATE)
    calib = tmp_path / "calib.mcap"
    write_trial(calib, Recording(imus=[ImuStream("wrist", t, acc=acc, gyr=gyr)]))
    out = tmp_path / "cal.json"
    runner = CliRunner()
    r = runner.invoke(cli, ["calibrate", str(calib), "-o", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["format"] == cal.CALIBRATION_FORMAT and len(doc["acc"]["matrix"]) == 3
    # apply it to a "trial" recorded with the same sensor
    acc2, gyr2 = _measure(sensor, acc_true[::-1].copy(), gyr_true[::-1].copy())
    trial = tmp_path / "trial.mcap"
    write_trial(trial, Recording(imus=[ImuStream("wrist", t, acc=acc2, gyr=gyr2)]))
    r = runner.invoke(cli, ["process", "calibrate", str(trial), "--calibration", str(out)])
    assert r.exit_code == 0, r.output
    with TrialReader(trial) as tr:
        s = tr.read("/derived/calibrated/wrist")
    assert s.columns == ["ax", "ay", "az", "gx", "gy", "gz"]
    assert np.sqrt(np.mean((s.values[:, :3] - acc_true[::-1]) ** 2)) < 0.05
    # the orientation step then uses the calibrated channel by default
    r = runner.invoke(cli, ["process", "orientation", str(trial)])
    assert r.exit_code == 0, r.output
    with TrialReader(trial) as tr:
        run = [v for v in tr.runs().values() if str(v.get("step")).startswith("orientation")][-1]
    assert "/derived/calibrated/wrist" in run["inputs"]
    # a wrong file is a one-line error
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "other"}')
    r = runner.invoke(cli, ["process", "calibrate", str(trial), "--calibration", str(bad)])
    assert r.exit_code != 0 and "not an imulog calibration file" in r.output


def test_calibrate_in_windows_equals_at_once(sensor, tmp_path):
    """A recording longer than one window is calibrated block by block as it is read: the same values as the
    whole channel at once (the map is per sample)."""
    import shutil

    from imulog.archive.doctor import check_file
    from imulog.steps.calibrate import calibration_from_arrays, run_calibrate
    from imulog.steps.windows import WindowParams

    acc_true, gyr_true = calibration_session(sensor)
    acc, gyr = _measure(sensor, acc_true, gyr_true)
    t = np.arange(len(acc)) * int(1e9 / RATE)
    calibration = calibration_from_arrays(t, acc, gyr)
    whole = write_trial(tmp_path / "whole.mcap", Recording(imus=[ImuStream("wrist", t, acc=acc, gyr=gyr)]))
    blocks = tmp_path / "blocks.mcap"
    shutil.copy(whole, blocks)
    run_calibrate(whole, calibration)
    run_calibrate(blocks, calibration, windows=WindowParams(core_s=10.0, margin_s=0.0))
    with TrialReader(whole) as a, TrialReader(blocks) as b:
        sa, sb = a.read("/derived/calibrated/wrist"), b.read("/derived/calibrated/wrist")
        np.testing.assert_array_equal(sa.t_ns, sb.t_ns)
        np.testing.assert_array_equal(sa.values, sb.values)
        assert (
            b.channel("/derived/calibrated/wrist").metadata["sha256"]
            == a.channel("/derived/calibrated/wrist").metadata["sha256"]
        )
    assert not check_file(blocks).problems
