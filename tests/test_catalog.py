"""imulog catalog and imulog report: one Parquet row per trial, incremental updates, Table 3.1 and plots."""

from __future__ import annotations

import json
import math
import os
import shutil
import sys

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.batch import run
from imulog.batch.catalog import build_catalog, schema
from imulog.batch.simulated import simulate_archive
from imulog.cli import cli

STEPS = "orientation,align,phases,trajectory,metrics,evaluate"


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    root = tmp_path_factory.mktemp("cat") / "archive"
    paths = simulate_archive(root, subjects=2, trials=2, repetitions=3, opening_static_s=5.0)
    report = run(root, STEPS, options={"phases": {"repetitions": 3}}, progress=False, ledger=None)
    assert report.ok
    return root, paths


def test_catalog_rows_and_readers(archive, tmp_path):
    root, paths = archive
    out = tmp_path / "catalog.parquet"
    result = CliRunner().invoke(cli, ["catalog", str(root), "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output
    assert "4 trials (4 read" in result.output
    table = pq.read_table(out)
    assert table.schema.equals(schema()) and table.num_rows == 4
    df = pd.read_parquet(out)
    assert sorted(df["subject"]) == ["S01", "S01", "S02", "S02"]
    assert set(df["task"]) == {"r2g"} and df["error"].isna().all()
    for row in df.itertuples():
        with TrialReader(row.path) as trial:
            imu = trial.channel("/imu/wrist")
            assert row.imu_duration_s == pytest.approx(imu.duration_s)
            assert row.raw_sha256 == trial.metadata["imulog.raw"]["sha256"]
            assert row.n_runs == len(trial.runs())
            ev = trial.metadata["imulog.evaluation"]
        assert row.file_size == os.path.getsize(row.path)
        assert list(row.devices) == ["vicon", "wrist"] and "/markers/vicon" in list(row.channels)
        assert "/derived/trajectory/zupt" in list(row.derived_channels)
        assert sorted({s.split(":")[0] for s in row.steps}) == sorted(STEPS.split(","))  # orientation:wrist
        runs = json.loads(row.runs_json)
        phases_run = next(r for r in runs if r["step"] == "phases:wrist")  # one run per IMU
        assert phases_run["params"]["repetitions"]["n_repetitions"] == 3
        assert row.n_repetitions == 3 and row.n_phases == 12
        assert json.loads(row.evaluation_json) == json.loads(json.dumps(ev))
        assert "arm_usage.overall_percent" in json.loads(row.metrics_json)
        assert row.best_mae_cm < 5.0
        # one IMU: the alignment columns are its one record, as before; the per-IMU columns by the same rule
        al = trial.metadata["imulog.alignment"]
        assert (
            json.loads(row.alignment_json) == json.loads(json.dumps(al)) and row.alignment_offset_ns == al["offset_ns"]
        )
        assert (row.n_imus, row.n_imus_aligned, row.n_imus_aligned_good) == (1, 1, int(al["quality"] == "good"))
        wrist = json.loads(row.alignment_imus_json)["wrist"]
        assert set(json.loads(row.alignment_imus_json)) == {"wrist"}
        assert (wrist["offset_ns"], wrist["drift_ppm"], wrist["quality"]) == (
            al["offset_ns"],
            al["drift_ppm"],
            al["quality"],
        )
    duckdb = pytest.importorskip("duckdb")
    got = duckdb.sql(
        f"select subject, count(*) as n, max(n_repetitions) as reps, "
        f"avg(cast(json_extract(evaluation_json, '$.methods.zupt.summary.x.mae_cm.mean') as double)) as zx "
        f"from '{out}' group by subject order by subject"
    ).fetchall()
    assert [(s, n, r) for s, n, r, _ in got] == [("S01", 2, 3), ("S02", 2, 3)]
    expected = (
        df.assign(
            zx=[json.loads(e)["methods"]["zupt"]["summary"]["x"]["mae_cm"]["mean"] for e in df["evaluation_json"]]
        )
        .groupby("subject")["zx"]
        .mean()
    )
    assert [z for *_, z in got] == pytest.approx(list(expected))


def test_catalog_is_incremental(archive, tmp_path):
    root = tmp_path / "archive"
    shutil.copytree(archive[0], root)
    out = tmp_path / "catalog.parquet"
    first = build_catalog(root, out)
    assert (first.read, first.reused, first.rows) == (4, 0, 4)
    again = build_catalog(root, out)
    assert (again.read, again.reused, again.rows) == (0, 4, 4)
    # one trial reprocessed with other parameters, one removed, one unreadable file added
    changed = root / "S01" / "S01_T1.mcap"
    run(changed, "phases", options={"phases": {"repetitions": 3, "static_margin_s": 0.1}}, progress=False)
    (root / "S02" / "S02_T2.mcap").unlink()
    (root / "S02" / "junk.mcap").write_bytes(b"junk")
    update = build_catalog(root, out)
    assert (update.read, update.reused, update.dropped, update.errors, update.rows) == (2, 2, 1, 1, 4)
    df = pd.read_parquet(out).set_index("path")
    row = df.loc[str(changed.resolve())]
    assert row["file_size"] == changed.stat().st_size
    runs = json.loads(row["runs_json"])
    assert runs[-1]["step"] == "phases:wrist" and runs[-1]["params"]["static_margin_s"] == 0.1
    assert df.loc[str((root / "S02" / "junk.mcap").resolve()), "error"].startswith("Archive")


def test_report_tables_and_plot(archive, tmp_path):
    root, paths = archive
    cat = tmp_path / "catalog.parquet"
    build_catalog(root, cat)
    out = tmp_path / "report"
    result = CliRunner().invoke(cli, ["report", str(cat), "-o", str(out)])
    assert result.exit_code == 0, result.output
    acc = pd.read_csv(out / "accuracy.csv")
    # recompute one cell straight from the trials: zupt, y axis, pooled over every repetition of every trial
    maes = []
    for p in paths:
        with TrialReader(p) as trial:
            maes += [r["y"]["mae_cm"] for r in trial.metadata["imulog.evaluation"]["methods"]["zupt"]["repetitions"]]
    cell = acc[(acc.method == "zupt") & (acc.axis == "y")].iloc[0]
    assert cell.n_repetitions == len(maes) == 12 and cell.n_subjects == 2 and cell.n_trials == 4
    assert cell.mae_cm_mean == pytest.approx(np.mean(maes)) and cell.mae_cm_std == pytest.approx(np.std(maes, ddof=1))
    md = (out / "accuracy.md").read_text()
    assert md.startswith("| method | MAE x (cm)")
    assert f"{np.mean(maes):.2f} ± {np.std(maes, ddof=1):.2f}" in md
    assert acc.groupby("method").size().to_dict() == {m: 3 for m in acc.method.unique()}
    # the drift-free methods beat double integration on every axis
    piv = acc.pivot(index="method", columns="axis", values="mae_cm_mean")
    assert (piv.loc["zupt"] < piv.loc["ddi"]).all()
    timing = pd.read_csv(out / "timing.csv")
    assert list(timing.label) == ["reach", "lift", "return_bottle", "return_hand"]
    assert (timing.n == 12).all() and (timing.duration_mean_s > 0.5).all() and (timing.duration_mean_s < 3).all()
    by_subject = pd.read_csv(out / "timing_by_subject.csv")
    assert set(by_subject.subject) == {"S01", "S02"} and (by_subject.n == 6).all()
    subj = pd.read_csv(out / "subject_errors.csv")
    assert set(subj.subject) == {"S01", "S02"} and (subj.n == 6).all()
    png = (out / "subject_errors.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert "subject_errors.png" in (out / "report.md").read_text()
    assert not math.isnan(cell.rom_pct_mean)


def test_report_without_matplotlib_says_so(archive, tmp_path, monkeypatch):
    cat = tmp_path / "catalog.parquet"
    build_catalog(archive[0], cat)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    result = CliRunner().invoke(cli, ["report", str(cat), "-o", str(tmp_path / "r")])
    assert result.exit_code != 0 and "matplotlib" in result.output and "--no-plots" in result.output
    tables = CliRunner().invoke(cli, ["report", str(cat), "-o", str(tmp_path / "t"), "--no-plots"])
    assert tables.exit_code == 0, tables.output
    assert (tmp_path / "t" / "accuracy.md").is_file() and not (tmp_path / "t" / "subject_errors.png").exists()


def test_report_keeps_each_imu_of_a_setup_apart():
    """The report pooled only the primary IMU's evaluation; a setup's other IMUs (per_imu) get rows of their own,
    never pooled with another segment's errors."""
    from imulog.batch.report import accuracy_table, repetition_errors

    def method(mae_cm):
        return {"repetitions": [{"repetition": 0, **{a: {"mae_cm": mae_cm, "rom_pct": 1.0} for a in "xyz"}}]}

    ev = {
        "imu": "/imu/upper_arm",
        "methods": {"zupt": method(1.0)},
        "per_imu": {"forearm": {"methods": {"zupt": method(3.0)}}},
    }
    df = pd.DataFrame(
        [{"path": "a.mcap", "subject": "S01", "trial": "T1", "evaluation_json": json.dumps(ev), "timing_json": None}]
    )
    table = {(r["method"], r["axis"]): r["mae_cm_mean"] for r in accuracy_table(df)}
    assert table[("zupt (upper_arm)", "y")] == 1.0 and table[("zupt (forearm)", "y")] == 3.0
    assert {r["method"] for r in repetition_errors(df)} == {"zupt (upper_arm)", "zupt (forearm)"}
    single = df.assign(evaluation_json=json.dumps({"imu": "/imu/wrist", "methods": {"zupt": method(2.0)}}))
    assert {r["method"] for r in accuracy_table(single)} == {"zupt"}  # one IMU: labels as before


def test_catalog_gives_every_imu_of_a_setup_its_alignment(tmp_path):
    """A setup aligned as a whole (upper arm, forearm, trunk on one station clock, markers): the catalog read only
    ``imulog.alignment`` (the first IMU's), so the table had no clock nor grade for the other IMUs."""
    from imulog.archive import write_trial
    from imulog.process.alignment_clock import device_to_reference
    from imulog.simulate.setup import simulate_setup

    sim = simulate_setup(seed=0, duration_s=40.0)  # (on 30 s the two clusters' windows scatter 3.4 ms: poor)
    path = write_trial(tmp_path / "setup.mcap", sim.recording, attach_sources=False)
    aligned = CliRunner().invoke(cli, ["process", "align", str(path)])
    assert aligned.exit_code == 0, aligned.output
    out = tmp_path / "catalog.parquet"
    build_catalog(tmp_path, out)
    row = pd.read_parquet(out).iloc[0]
    with TrialReader(path) as trial:
        meta = trial.metadata
    recs = {n: meta[f"imulog.alignment.{n}"] for n in ("upper_arm", "forearm", "trunk")}
    assert (row.n_imus, row.n_imus_aligned) == (3, 3)
    assert row.n_imus_aligned_good == sum(r["quality"] == "good" for r in recs.values()) >= 2
    per_imu = json.loads(row.alignment_imus_json)
    assert set(per_imu) == set(recs)
    for name, rec in recs.items():
        got = per_imu[name]
        assert (got["offset_ns"], got["drift_ppm"], got["quality"]) == (
            rec["offset_ns"],
            rec["drift_ppm"],
            rec["quality"],
        )
        t = next(s.t_ns for s in sim.recording.imus if s.name == name)
        assert np.array_equal(device_to_reference(t, got), device_to_reference(t, rec))  # the whole clock
        lag_error = np.max(np.abs(device_to_reference(t, got) - device_to_reference(t, sim.alignment)))
        # each IMU's clock from the table within the grade's tolerance (3 ms) of the truth over the whole trial
        print(f"{name}: catalog clock against the truth, max lag error {lag_error / 1e6:.3f} ms")
        assert lag_error < 3_000_000, (name, lag_error)
    # no cluster: the clock of the other two, said so
    assert per_imu["trunk"]["quality"] == "poor" and per_imu["trunk"]["clock_of"] == ["upper_arm", "forearm"]
    duckdb = pytest.importorskip("duckdb")
    got = duckdb.sql(
        f"select cast(json_extract(alignment_imus_json, '$.forearm.drift_ppm') as double) from '{out}'"
    ).fetchall()[0][0]
    assert got == pytest.approx(recs["forearm"]["drift_ppm"])
