"""``imulog process orientation --backend vqf_gyrocal`` records the gyroscope correction it estimated (the 3x3
sensitivity/misalignment ``M``, the bias it turns about, whether it was fitted) in the run's record, per valid run
and window, equal to what :func:`imulog.process.orientation_gyrocal.vqf_gyrocal` returns on the same samples."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from test_orientation_gyrocal import SENSITIVITY, _miscalibrated

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.model import ImuStream, Recording
from imulog.process.orientation_gyrocal import vqf_gyrocal
from imulog.steps.orientation import run_orientation
from imulog.steps.windows import WindowParams


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    """120 s at 200 Hz of a gyroscope 1 % off in sensitivity with cross-axis terms (simulated truth)."""
    _, gyr, acc, rate = _miscalibrated(seed=1)
    t_ns = np.round(np.arange(len(gyr)) * 1e9 / rate).astype(np.int64)
    path = tmp_path_factory.mktemp("gyrocal") / "trial.mcap"
    write_trial(path, Recording(imus=[ImuStream("wrist", t_ns, acc=acc, gyr=gyr)]), attach_sources=False)
    return path


def _last_run(path) -> dict:
    with TrialReader(path) as t:
        runs = t.runs()
        return runs[max(runs)]


def _stored(path):
    """The IMU samples as the step reads them (what the estimator is given), and their rate (Hz)."""
    with TrialReader(path) as t:
        s = t.read("/imu/wrist")
    return s.gyr, s.acc, (len(s.t_ns) - 1) / ((s.t_ns[-1] - s.t_ns[0]) / 1e9)


def test_one_window_records_the_estimated_correction(trial, tmp_path):
    path = tmp_path / "t.mcap"
    path.write_bytes(trial.read_bytes())
    run_orientation(path, params=_params("vqf_gyrocal"))
    run = _last_run(path)
    (entry,) = run["gyro_correction"]
    gyr, acc, rate = _stored(path)
    info: dict = {}
    _, m = vqf_gyrocal(gyr, acc, rate, info=info)
    assert entry["samples"] == [0, len(gyr)]
    np.testing.assert_allclose(entry["matrix"], m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(entry["bias_rad_s"], info["bias_rad_s"], rtol=0, atol=1e-12)
    assert entry["fitted"] is True
    # what it recorded is the correction of this gyroscope (M undoes the simulated sensitivity), not an identity
    assert np.abs(np.asarray(entry["matrix"]) @ SENSITIVITY - np.eye(3)).max() < 0.003
    assert np.abs(np.asarray(entry["matrix"]) - np.eye(3)).max() > 0.005
    # the simulated bias is (0.01, -0.02, 0.015) rad/s
    np.testing.assert_allclose(entry["bias_rad_s"], [0.01, -0.02, 0.015], atol=0.003)
    # `imulog info --json` shows it with the run
    out = CliRunner().invoke(cli, ["info", str(path), "--json"])
    assert out.exit_code == 0, out.output
    runs = json.loads(out.output)["runs"]
    assert runs[max(runs, key=int)]["gyro_correction"] == run["gyro_correction"]


def test_info_verbose_shows_the_correction(trial, tmp_path):
    """``imulog info -v`` prints what the run recorded, readably: M row by row (to 5 decimals), each axis's
    sensitivity error and the bias in deg/s, one block per window; without -v only the run line."""
    path = tmp_path / "t.mcap"
    path.write_bytes(trial.read_bytes())
    run_orientation(path, params=_params("vqf_gyrocal"), windows=WindowParams(core_s=50.0, margin_s=10.0))
    entries = _last_run(path)["gyro_correction"]
    out = CliRunner().invoke(cli, ["info", str(path), "-v"])
    assert out.exit_code == 0, out.output
    heads = [line.strip() for line in out.output.splitlines() if "gyro correction over" in line]
    assert heads == [
        "gyro correction over samples {}-{} (core {}-{}): fitted".format(*e["samples"], *e["core"]) for e in entries
    ]
    shown = [line.split("M = [", 1)[1].split("]", 1)[0] for line in out.output.splitlines() if "M = [" in line]
    assert len(shown) == len(entries)
    for text, e in zip(shown, entries, strict=True):
        m = np.array([[float(v) for v in row.split()] for row in text.split(";")])
        np.testing.assert_allclose(m, e["matrix"], rtol=0, atol=5e-6)
    (first,) = [line for line in out.output.splitlines() if "sensitivity x" in line][:1]
    m0 = np.asarray(entries[0]["matrix"])
    assert f"y {(m0[1, 1] - 1) * 100:+.2f} %" in first
    assert f"{np.degrees(entries[0]['bias_rad_s'][1]):+.3f}" in first and first.endswith("deg/s")
    plain = CliRunner().invoke(cli, ["info", str(path)])
    assert plain.exit_code == 0 and "gyro correction" not in plain.output


def test_other_backends_record_no_correction(trial, tmp_path):
    path = tmp_path / "t.mcap"
    path.write_bytes(trial.read_bytes())
    run_orientation(path, params=_params("vqf_offline"))
    assert "gyro_correction" not in _last_run(path)


def test_windows_record_one_correction_each(trial, tmp_path):
    """Several windows: one estimate per window, over the samples it read, each equal to the estimator's there."""
    path = tmp_path / "t.mcap"
    path.write_bytes(trial.read_bytes())
    run_orientation(path, params=_params("vqf_gyrocal"), windows=WindowParams(core_s=50.0, margin_s=10.0))
    entries = _last_run(path)["gyro_correction"]
    gyr, acc, rate = _stored(path)
    assert len(entries) >= 2
    assert entries[0]["core"][0] == 0 and entries[-1]["core"][1] == len(gyr)
    for e in entries:
        a, b = e["samples"]
        assert a <= e["core"][0] < e["core"][1] <= b
        _, m = vqf_gyrocal(gyr[a:b], acc[a:b], rate)
        np.testing.assert_allclose(e["matrix"], m, rtol=0, atol=1e-12)


def _params(backend: str):
    from imulog.process.orientation import OrientationParams

    return OrientationParams(backend=backend)
