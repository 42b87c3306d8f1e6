"""C3D export read back by ezc3d and by the independent `c3d` package (and kineticstoolkit when installed)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.export.c3d_grid import interp_gapped, plan_grid, whole_multiple
from imulog.process.alignment import device_to_reference

ezc3d = pytest.importorskip("ezc3d")
c3d = pytest.importorskip("c3d")


def read_with_c3d(path):
    """(points (F, M, 5): x, y, z, residual, cameras; analogs (F * k, A)) as the `c3d` package reads them."""
    with open(path, "rb") as f:
        reader = c3d.Reader(f)
        frames = [(p, a) for _, p, a in reader.read_frames()]
    return np.array([p for p, _ in frames]), np.concatenate([a.T for _, a in frames], axis=0)


@pytest.fixture(scope="module")
def r2g_c3d(processed_r2g, tmp_path_factory):
    out = tmp_path_factory.mktemp("c3d") / "r2g.c3d"
    result = CliRunner().invoke(cli, ["export", str(processed_r2g), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "points of /markers/vicon interpolated" in result.output  # 115 Hz IMU, 100 Hz markers: said so
    return out


@pytest.fixture(scope="module")
def nexus(shared_data, tmp_path_factory):
    """pyomeca's real Vicon Nexus C3D -> archive -> C3D."""
    src = shared_data / "vicon_nexus" / "markers_analogs.c3d"
    tmp = tmp_path_factory.mktemp("nexus")
    assert CliRunner().invoke(cli, ["convert", str(src), "-o", str(tmp / "nexus.mcap")]).exit_code == 0
    result = CliRunner().invoke(cli, ["export", str(tmp / "nexus.mcap"), "-o", str(tmp / "nexus.c3d")])
    assert result.exit_code == 0, result.output
    return src, tmp / "nexus.c3d"


def test_simulated_trial_holds_the_imu_at_its_own_rate(r2g_c3d, processed_r2g):
    c = ezc3d.c3d(str(r2g_c3d))
    with TrialReader(processed_r2g) as trial:
        mk = trial.read("/markers/vicon")
        imu = trial.read("/imu/wrist")
        alignment = trial.metadata["imulog.alignment"]
        device_rate = trial.channel("/imu/wrist").rate_hz  # 114.9 Hz on the IMU's clock (ms time stamps)
    params = c["parameters"]
    t_ref = device_to_reference(imu.t_ns, alignment)
    imu_rate = device_rate * (imu.t_ns[-1] - imu.t_ns[0]) / (t_ref[-1] - t_ref[0])  # on the reference clock
    assert params["ANALOG"]["RATE"]["value"][0] == pytest.approx(imu_rate, rel=1e-7)  # float32 in the file
    assert params["POINT"]["RATE"]["value"][0] == pytest.approx(imu_rate, rel=1e-7)  # float32 in the file  # ratio 1
    labels = params["ANALOG"]["LABELS"]["value"]
    assert labels[:3] == ["wrist_acc_x", "wrist_acc_y", "wrist_acc_z"] and "wrist_gyr_z" in labels
    assert params["ANALOG"]["UNITS"]["value"][labels.index("wrist_gyr_z")] == "rad/s"
    gyr_z = c["data"]["analogs"][0][labels.index("wrist_gyr_z")]
    # every IMU sample, in order, as is (float32): no interpolated value
    np.testing.assert_array_equal(gyr_z[np.isfinite(gyr_z)], imu.gyr[:, 2].astype(np.float32))
    # points interpolated onto the IMU's frames; residual -1 exactly where a point is missing
    pts = c["data"]["points"][:3].transpose(2, 1, 0) / 1000.0
    res = c["data"]["meta_points"]["residuals"][0].T
    np.testing.assert_array_equal(res == -1, np.isnan(pts).any(axis=2))
    assert (res[np.isfinite(pts).all(axis=2)] == 0).all()
    period = 1e9 / imu_rate
    g0 = t_ref[0] - np.flatnonzero(np.isfinite(gyr_z))[0] * period  # frames in the phase of the IMU's samples ...
    assert -period < g0 - mk.t_ns[0] <= 0  # ... from the markers' start (the IMU starts 2.3 s later)
    frame_t = g0 + np.arange(pts.shape[0]) * period
    x = np.interp(frame_t, mk.t_ns, mk.pos[:, 0, 0], left=np.nan, right=np.nan)
    good = np.isfinite(x) & np.isfinite(pts[:, 0, 0])
    assert good.mean() > 0.85
    np.testing.assert_allclose(pts[good, 0, 0], x[good], atol=2e-6)


def test_second_reader_sees_the_same(r2g_c3d):
    ours = ezc3d.c3d(str(r2g_c3d))
    points, analogs = read_with_c3d(r2g_c3d)
    res = ours["data"]["meta_points"]["residuals"][0].T  # (F, M)
    np.testing.assert_array_equal(points[:, :, 3] == -1, res == -1)
    assert (points[:, :, 3] == -1).any()
    valid = res >= 0
    np.testing.assert_allclose(points[valid][:, :3], ours["data"]["points"][:3].transpose(2, 1, 0)[valid], rtol=1e-6)
    np.testing.assert_array_equal(analogs, ours["data"]["analogs"][0].T.astype(np.float32))


def test_events_are_the_phases(r2g_c3d, processed_r2g):
    c = ezc3d.c3d(str(r2g_c3d))
    with TrialReader(processed_r2g) as trial:
        phases = trial.read("/derived/phases/wrist")
        alignment = trial.metadata["imulog.alignment"]
        imu = trial.read("/imu/wrist")
    t0 = device_to_reference(imu.t_ns[:1], alignment)[0]
    rate = c["parameters"]["POINT"]["RATE"]["value"][0]
    g0 = t0 - np.ceil(t0 * rate / 1e9 - 1e-6) * 1e9 / rate  # the first frame: at or before the markers' start (0)
    ev = c["parameters"]["EVENT"]
    times = ev["TIMES"]["value"][0] * 60 + ev["TIMES"]["value"][1]
    starts = [t for t, label in zip(times, ev["LABELS"]["value"], strict=True) if label == "reach"]
    expected = (phases.start_ns[np.asarray(phases.labels) == "reach"] - g0) / 1e9  # phases on the reference clock
    np.testing.assert_allclose(starts, expected, atol=2e-5)
    assert ev["USED"]["value"][0] == 2 * len(phases)


def test_kineticstoolkit_reads_the_same(r2g_c3d, processed_r2g):
    ktk = pytest.importorskip("kineticstoolkit")  # not a declared dependency: it requires PyQt5 (GPL)
    data = ktk.read_c3d(str(r2g_c3d), convert_point_unit=True)
    ours = ezc3d.c3d(str(r2g_c3d))
    np.testing.assert_allclose(data["Points"].data["O"][:, :3], ours["data"]["points"][:3, 0].T / 1000, rtol=1e-6)
    assert "wrist_gyr_x" in data["Analogs"].data


def test_real_nexus_c3d_residuals_masks_and_analogs_are_the_source(nexus):
    src_path, out = nexus
    src, ours = ezc3d.c3d(str(src_path)), ezc3d.c3d(str(out))
    labels = src["parameters"]["POINT"]["LABELS"]["value"]
    assert [lbl.split(":")[-1] for lbl in labels] == [
        lbl.split(":")[-1] for lbl in ours["parameters"]["POINT"]["LABELS"]["value"]
    ]
    a, b = src["data"]["points"][:3], ours["data"]["points"][:3]
    assert a.shape == b.shape
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-4)  # mm, float32 both sides
    src_res = src["data"]["meta_points"]["residuals"]
    assert (src_res == -1).sum() == 305  # the Nexus file's occluded points
    np.testing.assert_array_equal(ours["data"]["meta_points"]["residuals"], src_res)
    np.testing.assert_array_equal(
        ours["data"]["meta_points"]["camera_masks"], src["data"]["meta_points"]["camera_masks"]
    )
    assert ours["parameters"]["POINT"]["RATE"]["value"][0] == 100.0
    assert ours["parameters"]["ANALOG"]["RATE"]["value"][0] == 2000.0
    np.testing.assert_array_equal(ours["data"]["analogs"], src["data"]["analogs"])  # sample for sample
    analog = ours["parameters"]["ANALOG"]
    assert list(analog["SCALE"]["value"]) == [1.0] * 38 and list(analog["OFFSET"]["value"]) == [0] * 38
    assert analog["GEN_SCALE"]["value"][0] == 1.0


def test_real_nexus_export_read_by_the_second_reader(nexus):
    src_path, out = nexus
    src_pts, src_an = read_with_c3d(src_path)
    pts, an = read_with_c3d(out)
    np.testing.assert_array_equal(pts[:, :, 3], src_pts[:, :, 3])  # residuals, -1 for the occluded points
    np.testing.assert_array_equal(an, src_an)
    np.testing.assert_allclose(pts[:, :, :3], src_pts[:, :, :3], rtol=1e-6, atol=1e-4)


def test_grid_keeps_whole_multiples_and_follows_the_analog_otherwise():
    g = plan_grid((0, 5_790_000_000), (100.0, 0), (2000.0, 0))
    assert (g.point_rate_hz, g.ratio, g.frames, g.points_resampled) == (100.0, 20, 580, False)
    g = plan_grid((0, 10_000_000_000), (100.0, 0), (115.0, 3_000_000))
    assert g.points_resampled and g.ratio == 1 and g.point_rate_hz == 115.0
    assert (3_000_000 - g.g0_ns) % round(1e9 / 115) < 2 and g.g0_ns <= 0  # phase of the IMU, covers the markers
    assert whole_multiple(200.001, 100.0, 60.0) == 2  # 0.06 samples of drift over a minute: placed
    assert whole_multiple(200.02, 100.0, 60.0) == 0  # 1.2 samples: not


def test_interp_gapped_leaves_gaps_empty():
    t = np.array([0, 10, 20, 60, 70], dtype=np.int64)
    v = np.arange(5.0)[:, None]
    out = interp_gapped(t, v, np.array([5, 40, 60, 65, 80]), period_ns=10)[:, 0]
    np.testing.assert_array_equal(np.isnan(out), [False, True, False, False, True])
    np.testing.assert_allclose(out[[0, 2, 3]], [0.5, 3.0, 3.5])


def test_analog_channels_of_several_sensors_stay_apart(shared_data, tmp_path):
    """The real Delsys Trigno export (devices/delsys_trigno, emgio, BSD-3-Clause): two Mini sensors whose EMG
    channels are both called ``EMG``. Before, the C3D had two analogs labelled ``EMG`` and no descriptions, so a
    reader could not tell which sensor each came from; now a shared label takes its sensor's name and every
    analog's DESCRIPTIONS names its source channel. Both C3D readers see the same labels."""
    trial = tmp_path / "trigno.mcap"
    src = shared_data / "devices" / "delsys_trigno" / "truncated_trigno_sample.csv"
    assert CliRunner().invoke(cli, ["convert", str(src), "-o", str(trial)]).exit_code == 0
    out = tmp_path / "trigno.c3d"
    result = CliRunner().invoke(
        cli, ["export", str(trial), "-o", str(out), "--clock", "device", "--imu", "mini_sensor_10"]
    )
    assert result.exit_code == 0, result.output
    analog = ezc3d.c3d(str(out))["parameters"]["ANALOG"]
    labels = [str(x).strip() for x in analog["LABELS"]["value"]]
    descriptions = [str(x).strip() for x in analog["DESCRIPTIONS"]["value"]]
    assert len(set(labels)) == len(labels)
    assert labels[:2] == ["mini_sensor_10_EMG", "mini_sensor_11_EMG"]
    assert descriptions[:2] == ["/analog/mini_sensor_10 EMG", "/analog/mini_sensor_11 EMG"]
    assert descriptions[labels.index("mini_sensor_11_gyr_z")] == "/imu/mini_sensor_11 gyr_z"
    with open(out, "rb") as f:
        assert [str(x).strip() for x in c3d.Reader(f).analog_labels] == labels
    with TrialReader(trial) as t:  # the values under each label are that sensor's
        emg_11 = t.read("/analog/mini_sensor_11").values[:, 0]
    column = ezc3d.c3d(str(out))["data"]["analogs"][0, labels.index("mini_sensor_11_EMG")]
    np.testing.assert_allclose(column[: len(emg_11)], emg_11, rtol=1e-6, atol=1e-9)
