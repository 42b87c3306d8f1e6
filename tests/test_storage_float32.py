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
    for module in ("align", "trajectory", "trajectory_windows"):
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


def test_orientation_on_its_grid_does_not_change_the_evaluation(tmp_path: Path, monkeypatch):
    """Quaternions on a 2**-18 grid and gravity-free acceleration on a 2**-12 m/s^2 grid (counts, half of
    float32's bytes) against the same pipeline storing both as float32: every channel read back is within half a
    grid step of the float32 one, and the evaluation against the Vicon truth moves by a hundredth of a millimetre."""
    _pipeline(tmp_path / "grid")
    monkeypatch.setattr("imulog.steps.orientation.QUAT_GRID", {"precision": "float32"})
    monkeypatch.setattr("imulog.steps.orientation.ACC_GRID", {"precision": "float32"})
    _pipeline(tmp_path / "f32")
    with TrialReader(tmp_path / "grid" / "trial.mcap") as a, TrialReader(tmp_path / "f32" / "trial.mcap") as b:
        for topic, step in (("/derived/orientation/wrist", 2.0**-18), ("/derived/acc_global/wrist", 2.0**-12)):
            assert a.channel(topic).metadata["precision"] == "quantized", topic
            assert b.channel(topic).metadata["precision"] == "float32", topic
            x, y = a.read(topic).values, b.read(topic).values
            np.testing.assert_array_equal(np.rint(x / step), x / step)  # on the grid
            assert np.nanmax(np.abs(x - y)) <= step / 2 + 1e-7, topic  # the nearest grid point to the float32 value
        ea, eb = _numbers(a.metadata["imulog.evaluation"]), _numbers(b.metadata["imulog.evaluation"])
        assert a.metadata["imulog.timing"]["n_phases"] == b.metadata["imulog.timing"]["n_phases"]
    assert ea.keys() == eb.keys() and len(ea) > 10
    change = {k: abs(ea[k] - eb[k]) for k in ea if "_cm" in k}
    drift = ("/methods/ddi/", "/methods/dedrift/")  # plain double integration: tens of cm of drift
    accurate = max(v for k, v in change.items() if not k.startswith(drift))
    print(f"largest change of an error: {accurate:.5f} cm (drift-free methods), {max(change.values()):.5f} cm (all)")
    # measured 0.002 cm and 0.03 cm: well under the 0.1 cm the errors are reported at
    assert accurate <= 0.005 and max(change.values()) <= 0.1


def test_metrics_distance_on_its_grid_keeps_every_value_and_the_record(tmp_path: Path, monkeypatch):
    """The metrics distance channel on a 2**-10 cm grid (counts) against the same step storing it as float64, on a
    simulated home recording longer than one core (so it is written core by core, gaps and all): every stored value
    is the nearest grid point of the float64 one (at most 2**-11 cm, 5 um, against the published 1 cm histogram
    bins), the gaps stay NaN, and the metrics record (histogram, area, activity, per hour) is the same."""
    from imulog.converters import axivity

    from imulog.archive.streaming import write_trial_streaming
    from imulog.simulate.home import HomeParams, write_home_cwa
    from imulog.steps import metrics_windows
    from imulog.steps.metrics import run_metrics
    from imulog.steps.windows import WindowParams

    cwa = tmp_path / "home.cwa"
    write_home_cwa(cwa, HomeParams(days=1.0 / 24, rate_hz=25.0, seed=4, start="2024-03-04T09:40:00"))
    grid = write_trial_streaming(tmp_path / "grid.mcap", axivity.iter_chunks(cwa, blocks_per_chunk=300))
    wide = tmp_path / "f64.mcap"
    wide.write_bytes(grid.read_bytes())
    cores = WindowParams(core_s=1500.0, margin_s=10.0)
    run_metrics(grid, windows=cores)
    monkeypatch.setattr(metrics_windows, "DISTANCE_GRID", {})
    run_metrics(wide, windows=cores)
    step = 2.0**-10
    topic = "/derived/metrics/distance/ax6_4321"
    with TrialReader(grid) as a, TrialReader(wide) as b:
        assert a.channel(topic).metadata["precision"] == "quantized"
        assert "precision" not in b.channel(topic).metadata
        x, y = a.read(topic).values, b.read(topic).values
        assert len(x) == 90_000 and np.isfinite(y).mean() > 0.9
        np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
        finite = np.isfinite(y)
        assert not np.array_equal(x[finite], y[finite])  # the float64 values are not on the grid: it did round
        np.testing.assert_array_equal(x[finite], np.rint(y[finite] / step) * step)  # the nearest grid point
        assert np.nanmax(np.abs(x - y)) <= step / 2
        ra, rb = dict(a.metadata["imulog.metrics"]), dict(b.metadata["imulog.metrics"])
    assert ra.keys() == rb.keys()
    for k in ra:
        if k not in ("step", "created", "run"):
            assert ra[k] == rb[k], k
