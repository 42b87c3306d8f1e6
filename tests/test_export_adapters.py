"""gaitmap and kineticstoolkit adapters: their unit conventions, on real gaitmap data."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.export import ExportError
from imulog.export.adapters import GAITMAP_COLUMNS, gaitmap_frame, to_gaitmap, to_kineticstoolkit


@pytest.fixture(scope="module")
def gaitmap_trial(shared_data, tmp_path_factory):
    out = tmp_path_factory.mktemp("gaitmap")
    result = CliRunner().invoke(cli, ["convert", str(shared_data / "gaitmap_foot"), "-o", str(out)])
    assert result.exit_code == 0, result.output
    return next(out.glob("*.mcap"))


def test_to_gaitmap_gives_back_gaitmaps_own_numbers(gaitmap_trial, shared_data):
    """gaitmap's sample (gyr in deg/s) -> archive (rad/s) -> to_gaitmap: deg/s again, not 57x off."""
    src = pd.read_csv(shared_data / "gaitmap_foot" / "imu_sample.csv", header=[0, 1], index_col=0)
    with TrialReader(gaitmap_trial) as trial:
        df = to_gaitmap(trial, "right_sensor")
        with pytest.raises(ExportError, match="name the IMU"):
            to_gaitmap(trial)
    assert list(df.columns) == list(GAITMAP_COLUMNS)
    np.testing.assert_allclose(
        df.to_numpy(), src["right_sensor"][list(GAITMAP_COLUMNS)].to_numpy(), rtol=1e-9, atol=1e-12
    )
    assert df.attrs["units"]["gyr"] == "deg/s"
    np.testing.assert_allclose(np.diff(df.index.to_numpy()), 1 / 204.8, rtol=1e-6)


def test_gaitmap_frame_rotates_both_sensors():
    r = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])  # 90 deg about z
    out = gaitmap_frame(np.array([[1.0, 0, 0]]), np.array([[np.pi, 0, 0]]), rotation=r)
    np.testing.assert_allclose(out, [[0, 1, 0, 0, 180, 0]], atol=1e-12)
    with pytest.raises(ValueError):
        gaitmap_frame(np.zeros((1, 3)), np.zeros((1, 3)), rotation=np.eye(2))


def test_to_kineticstoolkit_keeps_units_and_events(gaitmap_trial):
    pytest.importorskip("kineticstoolkit")  # not a declared dependency (requires PyQt5, GPL)
    with TrialReader(gaitmap_trial) as trial:
        imu = trial.read("/imu/left_sensor")
        ts = to_kineticstoolkit(trial, "/imu/left_sensor")
        markers = to_kineticstoolkit(trial, "/markers/mocap")
        strides = to_kineticstoolkit(trial, "/events/strides")
        n_strides = len(trial.read("/events/strides"))
    np.testing.assert_array_equal(ts.data["gyr"], imu.gyr)
    assert ts.data_info["gyr"]["Unit"] == "rad/s" and ts.data_info["acc"]["Unit"] == "m/s^2"
    first = next(iter(markers.data))
    assert markers.data[first].shape[1] == 4 and markers.data_info[first]["Unit"] == "m"
    assert len(strides.events) == n_strides
