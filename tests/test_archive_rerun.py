"""Rerun's own MCAP loader (rerun-sdk 0.41, Rust) opens an imulog trial: what it sees, channel by channel."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from test_archive_helpers import generic_times, synthetic_recording

from imulog.archive import append_derived, write_trial
from imulog.archive.twins import TWIN_RATE_HZ
from imulog.model import SignalStream

rr_chunk = pytest.importorskip("rerun.chunk")


@pytest.fixture(scope="module")
def trial(tmp_path_factory) -> tuple[Path, object]:
    rng = np.random.default_rng(11)
    rec = synthetic_recording(rng)
    path = write_trial(tmp_path_factory.mktemp("rerun") / "trial.mcap", rec)
    t = rec.imus[0].t_ns
    q = SignalStream("/derived/orientation/wrist", t, ["qw", "qx", "qy", "qz"], ["1"] * 4, rng.normal(size=(len(t), 4)))
    append_derived(path, [q], run={"step": "orientation", "algorithm": "test"})
    return path, rec


def _entities(path: Path) -> dict[str, list]:
    out: dict[str, list] = {}
    for chunk in rr_chunk.McapReader(path).stream():
        out.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch())
    return out


def test_rerun_summary_lists_every_channel_with_schema_and_count(trial):
    path, rec = trial
    info = rr_chunk.McapReader(path).info()
    assert info.summary_source == "embedded"  # it used our summary, not a recovery scan
    seen = {c.topic: (c.schema.name, c.message_count) for c in info.channels}
    assert seen["/imu/wrist"] == (
        "imulog.ImuBlock",
        int(np.ceil((rec.imus[0].t_ns[-1] - rec.imus[0].t_ns[0]) / 1e9 + 1e-9)),
    )
    assert seen["/poses/cluster"] == (
        "imulog.PoseBlock",
        int(np.ceil((rec.poses[0].t_ns[-1] - rec.poses[0].t_ns[0]) / 1e9 + 1e-9)),
    )
    assert seen["/derived/viewer/poses/cluster"][0] == "foxglove.FrameTransform"
    assert seen["/events/c3d"] == ("imulog.IntervalEvent", 3)
    assert seen["/derived/orientation/wrist"][0] == "imulog.SignalBlock"
    assert {t for t in seen if not t.startswith("/derived/viewer/")} == {s.topic for s in rec.streams()} | {
        "/derived/orientation/wrist"
    }
    # imulog.trial, imulog.anthropometrics, imulog.device.wrist, imulog.device.chest, imulog.timeline, imulog.raw,
    # imulog.run.1
    assert info.metadata_count == 7
    assert info.attachment_count == 0


def test_rerun_decodes_blocks_and_draws_foxglove_poses(trial):
    path, rec = trial
    ents = _entities(path)
    expected = {s.topic for s in rec.streams() if len(s)} | {"/derived/orientation/wrist"}
    assert expected <= set(ents)
    assert {"/__mcap_metadata", "/__mcap_properties"} <= set(ents)
    # Rerun's protobuf decoder turns each ImuBlock into a struct; the packed arrays come through intact.
    blocks = [
        row
        for rb in ents["/imu/wrist"]
        if "imulog.ImuBlock:message" in rb.schema.names
        for row in rb.column("imulog.ImuBlock:message").to_pylist()
    ]
    assert sum(b[0]["count"] for b in blocks) == len(rec.imus[0])
    # packed repeated numbers: Rerun's protobuf reflection gives lists of numbers, not Binary
    # (schema_version 2 blocks give evenly spread times as start + span: docs/schemas.md)
    t = np.concatenate(
        [
            generic_times(*(b[0].get(k) for k in ("count", "t_ns", "t0_ns", "t_span_ns", "t_residual_ns")))
            for b in blocks
        ]
    )
    assert np.array_equal(t, rec.imus[0].t_ns)
    # the pose channel's viewer twin (foxglove.FrameTransform) is drawn as a Transform3D (float32)
    translations = [
        row
        for rb in ents["/derived/viewer/poses/cluster"]
        if "Transform3D:translation" in rb.schema.names
        for row in rb.column("Transform3D:translation").to_pylist()
    ]
    keep = np.arange(0, len(rec.poses[0]), int(np.ceil(100.0 / TWIN_RATE_HZ)))  # 100 Hz -> the twins' rate
    good = np.isfinite(rec.poses[0].position[keep]).all(axis=1)
    assert len(translations) == int(good.sum())
    got = np.array([r[0] for r in translations], dtype=np.float64)
    want = rec.poses[0].position[keep][good].astype(np.float32).astype(np.float64)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    assert np.allclose(got[~np.isnan(got)], want[~np.isnan(want)])
    meta_cols = {n for rb in ents["/__mcap_metadata"] for n in rb.schema.names}
    assert {"imulog.trial", "imulog.raw", "imulog.run.1"} <= meta_cols


def test_rerun_cli_converts_to_rrd_that_verifies(trial, tmp_path):
    exe = shutil.which("rerun") or str(Path(__import__("sys").executable).parent / "rerun")
    path, _ = trial
    rrd = tmp_path / "trial.rrd"
    res = subprocess.run(
        [exe, "mcap", "convert", str(path), "-o", str(rrd)], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr[-2000:]
    res = subprocess.run([exe, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    entities = {str(c.entity_path) for c in rr_chunk.RrdReader(rrd).stream()}
    assert {"/imu/wrist", "/markers/vicon", "/poses/cluster", "/derived/orientation/wrist"} <= entities
