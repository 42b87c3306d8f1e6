"""Evaluation metrics and the evaluate step's pure parts, against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process.evaluation import aggregate, format_table, summarize, trajectory_errors
from imulog.steps.evaluate import compute_evaluation, interpolate_reference, table_from_record


def test_errors_of_a_known_offset():
    t = np.linspace(0, 1, 101)
    ref = np.column_stack([0.4 * t, 0.1 * np.sin(np.pi * t), -0.2 * t**2])
    est = ref.copy()
    est[50:, 0] += 0.01  # 1 cm error in x over the second half (51 of 101 samples)
    est += [5.0, -3.0, 1.0]  # absolute offsets vanish: both are taken relative to their start
    r = trajectory_errors(est, ref)
    assert r["x"]["mae_cm"] == pytest.approx(51 / 101)
    assert r["x"]["rom_pct"] == pytest.approx(100 * (0.01 * 51 / 101) / 0.4)
    assert r["x"]["rmse_cm"] == pytest.approx(np.sqrt(51 / 101))
    assert r["x"]["final_cm"] == pytest.approx(1.0)
    assert r["y"]["mae_cm"] == pytest.approx(0.0, abs=1e-12)
    assert r["final_norm_cm"] == pytest.approx(1.0)
    assert r["x"]["spearman"] == pytest.approx(1.0)  # still monotonic
    assert r["z"]["spearman"] == pytest.approx(1.0)
    # a reversed estimate is perfectly anti-correlated
    assert trajectory_errors(-ref, ref)["x"]["spearman"] == pytest.approx(-1.0)


def test_nan_rows_are_ignored_and_too_few_rows_raise():
    ref = np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)]) / 100
    est = ref.copy()
    ref[3] = np.nan
    est[5, 1] = np.nan
    assert trajectory_errors(est, ref)["n_samples"] == 8
    with pytest.raises(ValueError):
        trajectory_errors(est[:1], ref[:1])


def test_summary_and_table_shape():
    rows = [
        {a: {"mae_cm": v, "rom_pct": 10 * v, "rmse_cm": v, "final_cm": v, "spearman": 0.9} for a in "xyz"}
        for v in (1.0, 3.0)
    ]
    s = summarize(rows)
    assert s["x"]["mae_cm"]["mean"] == 2.0
    assert s["x"]["mae_cm"]["std"] == pytest.approx(np.sqrt(2.0))
    text = format_table(aggregate({"zupt": rows, "optimized": rows[:1]}))
    lines = text.splitlines()
    assert lines[0].split()[:4] == ["method", "MAE", "x", "(cm)"]
    assert lines[2].startswith("zupt") and "2.00±1.41" in lines[2]
    assert lines[3].startswith("optimized") and lines[3].rstrip().endswith("1")


def test_interpolate_reference_respects_gaps():
    t_ref = np.arange(0, 1_000_000_000, 10_000_000, dtype=np.int64)  # 100 Hz, 1 s
    pos = np.column_stack([t_ref / 1e9, np.zeros(len(t_ref)), np.zeros(len(t_ref))])
    pos[40:50] = np.nan  # a 0.1 s occlusion
    t = np.array([5_000_000, 455_000_000, 995_000_000, 2_000_000_000], dtype=np.int64)
    out = interpolate_reference(t_ref, pos, t, max_gap_s=0.05)
    assert out[0, 0] == pytest.approx(0.005)
    assert np.isnan(out[1, 0])  # inside the gap
    assert np.isnan(out[3, 0])  # after the end
    assert np.isnan(out[2, 0])  # beyond the last sample (0.99 s)


def test_compute_evaluation_per_repetition_windows():
    t = np.arange(0, 4_000_000_000, 10_000_000, dtype=np.int64)
    ref = np.column_stack([np.sin(t / 1e9), np.cos(t / 1e9), t / 4e9])
    est = ref + np.where(t[:, None] < 2_000_000_000, 0.0, 0.02) * np.array([1, 0, 0])
    windows = [
        {"index": 1, "start_ns": 0, "end_ns": 1_900_000_000},
        {"index": 2, "start_ns": 1_500_000_000, "end_ns": 3_990_000_000},
    ]
    rec = compute_evaluation({"zupt": (t, est)}, (t, ref), reference_topic="/markers/vicon:O", windows=windows)
    reps = rec["methods"]["zupt"]["repetitions"]
    assert [r["repetition"] for r in reps] == [1, 2]
    assert reps[0]["x"]["mae_cm"] == pytest.approx(0.0, abs=1e-9)
    assert reps[1]["x"]["mae_cm"] > 1.0  # the 2 cm step happens inside window 2
    assert "zupt" in table_from_record(rec)
