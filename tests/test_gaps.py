"""Missing IMU samples (NaN runs): one rule (imulog.process.gaps) applied by every step, recorded in provenance.

Short gaps (<= 5 samples) are bridged linearly and counted; longer gaps split the signal: filters restart, outputs
are NaN inside the gap, a repetition that contains one is not reconstructed. Tested on the pure functions and on
a simulated drinking trial with a 3-sample and a 0.5 s gap, processed by every step and compared with the same
trial without gaps.
"""

from __future__ import annotations

import numpy as np
import pytest

from imulog.archive import TrialReader, write_trial
from imulog.process import quaternion as qmath
from imulog.process.gaps import GapParams, per_run, prepare, runs_of, valid_mask
from imulog.simulate import simulate
from imulog.steps.align import run_align
from imulog.steps.metrics import run_metrics
from imulog.steps.orientation import run_orientation
from imulog.steps.phases import run_phases
from imulog.steps.trajectory import compute_trajectories, run_trajectory


# ---------------------------------------------------------------------------------------------- pure rule
def test_short_gaps_bridged_long_gaps_split_edges_never_bridged():
    x = np.arange(40, dtype=float)[:, None] * np.array([[1.0, -2.0]])
    y = x.copy()
    y[0] = np.nan  # leading gap: no sample before it, never bridged
    y[10:13] = np.nan  # 3 samples: bridged
    y[20:26] = np.nan  # 6 samples: split
    (z,), report = prepare([y], GapParams(max_bridge_samples=5, min_run_samples=3))
    np.testing.assert_allclose(z[10:13], x[10:13])  # linear signal: the bridge is exact
    assert np.isnan(z[0]).all() and np.isnan(z[20:26]).all()
    assert report.runs == ((1, 20), (26, 40)) and report.bridged_gaps == 1 and report.bridged_samples == 3
    assert report.missing == 10 and report.skipped_samples == 7 and report.split
    d = report.as_dict()
    assert d["bridged_samples"] == 3 and d["runs"] == [[1, 20], [26, 40]]


def test_per_run_restarts_and_leaves_gaps_nan():
    v = np.ones(30)
    v[12:20] = np.nan
    (v2,), report = prepare([v], GapParams(max_bridge_samples=2, min_run_samples=5))
    (cum,) = per_run(lambda a: np.cumsum(a), report, v2)  # an integrator: restarts at each run
    assert cum[11] == 12 and np.isnan(cum[12:20]).all() and cum[20] == 1 and cum[-1] == 10
    with pytest.raises(ValueError, match="no valid run of at least 10 samples"):
        per_run(np.cumsum, prepare([np.full(8, np.nan)], GapParams())[1], np.full(8, np.nan))


def test_valid_mask_and_runs():
    a = np.array([[1.0, 2.0], [np.nan, 1.0], [3.0, 4.0]])
    b = np.array([1.0, 2.0, np.inf])
    assert valid_mask(a, None, b).tolist() == [True, False, False]
    assert runs_of(np.array([True, True, False, True])) == [(0, 2), (3, 4)]


# ------------------------------------------------------------------------------------------ every step
SHORT = 3  # samples
LONG_S = 0.5


def _process(path):
    run_orientation(path)
    run_align(path)
    run_phases(path)
    run_trajectory(path, methods=["zupt", "kalman"])
    run_metrics(path)
    with TrialReader(path) as trial:
        out = {t: trial.read(t) for t in trial.topics() if t.startswith(("/derived/", "/imu/"))}
        return out, trial.metadata, trial.runs()


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """The same 3-repetition trial without and with gaps (a 0.5 s one inside repetition 2's lift), processed."""
    tmp = tmp_path_factory.mktemp("gaps")
    sim = simulate("r2g", seed=0, repetitions=3)
    clean = write_trial(tmp / "clean.mcap", sim.recording)
    sim = simulate("r2g", seed=0, repetitions=3)
    imu = sim.recording.imus[0]
    t_ref = sim.truth.imu_t_ref_ns
    ph = sim.truth.phases
    lift2 = next(i for i, (lab, k) in enumerate(zip(ph.labels, ph.task_index, strict=True)) if (lab, k) == ("lift", 2))
    mid = int(np.searchsorted(t_ref, (ph.start_ns[lift2] + ph.end_ns[lift2]) // 2))
    n_long = int(round(LONG_S * 114.9))
    long_gap = (mid - n_long // 2, mid - n_long // 2 + n_long)
    short_at = int(np.searchsorted(t_ref, ph.start_ns[0])) - 200  # before the first repetition
    imu.gyr[short_at : short_at + SHORT] = np.nan  # e.g. lost packets
    imu.acc[long_gap[0] : long_gap[1]] = np.nan
    imu.gyr[long_gap[0] : long_gap[1]] = np.nan
    gapped = write_trial(tmp / "gaps.mcap", sim.recording)
    return _process(clean), _process(gapped), long_gap, short_at


def _gaps_of(runs: dict, step: str) -> dict:
    return next(r["gaps"] for r in runs.values() if r["step"].split(":")[0] == step)


def test_orientation_restarts_after_a_long_gap_and_keeps_the_heading(processed):
    (clean, _, _), (gapped, _, runs), (g0, g1), short_at = processed
    q, q0 = gapped["/derived/orientation/wrist"].values, clean["/derived/orientation/wrist"].values
    assert np.isnan(q[g0:g1]).all() and np.isfinite(np.delete(q, np.s_[g0:g1], axis=0)).all()
    gaps = _gaps_of(runs, "orientation")
    assert gaps["bridged_samples"] == SHORT and gaps["runs"] == [[0, g0], [g1, len(q)]]
    err = np.degrees(qmath.angle_between(q, q0))
    assert np.nanmedian(err[:g0]) < 0.5
    # after the gap the heading continues from before it: the only error left is the heading change that happened
    # inside the gap (unknowable without samples; 12 deg in this lift), not an arbitrary restart heading
    turned = np.degrees(qmath.angle(qmath.heading_offset(q0[g1 : g1 + 1], q0[g0 - 1 : g0])[None]))[0]
    assert turned > 5 and np.nanmedian(err[g1 + 230 :]) == pytest.approx(turned, abs=1.0)


def test_phases_see_no_movement_through_a_gap_and_mark_static_unknown(processed):
    (clean, meta0, _), (gapped, meta, runs), (g0, g1), _ = processed
    static = gapped["/derived/static/wrist"].values[:, 0]
    assert np.isnan(static[g0:g1]).all() and np.isfinite(np.delete(static, np.s_[g0:g1])).all()
    assert meta["imulog.timing"]["gaps"]["runs"] == _gaps_of(runs, "phases")["runs"]
    assert meta["imulog.timing"]["n_phases"] == meta0["imulog.timing"]["n_phases"] == 12
    p, p0 = gapped["/derived/phases/wrist"], clean["/derived/phases/wrist"]
    other = p.task_index != 2  # phases of the repetitions without a gap are where they were
    assert np.abs(p.start_ns[other] - p0.start_ns[other]).max() < 20e6
    t_gap = gapped["/imu/wrist"].t_ns[[g0, g1 - 1]]
    t_ref = meta["imulog.alignment"]
    assert t_ref  # phases are on the reference clock; no movement spans the device-clock gap
    mv = gapped["/derived/movements/wrist"]
    from imulog.process.alignment import device_to_reference

    a, b = device_to_reference(t_gap, meta["imulog.alignment"])
    assert not np.any((mv.start_ns < a) & (mv.end_ns > b))


def test_trajectory_leaves_out_the_repetition_with_a_gap_and_keeps_the_others(processed):
    """The step's rule alone: the clean trial's inputs with the gap cut into the gravity-free acceleration."""
    (clean, meta0, _), (gapped, meta, runs), (g0, g1), _ = processed
    acc = clean["/derived/acc_global/wrist"]
    static, orient = clean["/derived/static/wrist"], clean["/derived/orientation/wrist"]
    kwargs = dict(
        imu="wrist",
        methods=["zupt", "kalman"],
        static=(static.t_ns, static.values[:, 0]),
        phases=clean["/derived/phases/wrist"],
        orientation=(orient.t_ns, orient.values),
        alignment=meta0["imulog.alignment"],
        anthropometrics=meta0.get("imulog.anthropometrics"),
    )
    ref, rec0 = compute_trajectories(acc.t_ns, acc.values, **kwargs)
    cut = acc.values.copy()
    cut[g0:g1] = np.nan
    cut[100:103] = np.nan  # bridged
    out, rec = compute_trajectories(acc.t_ns, cut, **kwargs)
    assert rec["gaps"]["repetitions_left_out"] == [2] and rec["gaps"]["bridged_samples"] == 3
    assert [r["index"] for r in rec["repetitions"]] == [1, 3] and "gaps" not in rec0
    for s, s0 in zip(out, ref, strict=True):
        kept = np.isin(s0.t_ns, s.t_ns)
        assert 0 < kept.sum() < len(s0.t_ns)  # repetition 2 is missing, 1 and 3 are there ...
        np.testing.assert_allclose(s.values, s0.values[kept], atol=1e-9)  # ... unchanged


def test_trajectory_step_records_the_left_out_repetition(processed):
    """Through the whole chain: the repetitions without a gap stay within 4 cm of the trial without gaps (the
    alignment's global-to-world rotation shifts by a few degrees because of the heading change in the gap)."""
    (clean, _, _), (gapped, meta, runs), _, _ = processed
    assert meta["imulog.trajectory"]["gaps"]["repetitions_left_out"] == [2]
    assert _gaps_of(runs, "trajectory")["repetitions_left_out"] == [2]
    for r in meta["imulog.trajectory"]["repetitions"]:
        tr, tr0 = gapped["/derived/trajectory/zupt"], clean["/derived/trajectory/zupt"]
        sel = (tr.t_ns >= r["start_ns"]) & (tr.t_ns <= r["end_ns"])
        sel0 = (tr0.t_ns >= r["start_ns"]) & (tr0.t_ns <= r["end_ns"])
        n = min(sel.sum(), sel0.sum())
        assert n > 1000 and np.abs(tr.values[sel][:n] - tr0.values[sel0][:n]).max() < 0.04


def test_metrics_leave_the_gap_out_of_usage_and_distance(processed):
    (clean, meta0, _), (gapped, meta, runs), (g0, g1), short_at = processed
    rec, rec0 = meta["imulog.metrics"], meta0["imulog.metrics"]
    assert rec["gaps.missing_samples"] == g1 - g0 and _gaps_of(runs, "metrics")["runs"][1][0] == g1
    assert rec["arm_usage.overall_percent"] == pytest.approx(rec0["arm_usage.overall_percent"], abs=1.0)
    d = gapped["/derived/metrics/distance/wrist"].values[:, 0]
    assert np.isnan(d[g0:g1]).all() and np.isfinite(d[:g0]).all()
    assert sum(rec["distance.histogram_percent"]) == pytest.approx(100.0)
