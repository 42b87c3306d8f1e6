"""Derived channels stored as float32 (issue 28, docs/schemas.md): the demo pipeline run twice, once as shipped
and once with these channels' float32 requests taken back (float64 storage), gives the same evaluation against the Vicon
truth, and the stored channels differ by float32's rounding only (a micrometre on metres)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.commands.demo import demo_commands

F32_TOPICS = (
    "/derived/trajectory/",
    "/derived/vicon/cluster_pose",
    "/derived/vicon/angular_velocity",
    "/derived/reference/",
    "/derived/metrics/distance/",
)


def _pipeline(out: Path) -> None:
    for what, argv in demo_commands(out, repetitions=2, seed=5, view=False):
        r = CliRunner().invoke(cli, argv)
        assert r.exit_code == 0, f"{what}: {r.output}"


def _numbers(record, prefix=""):
    """Flat {path: float} of the numbers in a metadata record."""
    out = {}
    if isinstance(record, dict):
        for k, v in record.items():
            out.update(_numbers(v, f"{prefix}/{k}"))
    elif isinstance(record, list):
        for i, v in enumerate(record):
            out.update(_numbers(v, f"{prefix}/{i}"))
    elif isinstance(record, (int, float)) and not isinstance(record, bool):
        out[prefix] = float(record)
    return out


def test_float32_derived_channels_do_not_change_the_evaluation(tmp_path: Path, monkeypatch):
    _pipeline(tmp_path / "f32")
    # the same pipeline with these channels' float32 requests taken back (orientation stays float32 in both)
    for module in ("align", "trajectory", "trajectory_windows", "metrics_windows"):
        monkeypatch.setattr(f"imulog.steps.{module}.F32", {})
    _pipeline(tmp_path / "f64")
    with TrialReader(tmp_path / "f32" / "trial.mcap") as a, TrialReader(tmp_path / "f64" / "trial.mcap") as b:
        topics = [t for t in a.topics() if t.startswith(F32_TOPICS)]
        assert len(topics) >= 8 and set(topics) <= set(b.topics())
        for topic in topics:
            sa, sb = a.read(topic), b.read(topic)
            assert np.array_equal(sa.t_ns, sb.t_ns), topic
            va = getattr(sa, "values", None)
            pairs = (
                [(va, sb.values)] if va is not None else [(sa.position, sb.position), (sa.orientation, sb.orientation)]
            )
            for x, y in pairs:
                assert np.array_equal(x, x.astype(np.float32).astype(np.float64), equal_nan=True), topic  # float32
                scale = max(float(np.nanmax(np.abs(y))), 1.0) if np.isfinite(y).any() else 1.0
                # float32 rounding (and its effect on the steps that read these channels): a micrometre on metres
                assert np.nanmax(np.abs(x - y)) <= 1e-6 * scale, topic
        ea, eb = _numbers(a.metadata["imulog.evaluation"]), _numbers(b.metadata["imulog.evaluation"])
    assert ea.keys() == eb.keys() and len(ea) > 10
    for k in ea:
        # errors in cm, ranges in %, rank correlations: 1e-4 in the quantity's own unit, a thousandth of the
        # precision they are reported at (0.1 cm, 0.1 %, 2 decimals) and far below the IMU's centimetre errors
        assert abs(ea[k] - eb[k]) <= 1e-4, (k, ea[k], eb[k])
