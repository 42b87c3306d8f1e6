"""BROAD's synchronised optical poses as the reference of ``imulog process align`` and ``imulog evaluate``, on the
three real BROAD trials in ../shared/data/broad (docs/alignment.md, "A rigid body's poses").

Both refused them before ("no /markers/* channel in the trial"; "/poses/optical is not used as a reference"). Now
the alignment compares the gyroscope with the body's angular velocity from its orientations (lag near 0: the files
are synchronised; a copy with the IMU's clock shifted by 250 ms gives that shift back), poses missing in most
samples are refused in one line, and evaluate reports the BROAD paper's inclination and heading-free RMSE with the
metric benchmarks/broad_orientation.py uses (imulog.process.orientation.orientation_errors).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("h5py")

from imulog.converters import convert_file  # noqa: E402

from imulog.archive import TrialReader, write_trial  # noqa: E402
from imulog.cli import cli  # noqa: E402

TRIALS = (
    "02_undisturbed_slow_rotation_B",
    "05_undisturbed_slow_rotation_with_breaks_B",
    "14_undisturbed_slow_translation_with_breaks_B",
)
SHIFT_NS = 250_000_000


def run(*args) -> tuple[int, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.output


@pytest.fixture(scope="module")
def processed(shared_data, tmp_path_factory) -> dict[str, Path]:
    """The three trials converted, oriented (default backend) and aligned on their poses."""
    folder = tmp_path_factory.mktemp("broad")
    out = {}
    for name in TRIALS:
        path = folder / f"{name[:2]}.mcap"
        assert run("convert", shared_data / "broad" / f"{name}.hdf5", "-o", path)[0] == 0
        code, text = run("evaluate", path)  # no orientation, no alignment yet: the first missing step is named
        assert code == 1 and "imulog process orientation" in text, text
        assert run("process", "orientation", path)[0] == 0
        code, text = run("evaluate", path)
        assert code == 1 and f"imulog process align {path}" in text, text
        code, text = run("process", "align", path)
        assert code == 0, text
        assert "rigid body /poses/optical" in text
        out[name] = path
    return out


@pytest.mark.parametrize("name", TRIALS)
def test_align_on_the_poses_finds_the_synchronised_clock(processed, name):
    with TrialReader(processed[name]) as trial:
        record = trial.metadata["imulog.alignment"]
        topics = trial.topics()
    assert record["reference"] == "/poses/optical" and record["cluster"]["pose"] == "/poses/optical"
    # synchronised by BROAD's authors: the lag is within 2 samples (7 ms at 285.7 Hz) of zero; measured -4.3 to
    # -4.7 ms on the three trials whatever the low-pass (the gyroscope runs about one sample behind the optics)
    assert abs(record["offset_ns"]) < 7e6
    assert abs(record["drift_ppm"]) < 20 and record["quality"] == "good"
    assert record["vector_match"] > 0.9
    w = min(1.0, abs(record["rotation_imu_to_cluster"][0]))
    assert math.degrees(2 * math.acos(w)) < 1.0  # BROAD's frames are aligned: the fitted rotation is near identity
    assert "/derived/vicon/cluster_pose" in topics and "/derived/vicon/angular_velocity" in topics


def test_a_shifted_copy_gives_its_shift_back(processed, shared_data, tmp_path):
    name = TRIALS[0]
    rec = convert_file(shared_data / "broad" / f"{name}.hdf5")
    rec.imus[0].t_ns = rec.imus[0].t_ns + SHIFT_NS  # the IMU's clock reads 250 ms late
    shifted = write_trial(tmp_path / "shifted.mcap", rec)
    code, text = run("process", "align", shifted)
    assert code == 0, text
    with TrialReader(shifted) as trial:
        lag = trial.metadata["imulog.alignment"]["offset_ns"]
    with TrialReader(processed[name]) as trial:
        base = trial.metadata["imulog.alignment"]["offset_ns"]
    assert abs(lag - (base - SHIFT_NS)) < 1e6  # t_ref = t_dev + offset: 250 ms less, within 1 ms


def test_poses_mostly_missing_are_refused_in_one_line(shared_data, tmp_path):
    rec = convert_file(shared_data / "broad" / f"{TRIALS[1]}.hdf5")
    pose = rec.poses[0]
    lost = np.ones(len(pose.t_ns), dtype=bool)
    lost[::4] = False  # tracking kept in a quarter of the frames
    pose.orientation[lost] = np.nan
    pose.position[lost] = np.nan
    valid = int(np.all(np.isfinite(pose.orientation), axis=1).sum())  # a quarter, less BROAD's own lost frames
    path = write_trial(tmp_path / "lost.mcap", rec)
    code, text = run("process", "align", path)
    assert code == 1
    line = text.strip().splitlines()[-1]
    assert f"/poses/optical: only {valid} of its {len(pose.t_ns)} poses" in line and "at least 50 %" in line, text
    assert valid < 0.26 * len(pose.t_ns)
    with TrialReader(path) as trial:
        assert "imulog.alignment" not in trial.metadata and not trial.runs()


def test_evaluate_reports_the_broad_errors_with_the_benchmarks_metric(processed, shared_data):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        import broad_orientation as bench
    finally:
        sys.path.pop(0)
    for name, path in processed.items():
        code, text = run("evaluate", path)
        assert code == 0, text
        assert "inclination RMSE" in text and "movement phases" in text
        with TrialReader(path) as trial:
            record = trial.metadata["imulog.orientation_evaluation"]
            assert "imulog.evaluation" not in trial.metadata  # the trajectories' record stays theirs
        assert record["kind"] == "orientation" and record["reference"] == "/poses/optical"
        assert record["imu_to_reference"].startswith("none")  # BROAD declares its frames aligned
        expected = bench.evaluate(
            bench.load(shared_data / "broad" / f"{name}.hdf5"), ahrs=False, backends=["vqf_offline"]
        )
        ref = expected["vqf_offline"]
        # the same metric on the same estimate; they differ only by the alignment's ~4 ms lag, which evaluate applies
        assert abs(record["inclination_rmse_deg"] - ref["inclination_rmse_deg"]) < 0.05
        assert abs(record["heading_free_rmse_deg"] - ref["heading_free_rmse_deg"]) < 0.06
        assert abs(record["samples"] - ref["samples"]) <= 10
        assert record["inclination_rmse_deg"] < 1.0


def test_batch_runs_the_same_steps_on_a_broad_trial(shared_data, tmp_path):
    """`imulog batch --steps orientation,align,evaluate` takes the same path as the commands (the align step's
    dispatch, imulog.steps.align_setup.run_align_trial, knows poses too)."""
    path = tmp_path / "b05.mcap"
    assert run("convert", shared_data / "broad" / f"{TRIALS[1]}.hdf5", "-o", path)[0] == 0
    code, text = run("batch", path, "--steps", "orientation,align,evaluate", "--no-ledger")
    assert code == 0 and "0 failed" in text, text
    with TrialReader(path) as trial:
        assert trial.metadata["imulog.alignment"]["reference"] == "/poses/optical"
        assert trial.metadata["imulog.orientation_evaluation"]["kind"] == "orientation"


def test_the_catalog_has_the_orientation_errors(processed, tmp_path):
    import pandas as pd

    paths = list(processed.values())
    code, text = run("evaluate", paths[0])
    assert code == 0, text
    out = tmp_path / "catalog.parquet"
    code, text = run("catalog", paths[0], "-o", out)
    assert code == 0, text
    row = pd.read_parquet(out).iloc[0]
    with TrialReader(paths[0]) as trial:
        record = trial.metadata["imulog.orientation_evaluation"]
    assert row["eval_inclination_rmse_deg"] == pytest.approx(record["inclination_rmse_deg"])
    assert row["eval_heading_free_rmse_deg"] == pytest.approx(record["heading_free_rmse_deg"])


def test_a_trial_with_trajectories_keeps_both_evaluations(processed, tmp_path):
    """BROAD's translation trial once it has trajectories too (process phases, trajectory): evaluate chooses the
    trajectories by default, --what orientation the orientation against the poses; each has its own record and
    step, so neither replaces the other (both wrote imulog.evaluation before, and the orientation had no option)."""
    import json
    import shutil

    import pandas as pd

    path = tmp_path / "14.mcap"
    shutil.copy(processed[TRIALS[2]], path)
    for step in ("phases", "trajectory"):
        code, text = run("process", step, path)
        assert code == 0, text
    code, text = run("evaluate", path)  # auto: the trajectories
    assert code == 0 and "errors against" in text, text
    with TrialReader(path) as trial:
        trajectories = trial.metadata["imulog.evaluation"]
    assert "methods" in trajectories and trajectories.get("kind") != "orientation"
    code, text = run("evaluate", path, "--what", "orientation", "--json")
    assert code == 0, text
    orientation = json.loads(text)
    assert orientation["kind"] == "orientation" and orientation["inclination_rmse_deg"] < 1.0
    with TrialReader(path) as trial:
        assert trial.metadata["imulog.evaluation"] == trajectories  # untouched by the orientation's run
        assert trial.metadata["imulog.orientation_evaluation"] == orientation
        steps = [r["step"] for r in trial.runs().values()]
    assert "evaluate" in steps and "evaluate_orientation" in steps
    code, text = run("evaluate", path, "--what", "trajectory", "--json")  # up to date: read back, not recomputed
    assert code == 0 and json.loads(text) == trajectories, text
    with TrialReader(path) as trial:
        assert trial.metadata["imulog.orientation_evaluation"] == orientation
    code, text = run("evaluate", path, "--what", "orientation", "--strides")
    assert code == 1 and "--strides" in text and "--what orientation" in text, text
    rrd = tmp_path / "14.rrd"  # the viewer's evaluation panel shows both reports
    assert run("view", path, "--save", rrd)[0] == 0
    from rerun.chunk import RrdReader

    from imulog.view import layout as L

    chunk = next(c for c in RrdReader(rrd).stream().to_chunks() if c.entity_path == L.evaluation_entity())
    panel = chunk.to_record_batch().column("TextDocument:text").to_pylist()[0][0]
    assert "| zupt |" in panel and "inclination_rmse_deg" in panel, panel
    out = tmp_path / "catalog.parquet"
    assert run("catalog", path, "-o", out)[0] == 0
    row = pd.read_parquet(out).iloc[0]
    assert row["eval_inclination_rmse_deg"] == pytest.approx(orientation["inclination_rmse_deg"])
    assert row["best_mae_cm"] > 0 and len(row["eval_methods"]) > 1
    assert json.loads(row["orientation_evaluation_json"])["reference"] == "/poses/optical"


def test_an_unknown_choice_is_refused_by_the_python_api(processed):
    """The Python counterpart of --what names the choices (click refuses others itself)."""
    from imulog.steps.evaluate import run_evaluate

    with pytest.raises(ValueError, match="what='sideways'"):
        run_evaluate(processed[TRIALS[0]], what="sideways")
