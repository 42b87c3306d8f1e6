"""Issue 32 end to end on a simulated stand-in for the held-out chain recording: a hand-moved 5-segment chain,
one IMU per segment at 40 Hz in ONE CSV without a time column, four markers per segment at 30 Hz in another CSV
with one column per marker axis (``seg1_marker1_x``, ...), still only at the start, the end and once for 0.3 s.

Each segment is the simulator's ``continuous`` protocol (its own seed; one shared clock for the five IMUs, as in
one file). Through the command line only: convert with one mapping file beside each CSV, then per segment
orientation, align (the cluster found among all 20 markers), phases, trajectory and evaluate."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.simulate.chain import IMU_HZ, MARKER_HZ, SEGMENTS, write_chain


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    folder = tmp_path_factory.mktemp("chain")
    imu_csv, mk_csv, sims = write_chain(folder)
    out = folder / "chain.mcap"
    res = CliRunner().invoke(cli, ["convert", str(imu_csv), str(mk_csv), "-o", str(out)])
    assert res.exit_code == 0, res.output
    return folder, out, sims


def test_the_chain_files_have_the_recordings_shape(chain):
    folder, out, sims = chain
    header = (folder / "chain_imu.csv").read_text().splitlines()[0].split(",")
    assert len(header) == SEGMENTS * 6 and not any("time" in h for h in header)
    mk_header = (folder / "chain_markers.csv").read_text().splitlines()[0].split(",")
    assert len(mk_header) == SEGMENTS * 4 * 3 and mk_header[0] == "seg1_marker1_x"
    # continuous motion: still only at the start, the end and once for 0.3 s
    static = sims[0].truth.imu_static_mask
    d = np.diff(np.concatenate([[0], static.astype(np.int8), [0]]))
    runs = (np.flatnonzero(d == -1) - np.flatnonzero(d == 1)) / IMU_HZ
    assert static.mean() < 0.35 and any(0.2 <= r <= 0.4 for r in runs)
    with TrialReader(out) as t:
        topics = t.topics()
        assert {f"/imu/seg{k}" for k in range(1, SEGMENTS + 1)} <= set(topics)
        mk = t.read("/markers/markers")
        assert len(mk.labels) == SEGMENTS * 4
        imu = t.read("/imu/seg1")
        assert abs(1e9 / np.median(np.diff(imu.t_ns)) - IMU_HZ) < 1e-6
        assert abs(1e9 / np.median(np.diff(mk.t_ns)) - MARKER_HZ) < 1e-3


@pytest.mark.parametrize("seg", range(1, SEGMENTS + 1))
def test_each_segment_through_the_pipeline_says_what_does_not_apply(chain, tmp_path, seg):
    _, out, _ = chain
    trial = tmp_path / f"seg{seg}.mcap"
    shutil.copyfile(out, trial)
    runner = CliRunner()
    imu = f"seg{seg}"

    def run(*args):
        res = runner.invoke(cli, list(args))
        assert res.exit_code == 0, (args, res.output)
        return res.output

    run("process", "orientation", str(trial), "--imu", imu)
    run("process", "align", str(trial), "--imu", imu, "--markers", "markers")
    with TrialReader(trial) as t:
        al = t.metadata["imulog.alignment"]
    found = [m.split(":")[-1] for m in al["cluster"]["markers"]]
    assert all(m.startswith(f"seg{seg}_") for m in found), found  # its own markers among all 20
    assert al["quality"] != "poor", (al["quality"], al.get("quality_reasons"))
    run("process", "phases", str(trial), "--imu", imu)
    out_traj = run("process", "trajectory", str(trial), "--imu", imu)
    # one line per rest-based method that says the true rests are missing (no rest for a stretch longer than
    # 15 s, or the few "rests" left imply a de-drift no sensor error explains: they are no rests) and what to do
    for m in ("zupt", "kalman", "zupt_bias"):
        lines = [x for x in out_traj.splitlines() if f"assumption failed: {m}:" in x]
        assert len(lines) == 1, out_traj
        assert "no rest boundary for" in lines[0] or "the rests are not rests" in lines[0], lines[0]
        assert "reconstruct between rests or use a reference" in lines[0] or "check the rests" in lines[0]
    with TrialReader(trial) as t:
        rec = t.metadata["imulog.trajectory"]
    # no accelerometer bias outside the sensor's range is used: a fit of the motion is refused, not applied
    errors = rec.get("accelerometer_errors")
    if errors is not None:
        # within the sensor's range (1 m/s^2, 5 %) once each element's own 3 standard errors are allowed for
        b = np.abs(errors["bias_mps2"]) - 3.0 * np.asarray(errors["bias_se_mps2"])
        e = np.abs(errors["matrix"]) - 3.0 * np.asarray(errors["matrix_se"])
        in_range = np.max(b) <= 1.0 and np.max(e) <= 0.05
        assert errors["applied"] is bool(in_range), errors
        if not in_range:
            assert "bias" in rec["checks"]["zupt_bias"]["failed"]
    for m in ("zupt", "kalman", "zupt_bias"):
        assert not rec["checks"][m]["ok"] and {"no_rest", "dedrift"} & set(rec["checks"][m]["failed"]), m
    # movements with no true rest between them are one window (a velocity reset only at each end)
    assert rec.get("merged_repetitions"), rec.keys()
    info = run("info", str(trial))
    assert "/derived/trajectory/zupt" in info and "[assumptions failed]" in info and "\nassumptions failed:\n" in info
    ev = run("evaluate", str(trial))
    assert "median x" in ev and "p90 x" in ev and "\ndedrift " in ev and "beats dedrift" in ev
    assert "warning: zupt: assumptions fail" in ev
    with TrialReader(trial) as t:
        e = t.metadata["imulog.evaluation"]
    assert e["baseline"] == "dedrift" and "dedrift" in e["methods"]
    for m in ("zupt", "dedrift"):
        for a in "xyz":
            fig = e["methods"][m]["summary"][a]
            assert {"median_cm", "p90_cm", "rom_cm"} <= set(fig) and fig["p90_cm"]["mean"] >= fig["median_cm"]["mean"]
    assert e["methods"]["zupt"]["assumptions"] == "failed"
