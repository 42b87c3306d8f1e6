"""C3D export read back by ezc3d (and kineticstoolkit when installed) equal to the source."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.export.c3d import interp_gapped
from imulog.process.alignment import device_to_reference

ezc3d = pytest.importorskip("ezc3d")


@pytest.fixture(scope="module")
def r2g_c3d(processed_r2g, tmp_path_factory):
    out = tmp_path_factory.mktemp("c3d") / "r2g.c3d"
    result = CliRunner().invoke(cli, ["export", str(processed_r2g), "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out


def test_points_analogs_and_events_equal_the_trial(r2g_c3d, processed_r2g):
    c = ezc3d.c3d(str(r2g_c3d))
    with TrialReader(processed_r2g) as trial:
        mk = trial.read("/markers/vicon")
        imu = trial.read("/imu/wrist")
        phases = trial.read("/derived/phases/wrist")
        alignment = trial.metadata["imulog.alignment"]
    params = c["parameters"]
    assert params["POINT"]["LABELS"]["value"] == list(mk.labels)
    assert params["POINT"]["UNITS"]["value"] == ["mm"] and params["POINT"]["RATE"]["value"][0] == 100.0
    pts = c["data"]["points"][:3].transpose(2, 1, 0) / 1000.0  # (F, M, 3) m
    src = np.where(mk.valid[:, :, None], mk.pos, np.nan)
    assert pts.shape == src.shape  # the Vicon trial has no dropped frames
    np.testing.assert_array_equal(np.isnan(pts), np.isnan(src))
    np.testing.assert_allclose(pts, src, rtol=1e-6, atol=1e-7)  # C3D stores float32
    # IMU as analogs, interpolated onto the frames on the reference clock
    labels = params["ANALOG"]["LABELS"]["value"]
    assert labels[:3] == ["wrist_acc_x", "wrist_acc_y", "wrist_acc_z"] and "wrist_gyr_z" in labels
    assert params["ANALOG"]["UNITS"]["value"][labels.index("wrist_gyr_z")] == "rad/s"
    analogs = c["data"]["analogs"][0]  # (A, F)
    gyr_z = analogs[labels.index("wrist_gyr_z")]
    t_ref = device_to_reference(imu.t_ns, alignment)
    expected = np.interp(mk.t_ns, t_ref, imu.gyr[:, 2], left=np.nan, right=np.nan)
    ok = np.isfinite(gyr_z)
    assert ok.mean() > 0.9
    np.testing.assert_allclose(gyr_z[ok], expected[ok], rtol=1e-5, atol=1e-6)
    # events: every phase start and end, in seconds from the first frame
    ev = params["EVENT"]
    times = ev["TIMES"]["value"][0] * 60 + ev["TIMES"]["value"][1]
    starts = [t for t, label in zip(times, ev["LABELS"]["value"], strict=True) if label == "reach"]
    expected_reach = (phases.start_ns[np.asarray(phases.labels) == "reach"] - mk.t_ns[0]) / 1e9
    np.testing.assert_allclose(starts, expected_reach, atol=1e-5)
    assert ev["USED"]["value"][0] == 2 * len(phases)


def test_kineticstoolkit_reads_the_same(r2g_c3d, processed_r2g):
    ktk = pytest.importorskip("kineticstoolkit")  # not a declared dependency: it requires PyQt5 (GPL)
    data = ktk.read_c3d(str(r2g_c3d), convert_point_unit=True)
    with TrialReader(processed_r2g) as trial:
        mk = trial.read("/markers/vicon")
        phases = trial.read("/derived/phases/wrist")
    o = data["Points"].data["O"][:, :3]
    np.testing.assert_allclose(o, np.where(mk.valid[:, :1], mk.pos[:, 0], np.nan), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(data["Points"].time, (mk.t_ns - mk.t_ns[0]) / 1e9, atol=1e-9)
    names = [e.name for e in data["Points"].events]
    assert names.count("lift") == list(phases.labels).count("lift") == 5
    assert "wrist_gyr_x" in data["Analogs"].data


def test_real_nexus_c3d_round_trips(shared_data, tmp_path):
    """pyomeca's real Vicon Nexus C3D -> archive -> C3D: the same markers and EMG analogs."""
    src_path = shared_data / "vicon_nexus" / "markers_analogs.c3d"
    mcap = tmp_path / "nexus.mcap"
    assert CliRunner().invoke(cli, ["convert", str(src_path), "-o", str(mcap)]).exit_code == 0
    out = tmp_path / "nexus.c3d"
    result = CliRunner().invoke(cli, ["export", str(mcap), "-o", str(out)])
    assert result.exit_code == 0, result.output
    src, ours = ezc3d.c3d(str(src_path)), ezc3d.c3d(str(out))
    labels = src["parameters"]["POINT"]["LABELS"]["value"]
    ours_labels = ours["parameters"]["POINT"]["LABELS"]["value"]
    assert [lbl.split(":")[-1] for lbl in labels] == [lbl.split(":")[-1] for lbl in ours_labels]
    a, b = src["data"]["points"][:3], ours["data"]["points"][:3]
    assert a.shape == b.shape
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-4)  # mm, float32 both sides
    assert ours["parameters"]["ANALOG"]["RATE"]["value"][0] == 2000.0
    np.testing.assert_allclose(ours["data"]["analogs"], src["data"]["analogs"], rtol=1e-6, atol=1e-9)


def test_interp_gapped_leaves_gaps_empty():
    t = np.array([0, 10, 20, 60, 70], dtype=np.int64)
    v = np.arange(5.0)[:, None]
    out = interp_gapped(t, v, np.array([5, 40, 60, 65, 80]), period_ns=10)[:, 0]
    np.testing.assert_array_equal(np.isnan(out), [False, True, False, False, True])
    np.testing.assert_allclose(out[[0, 2, 3]], [0.5, 3.0, 3.5])
