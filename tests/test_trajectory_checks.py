"""Issue 32: velocity resets only at true rests, every method checks its assumptions, robust evaluation with a
de-drift baseline, and alignment graded from residuals (not from the number of windows)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.process import trajectory_checks as tc
from imulog.process.alignment_quality import grade
from imulog.process.drift import HighpassParams, highpass
from imulog.process.evaluation import trajectory_errors
from imulog.process.rests import RestParams, true_rests
from imulog.process.trajectory_opt import DEFAULT_PARAMS, reconstruct
from imulog.simulate import simulate

RATE = 100.0


def _noise(n, sd=0.02, seed=0):
    return np.random.default_rng(seed).normal(0.0, sd, (n, 3))


def test_a_still_gyroscope_during_translation_is_not_a_rest():
    """2 s rest, 6 s translation (the wrist does not turn: a gyroscope-only mask calls it static), 2 s rest."""
    t = np.arange(0, 10, 1 / RATE)
    acc = _noise(len(t))
    moving = (t >= 2) & (t < 8)
    acc[moving, 0] += 0.8 * np.sin(2 * np.pi * 0.5 * (t[moving] - 2))  # 0.5 Hz back and forth
    gyro_static = np.ones(len(t), bool)
    rests = true_rests(gyro_static, acc, RATE)
    assert rests[(t < 1.5) | (t > 8.5)].all()  # the true rests stay rests (but for the long window's half
    assert rests[(t < 1.8) | (t > 8.2)].mean() > 0.9  # width next to the movement)
    assert rests[(t > 2.3) & (t < 7.7)].mean() < 0.1  # the translation is no rest
    # a slow glide (0.4 Hz, 0.5 m/s^2) varies little within 0.25 s; the second, longer window cut to the
    # candidate rest sees it
    slow = _noise(len(t), seed=1)
    slow[moving, 1] += 0.5 * np.sin(2 * np.pi * 0.4 * (t[moving] - 2))
    assert true_rests(gyro_static, slow, RATE)[(t > 3) & (t < 7)].mean() < 0.1
    short = dataclasses.replace(RestParams(), long_window_s=None)
    assert true_rests(gyro_static, slow, RATE, short)[(t > 3) & (t < 7)].mean() > 0.3  # what it adds
    # a constant acceleration has no variation: only the (optional) mean limit tells it from a tilted rest
    push = _noise(len(t), seed=4)
    push[moving, 0] += 1.0
    assert true_rests(gyro_static, push, RATE)[(t > 3) & (t < 7)].mean() > 0.9
    with_mean = dataclasses.replace(RestParams(), max_mean_mps2=0.6)
    assert not true_rests(gyro_static, push, RATE, with_mean)[(t > 3) & (t < 7)].any()
    # a short true rest (0.3 s, a foot's stance) inside motion survives
    stance = _noise(len(t), seed=2)
    stance[:, 2] += 2.0 * np.sin(2 * np.pi * 1.0 * t)
    still = (t > 5) & (t < 5.3)
    stance[still, 2] = np.random.default_rng(3).normal(0.0, 0.02, still.sum())
    assert true_rests(still, stance, RATE)[still].mean() > 0.9


def test_a_rest_whose_orientation_drifts_stays_a_rest_and_a_glide_stays_none():
    """A gyroscope bias makes the filter's tilt drift during a rest, so the gravity-free acceleration ramps
    (5 deg/s: 0 -> 2.6 m/s^2 over 3 s) although the sensor is still; in its own frame the specific force is
    constant. With the orientation the gate keeps that rest; a glide (the translation of the first test, with the
    same drift) varies the specific force in both frames and stays no rest."""
    from imulog.process import quaternion as quat

    t = np.arange(0, 10, 1 / RATE)
    g = np.array([0.0, 0.0, 9.81])
    q = quat.from_rotation_vector(np.radians(5.0) * t[:, None] * np.array([1.0, 0.0, 0.0]))  # drifting estimate
    f_sensor = np.tile(g, (len(t), 1)) + _noise(len(t), seed=5)  # the still sensor measures gravity only
    acc = quat.rotate(q, f_sensor) - g  # what the trajectory step gets: gravity-free in the drifting frame
    gyro_static = np.ones(len(t), bool)
    assert true_rests(gyro_static, acc, RATE)[(t > 2) & (t < 8)].mean() < 0.5  # the drift alone: dropped
    assert true_rests(gyro_static, acc, RATE, orientation=q).all()
    moving = (t >= 2) & (t < 8)
    glide = f_sensor.copy()
    glide[moving, 0] += 0.5 * np.sin(2 * np.pi * 0.4 * (t[moving] - 2))  # along the drift axis: no cancelling
    acc_glide = quat.rotate(q, glide) - g
    assert true_rests(gyro_static, acc_glide, RATE, orientation=q)[(t > 3) & (t < 7)].mean() < 0.1
    # without a valid orientation the gate is the gravity-free one
    no_q = np.full_like(q, np.nan)
    np.testing.assert_array_equal(
        true_rests(gyro_static, acc, RATE, orientation=no_q), true_rests(gyro_static, acc, RATE)
    )


def test_movements_without_a_true_rest_between_them_are_one_window():
    """Two movements whose still-gyroscope pause is a translation: with the gyroscope's mask they are two
    windows, with the true rests both widen to the same rests and are merged (one reset at each end)."""
    from imulog.process.trajectory_opt import merge_overlapping, repetition_windows

    t = np.arange(0, 12, 1 / RATE)
    bounds = {1: np.array([[2.0, 4.0]]), 2: np.array([[6.0, 8.0]])}
    gyro = (t < 2.0) | ((t > 4.0) & (t < 6.0)) | (t > 8.0)
    rests = (t < 2.0) | (t > 8.0)  # the pause between them translates: no rest
    two, merged = merge_overlapping(repetition_windows(t, bounds, gyro))
    assert len(two) == 2 and not merged
    one, merged = merge_overlapping(repetition_windows(t, bounds, rests))
    assert len(one) == 1 and merged == [[1, 2]]
    assert rests[one[0].start] and rests[one[0].stop - 1] and not rests[one[0].start + 1 : one[0].stop - 1].all()


def test_rest_summary_and_the_one_line_why():
    t = np.arange(0, 70, 1 / RATE)
    rests = (t < 3) | (t > 67)  # the chain: still only at the start and the end
    summary = tc.rest_summary(t, rests, [(0, len(t))])
    assert summary["count"] == 2 and summary["longest_without_s"] == pytest.approx(64, abs=0.05)
    check = tc.assess("zupt", rests=summary)
    assert not check["ok"] and check["failed"] == ["no_rest"]
    assert tc.format_check("zupt", check) == (
        "zupt: no rest boundary for 64 s: dead reckoning drifts; reconstruct between rests or use a reference"
    )
    ok = tc.rest_summary(t, (t % 5) < 0.5, [(0, len(t))])
    assert tc.assess("zupt", rests=ok)["ok"] and ok["median_spacing_s"] == pytest.approx(5.0)
    attrs = tc.check_attrs(check)
    assert attrs["assumptions"] == "failed" and attrs["assumptions_why"].startswith("no rest boundary for 64 s")


def test_unphysical_bias_and_implausible_dedrift_are_flagged():
    assert not tc.bias_check({"bias_mps2": [0.1, 8.7, 0.0], "matrix": [[0.0] * 3] * 3})["ok"]
    assert tc.bias_check({"bias_mps2": [0.1, -0.3, 0.05], "matrix": [[0.01] * 3] * 3})["ok"]
    t = np.arange(0, 4, 1 / RATE)
    rests = (t < 1) | (t > 3)
    acc = np.zeros((len(t), 3))
    acc[~rests, 0] = 1.0  # accelerates and never decelerates: the "rest" after it is no rest
    check = tc.dedrift_check(tc.dedrift_offsets(t, acc, rests))
    assert not check["ok"] and check["max_offset_mps2"] == pytest.approx(1.0, rel=0.05)
    acc[~rests, 0] = np.sin(2 * np.pi * (t[~rests] - 1) / 2)  # one full cycle: back to zero velocity
    assert tc.dedrift_check(tc.dedrift_offsets(t, acc, rests))["ok"]


def test_highpass_reports_the_share_of_motion_it_removes():
    """A reach with a 4 s hold at the target (the drinking task's mouth): a 0.3 Hz high-pass pulls the hold
    back to zero, removing most of the motion's range; a fast back-and-forth loses little."""
    t = np.arange(0, 10, 1 / RATE)
    u = np.clip((t - 1) / 1.5, 0, 1)
    reach = 0.3 * (10 * u**3 - 15 * u**4 + 6 * u**5)[:, None] * np.ones(3)

    def filtered(x):
        y = highpass(x, RATE, HighpassParams())
        return y - y[0]  # as reconstruct() writes it: displacement from the window's start

    share = tc.removed_share(reach, filtered(reach))
    assert min(share) > 0.3
    env = np.sin(np.pi * np.clip((t - 1) / 8, 0, 1)) ** 2
    fast = (0.05 * env * np.sin(2 * np.pi * 2.0 * (t - 1)))[:, None] * np.ones(3)  # 2 Hz, far above 0.3 Hz
    assert max(tc.removed_share(fast, filtered(fast))) < 0.01
    assert not tc.assess("highpass", share=share)["ok"]


def test_dedrift_baseline_removes_a_constant_offset_between_the_window_ends():
    t = np.linspace(0, 5, 501)  # the reach ends exactly at the window's last sample
    u = t / 5
    true_acc = (60 * u - 180 * u**2 + 120 * u**3)[:, None] * np.array([0.2, -0.1, 0.05]) / 25  # min-jerk
    true_pos = (10 * u**3 - 15 * u**4 + 6 * u**5)[:, None] * np.array([0.2, -0.1, 0.05])
    pos = reconstruct("dedrift", t, true_acc + 0.05, None, params=DEFAULT_PARAMS)
    assert np.abs(pos - true_pos).max() < 1e-3
    ddi = reconstruct("ddi", t, true_acc + 0.05 * (t > 2.5)[:, None], None, params=DEFAULT_PARAMS)
    dd = reconstruct("dedrift", t, true_acc + 0.05 * (t > 2.5)[:, None], None, params=DEFAULT_PARAMS)
    assert np.abs(dd - true_pos).max() < np.abs(ddi - true_pos).max()


def test_robust_errors_and_error_larger_than_the_motion():
    ref = np.zeros((200, 3))
    ref[:, 0] = np.linspace(0, 0.10, 200)
    est = ref.copy()
    est[1:, 1] += 0.01  # (errors are taken relative to the first sample)
    est[190:, 1] += 0.2  # ten bad samples: the mean moves, the median does not
    r = trajectory_errors(est, ref)
    assert r["y"]["median_cm"] == pytest.approx(1.0) and r["y"]["mae_cm"] > 1.9
    assert r["y"]["p90_cm"] == pytest.approx(1.0, abs=1e-6) and r["x"]["rom_cm"] == pytest.approx(10.0)
    assert r["reach_cm"] == pytest.approx(10.0) and not r["exceeds_motion"]
    far = ref + np.array([0.0, 0.3, 0.0]) * np.linspace(0, 1, 200)[:, None]
    assert trajectory_errors(far, ref)["exceeds_motion"]


def test_evaluate_names_the_windows_whose_error_exceeds_the_motion_and_methods_that_do_not_beat_the_baseline():
    """Two 2-s windows of a 10 cm reach: ``zupt`` is 1 cm off in both, ``ddi`` drifts 30 cm in the second,
    the baseline is 2 cm off in both."""
    from imulog.steps.evaluate import compute_evaluation, warning_lines

    t_ns = np.arange(400, dtype=np.int64) * 10_000_000  # 100 Hz, 4 s
    ref = np.zeros((400, 3))
    ref[:, 0] = 0.10 * np.sin(np.pi * np.arange(400) / 200) ** 2  # out and back in each window
    ramp = np.concatenate([np.linspace(0, 1, 200)] * 2)[:, None]
    zupt = ref + 0.01 * ramp * np.array([0.0, 1.0, 0.0])
    ddi = ref + np.where(np.arange(400)[:, None] >= 200, 0.30 * ramp, 0.005 * ramp) * np.array([0.0, 0.0, 1.0])
    base = ref + 0.02 * ramp * np.array([1.0, 1.0, 1.0])
    windows = [
        {"index": 1, "start_ns": 0, "end_ns": int(t_ns[199])},
        {"index": 2, "start_ns": int(t_ns[200]), "end_ns": int(t_ns[-1])},
    ]
    rec = compute_evaluation(
        {"zupt": (t_ns, zupt), "ddi": (t_ns, ddi), "dedrift": (t_ns, base)},
        (t_ns, ref),
        reference_topic="/markers/cluster",
        windows=windows,
        baseline="dedrift",
    )
    assert rec["methods"]["ddi"]["exceeds_motion"] == [2] and rec["methods"]["zupt"]["exceeds_motion"] == []
    assert rec["methods"]["zupt"]["beats_baseline"] == {"x": True, "y": True, "z": True}
    assert rec["methods"]["ddi"]["beats_baseline"] == {"x": True, "y": True, "z": False}
    lines = warning_lines(rec)
    assert "ddi: the error exceeds the motion itself in 1 of 2 windows (2)" in lines
    assert not any(x.startswith("zupt:") for x in lines)
    rec["methods"]["ddi"]["beats_baseline"]["x"] = rec["methods"]["ddi"]["beats_baseline"]["y"] = False
    assert "ddi: no better than the dedrift baseline on any axis" in warning_lines(rec)


def test_continuous_simulation_has_exact_motion_and_gyroscope_still_glides():
    from imulog.process import quaternion as quat
    from imulog.simulate.protocols import continuous

    rng = np.random.default_rng(4)
    built = continuous.build(continuous.Params(duration_s=30.0), rng, rng)
    t = np.arange(0, built.end_s, 1e-3)
    k = built.plan.evaluate(t)
    assert np.abs(np.gradient(k.position, t, axis=0) - k.velocity)[5:-5].max() < 1e-4
    assert np.abs(np.gradient(k.velocity, t, axis=0) - k.acceleration)[5:-5].max() < 1e-2
    w = 2 * quat.multiply(quat.conjugate(k.orientation), np.gradient(k.orientation, t, axis=0))[:, 1:]
    assert np.abs(w - k.omega)[5:-5].max() < 1e-2
    glides = [i for i in built.plan.intervals if i.label == "glide"]
    assert len(glides) == 6
    for g in glides:  # the gyroscope is exactly still while the sensor translates
        sel = (t > g.start_s) & (t < g.end_s)
        assert np.abs(k.omega[sel]).max() == 0.0 and np.linalg.norm(k.velocity[sel], axis=1).max() > 0.02
    rest = next(i for i in built.plan.intervals if i.label == "rest")
    inside = (t > rest.start_s) & (t < rest.end_s)
    assert not k.moving[inside].any() and k.moving[(t > rest.end_s + 0.01) & (t < rest.end_s + 10)].all()


@pytest.fixture(scope="module")
def continuous_trial(tmp_path_factory):
    from imulog.steps.align import run_align
    from imulog.steps.orientation import run_orientation
    from imulog.steps.phases import run_phases

    sim = simulate("continuous", subject=1, seed=0)
    path = tmp_path_factory.mktemp("cont") / "continuous.mcap"
    write_trial(path, sim.recording)
    run_orientation(path)
    run_align(path)
    run_phases(path)
    return sim, path


def test_continuous_motion_resets_only_at_true_rests_and_says_why(continuous_trial):
    sim, path = continuous_trial
    runner = CliRunner()
    res = runner.invoke(cli, ["process", "trajectory", str(path)])
    assert res.exit_code == 0, res.output
    assert "still-gyroscope intervals are not rests" in res.output
    assert "assumption failed: highpass: removes" in res.output and "assumption failed: zupt_bias" in res.output
    with TrialReader(path) as t:
        rec = t.metadata["imulog.trajectory"]
        static = t.read(f"/derived/static/{sim.recording.imus[0].name}")
        meta = t.channel("/derived/trajectory/highpass").metadata
        assert "/derived/trajectory_baseline/dedrift" in t.topics()
    assert meta["assumptions"] == "failed" and "removes_motion" in meta["assumptions_failed"]
    # the zupt_bias estimate on continuous motion is not physical: refused, not applied
    assert rec["accelerometer_errors"]["applied"] is False and "bias" in rec["checks"]["zupt_bias"]["failed"]
    # false rests: gyroscope-static samples while the truth moves, before and after the accelerometer gate
    truth_static = sim.truth.imu_static_mask
    gyro = static.values[:, 0] > 0.5
    assert rec["rests"]["static_runs_not_rests"] > 10
    false_gyro = float((gyro & ~truth_static).sum())
    kept_s, given_s = rec["rests"]["rest_s"], rec["rests"]["static_s"]
    assert false_gyro / RATE > 5.0 and given_s - kept_s > 0.6 * false_gyro / len(gyro) * (given_s / gyro.mean())
    ev = runner.invoke(cli, ["evaluate", str(path)])
    assert ev.exit_code == 0, ev.output
    assert "median x" in ev.output and "p90 x" in ev.output and "beats dedrift" in ev.output
    assert "\ndedrift " in ev.output and "warning: highpass: assumptions fail: removes" in ev.output
    with TrialReader(path) as t:
        e = t.metadata["imulog.evaluation"]
    assert e["baseline"] == "dedrift" and set(e["methods"]["zupt"]["beats_baseline"]) == {"x", "y", "z"}
    assert e["methods"]["highpass"]["assumptions"] == "failed"


def test_drinking_trial_rests_are_kept_and_methods_pass_their_checks():
    """The drinking task rests between phases: the gate removes nothing inside the repetitions, so ZUPT is
    unchanged, and the rest-based methods' checks hold."""
    from imulog.process.orientation import estimate_orientation, gravity_free_acceleration
    from imulog.steps.trajectory import compute_trajectories

    sim = simulate("r2g", subject=1, seed=0, repetitions=4)
    imu, truth = sim.recording.imus[0], sim.truth
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) / 1e9)
    est = estimate_orientation(imu.gyr, imu.acc, rate)
    acc_g = gravity_free_acceleration(est.quat, imu.acc, est.static)
    kw = dict(
        imu="wrist",
        methods=["zupt", "kalman", "highpass"],
        static=(imu.t_ns, truth.imu_static_mask.astype(float)),
        phases=truth.phases,
        alignment=dict(truth.alignment),
    )
    on, rec = compute_trajectories(imu.t_ns, acc_g, **kw)
    off, _ = compute_trajectories(
        imu.t_ns, acc_g, params=dataclasses.replace(DEFAULT_PARAMS, rests=RestParams(enabled=False)), **kw
    )
    assert np.array_equal(on[0].values, off[0].values)
    assert rec["checks"]["zupt"]["ok"] and rec["checks"]["kalman"]["ok"], rec["checks"]
    assert rec["checks"]["zupt"]["rests"]["count"] >= 4 * 4
    assert not rec["checks"]["highpass"]["ok"]  # the 4 s hold at the mouth: most of the motion removed
    assert "merged_repetitions" not in rec


def _record(offsets_ms, width_s, drift=False, **kw):
    windows = [
        {"start_s": i * width_s, "width_s": width_s, "used": True, "offset_ns": int(o * 1e6)}
        for i, o in enumerate(offsets_ms)
    ]
    return {"score": 0.97, "cluster": {"vector_match": 0.99}, "windows": windows, "drift_estimated": drift, **kw}


LIMITS = dict(poor_score=0.8, poor_spread_s=0.003, poor_vector_match=0.9)


def test_alignment_grade_from_residuals_not_window_count():
    quality, reasons, notes = grade(_record([12.0, 12.4], 33.0), **LIMITS)  # a correct 66 s trial
    assert quality == "good" and not reasons and "1.6 ms" in notes[0]
    assert grade(_record([12.0, 17.5], 33.0), **LIMITS)[0] == "poor"  # the windows disagree by 5.5 ms
    assert grade(_record([12.0], 600.0), **LIMITS)[0] == "poor"  # 10 min in one window: 15 ms at the ends
    assert grade({**_record([12.0, 12.4], 33.0), "score": 0.6}, **LIMITS)[0] == "poor"
    wrong = {**_record([12.0, 12.4], 33.0), "cluster": {"vector_match": 0.5}}
    assert "vector match" in grade(wrong, **LIMITS)[1][0]


def test_wrong_alignment_of_a_short_trial_is_still_poor_and_a_correct_one_good():
    from imulog.process import alignment as al
    from imulog.steps.align import compute_alignment

    sim = simulate("r2g", seed=2, repetitions=2, extra_segments=("upper_arm",))
    imu, mk = sim.recording.imus[0], sim.recording.markers[0]
    _, rec = compute_alignment(
        "wrist", imu.t_ns, imu.gyr, mk.topic, mk.t_ns, mk.labels, mk.pos, al.AlignmentParams(), resample=False
    )
    err = np.abs(al.device_to_reference(imu.t_ns, rec) - sim.truth.imu_t_ref_ns).max()
    assert err < 2e6 and rec["quality"] == "good", (err, rec["quality_reasons"])
    arm = [m for m in mk.labels if "upper_arm" in m.lower() or m.lower().startswith(("ua", "arm"))]
    if len(arm) < 3:
        pytest.skip(f"no upper-arm markers among {mk.labels}")
    try:
        _, bad = compute_alignment(
            "wrist",
            imu.t_ns,
            imu.gyr,
            mk.topic,
            mk.t_ns,
            mk.labels,
            mk.pos,
            dataclasses.replace(al.AlignmentParams(), cluster="given", markers=tuple(arm[:4])),
            resample=False,
        )
    except ValueError:
        return  # refused outright: no marker moves like the IMU
    assert bad["quality"] == "poor", bad


def test_no_rest_at_all_says_so_in_one_line(tmp_path):
    """The held-out chain: still only at the start and the end. Every rest-based method says that the rests
    are missing and what would work; the baseline is reported beside them."""
    from imulog.steps.align import run_align
    from imulog.steps.orientation import run_orientation
    from imulog.steps.phases import run_phases

    path = tmp_path / "chain.mcap"
    write_trial(path, simulate("continuous", seed=3, rests=0, duration_s=40.0, glides=4).recording)
    run_orientation(path)
    run_align(path)
    run_phases(path)
    res = CliRunner().invoke(cli, ["process", "trajectory", str(path), "--method", "zupt,kalman,highpass"])
    assert res.exit_code == 0, res.output
    lines = [x for x in res.output.splitlines() if "assumption failed: zupt:" in x]
    assert len(lines) == 1, res.output
    longest = float(lines[0].split("no rest boundary for ")[1].split(" s")[0])
    # 40 s of motion with no true rest; a 0.5-s slow-down mid-glide (0.1-0.3 m/s) varies little but keeps
    # accelerating (0.7 m/s^2 on average): no rest (RestParams.run_mean; without it 28 s)
    assert longest >= 30 and "reconstruct between rests or use a reference" in lines[0]


def test_viewer_labels_a_trajectory_whose_assumptions_fail(continuous_trial, tmp_path):
    from rerun.chunk import RrdReader

    from imulog.view import layout as L

    _, path = continuous_trial
    runner = CliRunner()
    assert runner.invoke(cli, ["process", "trajectory", str(path), "--method", "zupt,highpass"]).exit_code == 0
    out = tmp_path / "continuous.rrd"
    res = runner.invoke(cli, ["view", str(path), "--save", str(out)])
    assert res.exit_code == 0, res.output
    # the error series' name in the plot says so (and the path's label when it is one strip)
    entity = L.error_entity("/derived/trajectory/highpass")
    text = [
        str(c.to_record_batch().to_pylist()) for c in RrdReader(out).stream().to_chunks() if c.entity_path == entity
    ]
    assert any("assumptions failed: removes_motion" in t for t in text), text[:1]
