"""``imulog record --view --web``, headless: a Rerun client connected to the recorder's gRPC proxy (the one the
browser viewer uses) receives the IMU, the markers and the online VQF orientation while the trial is recorded, and
the archive is the same as without the view."""

from __future__ import annotations

import re
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("pylsl")

import test_record as base  # noqa: E402
from procs import start  # noqa: E402

from imulog.archive import TrialReader  # noqa: E402
from imulog.view.rrd import read_scalars, summarize  # noqa: E402
from imulog.view.server import free_port, rerun_executable  # noqa: E402

trial, lsl_env = base.trial, base.lsl_env  # the fixtures


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="Rerun's server binary, Linux CI")
def test_record_view_web_streams_to_the_viewer(trial, lsl_env, tmp_path):
    out, got = tmp_path / "viewed.mcap", tmp_path / "received.rrd"
    web, grpc = free_port(), free_port()
    rec = base.imulog(
        lsl_env, "record", "-o", out, "--stream", "name=wrist", "--stream", "name=vicon", "--duration", "6", "--wait", "30",
        "--view", "--web", "--port", web, "--grpc-port", grpc,
    )  # fmt: skip
    play = base.imulog(lsl_env, "replay", trial["mcap"], "--duration", "8", "--wait-consumers", "30")
    client = None
    try:
        lines = base.wait_for_line(rec, "recording into")
        assert any(f"http://127.0.0.1:{web}" in line for line in lines), lines
        client = start(
            [str(rerun_executable()), f"rerun+http://127.0.0.1:{grpc}/proxy", "--save", str(got)]
            + ["--bind", "127.0.0.1", "--port", str(free_port())],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env={**lsl_env, "RERUN_ANALYTICS": "0"},
        )
        base.wait_for_line(rec, "first samples written")
        deadline = time.monotonic() + 30  # mid-recording (6 s of it): the client is receiving
        while rec.poll() is None and not (got.exists() and got.stat().st_size > 0) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert rec.poll() is None and got.exists() and got.stat().st_size > 0, (
            "no data reached the viewer while recording"
        )
        rec_out, rec_err = rec.communicate(timeout=60)
        assert rec.returncode == 0, rec_err
        latency = re.search(r"sample-to-viewer latency median (\d+) ms, max (\d+) ms", rec_err)
        # the issue: sample-to-screen under 0.5 s (the median: on a loaded 2-core machine single pieces wait longer)
        assert latency and int(latency.group(1)) < 500, rec_err
        client.wait(timeout=30)  # the stream ends with the recording: the client saves and exits
    finally:
        for p in (rec, play, client):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    entities = summarize(got)
    acc, orientation = entities["/imu/wrist/acc"], entities["/derived/orientation/wrist"]
    markers = entities["/world/markers/vicon"]
    with TrialReader(out) as t:
        n_imu = t.channel("/imu/wrist").sample_count
        n_mk = t.channel("/markers/vicon").sample_count
        topics = t.topics()
    # every recorded sample reached the viewer (plotted as recorded: one row per sample)
    assert acc.component_rows["Scalars:scalars"] == n_imu
    assert markers.component_rows["Points3D:positions"] == n_mk
    assert orientation.component_rows["Scalars:scalars"] == n_imu
    assert "/derived/orientation_static/wrist/state" in entities  # VQF's online rest detection: moving / at rest
    _, q = read_scalars(got, "/derived/orientation/wrist")
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)  # unit quaternions from VQF
    # the view is not written to the archive
    assert not [x for x in topics if x.startswith("/derived/orientation")]
    assert {"/imu/wrist", "/markers/vicon"} <= set(topics)
    # the live orientation is VQF's: its inclination agrees with `process orientation` (VQF offline) on the trial
    base.run_cli("process", "orientation", out)
    with TrialReader(out) as t:
        q_off = t.read("/derived/orientation/wrist").values
    assert len(q_off) == len(q)
    angle = np.degrees(np.arccos(np.clip(np.sum(_up(q) * _up(q_off), axis=1), -1.0, 1.0)))
    assert np.max(angle) < 2.0, np.max(angle)  # measured: 0.13 deg median, 0.41 deg max


def _up(q: np.ndarray) -> np.ndarray:
    """The global z axis in the sensor frame, from sensor-to-global quaternions (w, x, y, z)."""
    w, x, y, z = q.T
    return np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1)
