"""The phases step window by window: a recording cut into windows gives the movements, phases, static mask and
timing rows of the same recording computed as one window (every method and protocol that runs beyond one)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from imulog.converters import axivity

from imulog.archive import TrialReader
from imulog.archive.streaming import write_trial_streaming
from imulog.process.segmentation.boundaries import white_noise_rad_s
from imulog.process.segmentation.dynamos import runs
from imulog.process.segmentation.reduce import (
    NoiseHistogram,
    exact_median_below,
    second_differences,
    threshold_runs,
)
from imulog.simulate.home import HomeParams, write_home_cwa
from imulog.steps.phases import run_phases
from imulog.steps.phases_store import NormFile
from imulog.steps.phases_windows import PhaseWindows

IMU = "ax6_4321"


def test_threshold_runs_join_across_chunks():
    rng = np.random.default_rng(1)
    x = rng.random(5000)
    x[1000:2600] = 2.0  # one run across several chunks
    x[2999] = 2.0  # a run ending exactly at a chunk's end
    x[3000:3004] = 2.0  # ... continued by the next chunk
    x[-1] = 2.0  # the recording's last sample
    whole = runs(x > 0.9)
    cuts = [0, 700, 1200, 1201, 1900, 3000, 4999, 5000]
    chunks = [(a, x[a:b]) for a, b in zip(cuts[:-1], cuts[1:], strict=True)] + [(5000, np.zeros(0))]
    got = threshold_runs(iter(chunks), 0.9)
    np.testing.assert_array_equal(got[0], whole[0])
    np.testing.assert_array_equal(got[1], whole[1])


def test_noise_histogram_matches_white_noise():
    rng = np.random.default_rng(2)
    lsb = 0.061 * np.pi / 180  # a quantised gyroscope (AX6 at 2000 deg/s): the medians are exact
    g = np.round((rng.normal(0, 0.004, (30_000, 3)) + 0.3 * np.sin(np.arange(30_000) / 300)[:, None]) / lsb) * lsb
    h = NoiseHistogram(0.5)
    for a, b in [(0, 7000), (7000, 7001), (7001, 30_000)]:  # pieces, each centre counted once
        h.add(second_differences(g, a, b, a == 0, b == 30_000))
    assert h.white_noise() == pytest.approx(white_noise_rad_s(g), rel=1e-9)
    cont = rng.normal(0, 0.003, (20_000, 3))  # continuous values: within a bin width
    h = NoiseHistogram(0.5)
    h.add(second_differences(cont, 0, 20_000, True, True))
    assert abs(h.white_noise() - white_noise_rad_s(cont)) < 2 * h.width


def test_exact_median_below(tmp_path):
    rng = np.random.default_rng(3)
    x = np.abs(rng.normal(0, 1, 100_001))
    f = NormFile(tmp_path)
    for a in range(0, len(x), 30_000):
        f.append(x[a : a + 30_000])
    np.testing.assert_array_equal(f[500:900], x[500:900])
    for thr in (0.7, 5.0):
        assert exact_median_below(f, thr) == np.median(x[x < thr])
    f.close()


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    folder = tmp_path_factory.mktemp("longphases")
    cwa = folder / "home.cwa"
    write_home_cwa(cwa, HomeParams(days=0.03, seed=4, start="2024-03-04T09:40:00"))  # 43 min at 100 Hz
    return write_trial_streaming(folder / "home.mcap", axivity.iter_chunks(cwa, blocks_per_chunk=300))


@pytest.fixture(scope="module")
def whole(trial, tmp_path_factory):
    path = tmp_path_factory.mktemp("whole") / "whole.mcap"
    shutil.copy(trial, path)
    run_phases(path)
    return path


def _read(path):
    with TrialReader(path) as t:
        return (
            t.read(f"/derived/movements/{IMU}"),
            t.read(f"/derived/phases/{IMU}"),
            t.read(f"/derived/static/{IMU}"),
            t.metadata["imulog.timing"],
        )


def _logs(path, kind):
    """(log time, text) of the foxglove.Log twin of /derived/{kind}/{IMU}; the channel must exist once."""
    from mcap.reader import make_reader

    topic = f"/derived/viewer/{kind}/{IMU}"
    with TrialReader(path) as t:
        assert [c.topic for c in t.channels].count(topic) == 1
    from imulog.archive._generated.foxglove import Log_pb2

    with open(path, "rb") as f:
        return [
            (m.log_time, Log_pb2.Log.FromString(m.data).message)
            for _, _, m in make_reader(f).iter_messages(topics=[topic])
        ]


def test_cores_equal_the_whole(trial, whole, tmp_path, monkeypatch):
    """Small cores (7 min), and intervals written in pieces of 37, give the whole computation's movements, phases and static mask to the sample: the norm
    filtered core by core differs from the whole filtering by rounding only (the overlap covers the filters'
    reach), and every statistic the whole computation takes over the recording comes from a first pass."""
    import imulog.steps.phases_windows as phases_windows

    monkeypatch.setattr(phases_windows, "INTERVAL_PIECE", 37)
    cored = tmp_path / "cored.mcap"
    shutil.copy(trial, cored)
    run_phases(cored, windows=PhaseWindows(core_s=420.0, margin_s=30.0, context_s=600.0))
    mw, pw, sw, tw = _read(whole)
    mc, pc, sc, tc = _read(cored)
    assert len(mw) > 100
    for a, b in ((mw, mc), (pw, pc)):
        np.testing.assert_array_equal(a.start_ns, b.start_ns)
        np.testing.assert_array_equal(a.end_ns, b.end_ns)
        np.testing.assert_array_equal(a.task_index, b.task_index)
        assert a.labels == b.labels
    np.testing.assert_array_equal(sw.t_ns, sc.t_ns)
    np.testing.assert_array_equal(sw.values, sc.values)
    assert tc["n_movements"] == tw["n_movements"] and tc["static_fraction"] == tw["static_fraction"]
    # intervals written in pieces get the foxglove.Log twins the whole writes, once each, also after a rerun
    run_phases(cored, windows=PhaseWindows(core_s=420.0, margin_s=30.0, context_s=600.0), force=True)
    for kind in ("movements", "phases"):
        assert _logs(cored, kind) == _logs(whole, kind) and len(_logs(whole, kind)) == len(
            mw if kind == "movements" else pw
        )
    with TrialReader(cored) as t:  # the replaced channels' closing statistics went with them
        stats = [x.name for x in t.summary.metadata_indexes if x.name.startswith("imulog.channel_stats.")]
        assert len(stats) == 1 and stats[0] == t.channel(f"/derived/static/{IMU}").metadata["stats_record"]
    # the record: the same row per phase, and the summaries
    assert tc["phases"] == tw["phases"] and tc["repetition_quality"] == tw["repetition_quality"]
    assert "window by window" in tc["computed"] and "computed" not in tw
    durations = np.array([row["duration_s"] for row in tw["phases"]])
    assert tc["phase_durations"]["n"] == len(durations)
    assert tc["phase_durations"]["median_s"] == pytest.approx(np.median(durations), abs=1e-3)
    assert sum(tc["phase_durations"]["histogram"]["counts"]) == len(durations)
    assert sum(row["phases"] for row in tc["by_hour"]) == tc["n_phases"]
    assert [row["start"] for row in tc["by_hour"]] == ["2024-03-04T09:00:00", "2024-03-04T10:00:00"]
    assert sum(row["recorded_s"] for row in tc["by_hour"]) == pytest.approx(len(sw.t_ns) / tc["rate_hz"], abs=0.1)


def test_movement_across_a_core_boundary_is_found_once(trial, whole, tmp_path):
    mw, pw, sw, _ = _read(whole)
    t0 = int(sw.t_ns[0])
    dur = mw.end_ns - mw.start_ns
    k = int(np.argmax(np.where(mw.start_ns - t0 > 300e9, dur, 0)))  # a long movement after 5 min
    assert dur[k] > 2e9
    boundary = int(np.searchsorted(sw.t_ns, (mw.start_ns[k] + mw.end_ns[k]) // 2))  # a core boundary inside it
    rate = (len(sw.t_ns) - 1) / ((sw.t_ns[-1] - t0) * 1e-9)
    cored = tmp_path / "boundary.mcap"
    shutil.copy(trial, cored)
    run_phases(cored, windows=PhaseWindows(core_s=boundary / rate, margin_s=30.0))
    mc, pc, _, _ = _read(cored)
    inside = (mc.start_ns <= sw.t_ns[boundary]) & (mc.end_ns >= sw.t_ns[boundary])
    assert inside.sum() == 1
    assert (mc.start_ns[inside][0], mc.end_ns[inside][0]) == (mw.start_ns[k], mw.end_ns[k])
    assert len(mc) == len(mw) and len(pc) == len(pw)
    assert np.all(np.diff(pc.start_ns) > 0)


def test_whole_signal_methods_are_refused_beyond_one_window(trial, tmp_path):
    from dataclasses import replace

    from imulog.process.segmentation.pipeline import PhaseParams

    cored = tmp_path / "refused.mcap"
    shutil.copy(trial, cored)
    for method in ("template", "double-threshold"):
        params = replace(PhaseParams(), protocol="movements", method=method)
        with pytest.raises(
            ValueError, match=f"method {method} detects movements on the whole signal .*--method dynamos"
        ):
            run_phases(cored, params=params, windows=PhaseWindows(core_s=600.0))
    with TrialReader(cored) as t:
        assert f"/derived/phases/{IMU}" not in t.topics()


@pytest.fixture(scope="module")
def r2g_trial(tmp_path_factory):
    from imulog.archive import write_trial
    from imulog.simulate import simulate

    sim = simulate("r2g", seed=3, subject=2, repetitions=6, extra_submovement_probability=0.3)
    return write_trial(tmp_path_factory.mktemp("r2g") / "r2g.mcap", sim.recording, attach_sources=False)


@pytest.mark.parametrize(
    "change",
    [
        {},
        {"dynamos": {"threshold": "otsu"}},
        {"static": "gyro-norm"},
        {"repetitions": {"split": "activity"}},
        {"protocol": "movements", "static_margin_s": 0.1},
    ],
    ids=["r2g", "otsu", "gyro-norm", "activity-split", "movements"],
)
def test_windows_equal_one_window_for_every_protocol(r2g_trial, tmp_path, change):
    """A drinking-task trial cut into 20-s cores gives the event-corrected phases, their
    confidence, the movements and the static mask of the trial computed as one window."""
    from dataclasses import replace

    from imulog.process.segmentation.dynamos import DynamosParams
    from imulog.process.segmentation.pipeline import PhaseParams
    from imulog.process.segmentation.repetitions import RepetitionParams

    reps = RepetitionParams(n_repetitions=6, **change.get("repetitions", {}))
    params = replace(PhaseParams(), repetitions=reps, dynamos=DynamosParams(**change.get("dynamos", {})))
    params = replace(params, **{k: v for k, v in change.items() if k not in ("repetitions", "dynamos")})
    one, cut = tmp_path / "one.mcap", tmp_path / "cut.mcap"
    shutil.copy(r2g_trial, one)
    shutil.copy(r2g_trial, cut)
    run_phases(one, imu="wrist", params=params)
    run_phases(cut, imu="wrist", params=params, windows=PhaseWindows(core_s=20.0, margin_s=10.0))
    with TrialReader(one) as t1, TrialReader(cut) as t2:
        assert "windows" in t2.runs()[max(t2.runs())]["params"] and "windows" not in t1.runs()[max(t1.runs())]["params"]
        for kind in ("movements", "phases"):
            a, b = t1.read(f"/derived/{kind}/wrist"), t2.read(f"/derived/{kind}/wrist")
            np.testing.assert_array_equal(a.start_ns, b.start_ns)
            np.testing.assert_array_equal(a.end_ns, b.end_ns)
            assert a.labels == b.labels and a.task_index.tolist() == b.task_index.tolist()
        s1, s2 = t1.read("/derived/static/wrist"), t2.read("/derived/static/wrist")
        np.testing.assert_array_equal(s1.values, s2.values)
        r1, r2 = t1.metadata["imulog.timing"], t2.metadata["imulog.timing"]
    assert r1["phases"] == r2["phases"] and r1["repetition_quality"] == r2["repetition_quality"]
    assert r1["n_phases"] == r2["n_phases"] > 0 and r1["static_fraction"] == r2["static_fraction"]
    if params.protocol == "r2g":
        assert r1["n_phases"] == 24 and r1["mean_confidence"] == r2["mean_confidence"]


def test_cli_prints_the_summary_of_a_recording_in_windows(trial, tmp_path, monkeypatch):
    from click.testing import CliRunner

    import imulog.steps.phases as step
    from imulog.cli import cli

    cored = tmp_path / "cli.mcap"
    shutil.copy(trial, cored)
    monkeypatch.setattr(step, "PhaseWindows", lambda: PhaseWindows(core_s=600.0))  # this 43-min trial: 5 windows
    result = CliRunner().invoke(cli, ["process", "phases", str(cored)])
    assert result.exit_code == 0, result.output
    assert "window by window" in result.output and "phases per hour" in result.output
    assert len(result.output.splitlines()) < 20  # no line per phase


def test_rest_windows_cut_at_rests_keep_repetitions_and_flag_long_stretches():
    from imulog.steps.windows import RestWindow, rest_windows

    rests = [(0, 100), (300, 400), (700, 800), (1500, 1600)]
    assert rest_windows(rests, 2000, 1.0, core_s=3000) == [RestWindow(0, 0, 2000, 0, 2000)]  # one core: whole
    w = rest_windows(rests, 2000, 1.0, core_s=500, max_s=300)
    assert [(x.lo, x.hi, x.core_lo, x.core_hi, x.split) for x in w[:2]] == [
        (0, 400, 0, 350, False),  # read to the end of the rest after, own to its middle
        (300, 800, 350, 750, False),
    ]
    assert all(x.split for x in w[2:])  # 700 s without a rest (max 300 s): cut and flagged
    assert [x.core_lo for x in w[1:]] == [x.core_hi for x in w[:-1]] and w[-1].core_hi == 2000
    kept = rest_windows(rests, 2000, 1.0, core_s=500, max_s=300, keep_together=[(250, 750)])
    assert (kept[0].lo, kept[0].hi) == (0, 800)  # a repetition over the rest at 300-400: not cut there


def test_trajectory_window_by_window_equals_the_whole(trial, tmp_path):
    """A daily-life recording cut at rests into 10-min windows gives the whole computation's trajectories (each
    movement is reconstructed from its own rests), every sample once; no step refuses for length."""
    from imulog.steps.trajectory import run_trajectory
    from imulog.steps.trajectory_windows import TrajectoryWindows

    path, cut = _oriented_and_segmented_twice(trial, tmp_path)
    methods = ("zupt", "ddi")
    run_trajectory(path, methods=methods, windows=TrajectoryWindows(core_s=3600.0))  # one window: the whole
    run_trajectory(cut, methods=methods, windows=TrajectoryWindows(core_s=600.0))
    with TrialReader(path) as a, TrialReader(cut) as b:
        ra, rb = a.metadata["imulog.trajectory"], b.metadata["imulog.trajectory"]
        assert rb["windows"]["count"] >= 4 and "windows" not in ra and not rb["windows"]["skipped"]
        assert [r["start_ns"] for r in ra["repetitions"]] == [r["start_ns"] for r in rb["repetitions"]]
        for topic in ("/derived/trajectory/zupt", "/derived/trajectory/ddi", "/derived/trajectory_baseline/dedrift"):
            x, y = a.read(topic), b.read(topic)
            assert len(x.t_ns) > 10_000
            np.testing.assert_array_equal(x.t_ns, y.t_ns)  # every sample once, none lost at a cut
            np.testing.assert_allclose(x.values, y.values, atol=1e-6)
    short = tmp_path / "short.mcap"
    shutil.copy(path, short)
    run_trajectory(short, methods=methods, windows=TrajectoryWindows(core_s=600.0, max_s=5.0), force=True)
    with TrialReader(short) as t:
        assert t.metadata["imulog.trajectory"]["windows"]["split"]  # stretches over 5 s without a rest, flagged


def test_exact_median_below_narrows_to_few_values(tmp_path):
    """The values near the median are gathered in bounded memory: many close values, a run of equal zeros."""
    rng = np.random.default_rng(5)
    x = np.concatenate([np.zeros(40_000), 0.01 + 1e-7 * rng.random(150_000), rng.random(30_000)])
    rng.shuffle(x)
    f = NormFile(tmp_path)
    f.append(x)
    assert exact_median_below(f, 0.9, max_values=1000) == np.median(x[x < 0.9])
    f2 = NormFile(tmp_path)
    f2.append(np.concatenate([np.zeros(5000), [0.5, 0.7]]))  # the median is one of many equal values
    assert exact_median_below(f2, 0.9, max_values=10) == 0.0
    f.close()
    f2.close()


def test_trajectory_windows_records_merge_into_one():
    """Repetitions concatenated, rests summed, a method's failed checks kept with their reason and window count
    (what `imulog process trajectory` prints)."""
    from imulog.steps.trajectory import check_lines
    from imulog.steps.trajectory_windows import TrajectoryWindows, merge_records

    ok = {"ok": True, "failed": []}
    windows = [
        {"repetitions": [{"index": 1}], "rests": {"static_s": 2.0, "static_runs": 3}, "checks": {"zupt": ok}},
        {
            "repetitions": [{"index": 2}, {"index": 3}],
            "rests": {"static_s": 1.5, "static_runs": 1},
            "checks": {"zupt": {"ok": False, "failed": ["rests"], "why": "no rest", "suggest": "use ddi"}},
        },
    ]
    skipped = [{"start_ns": 0, "end_ns": 1, "why": "every repetition contains a gap"}]
    rec = merge_records(windows, skipped, [], TrajectoryWindows())
    assert [r["index"] for r in rec["repetitions"]] == [1, 2, 3]
    assert rec["rests"] == {"static_s": 3.5, "static_runs": 4}
    assert rec["windows"]["count"] == 3 and rec["windows"]["skipped"] == skipped
    assert rec["checks"]["zupt"]["windows_failed"] == 1
    assert check_lines(rec) == ["assumption failed: zupt: no rest; use ddi"]


def test_rest_windows_read_only_the_context_of_a_long_rest():
    """A night between two movements: each window reads ``context_s`` of it, rest-only windows of at most
    ``max_s`` own the middle; every sample is owned once (issue 24: memory did not stay bounded by a window)."""
    from imulog.steps.windows import rest_windows

    rests = [(0, 100), (300, 400), (600, 5600), (5800, 5900)]  # a 5000 s rest at 600-5600
    w = rest_windows(rests, 6000, 1.0, core_s=500, max_s=300, context_s=50)
    assert w[0].core_lo == 0 and w[-1].core_hi == 6000
    assert [x.core_lo for x in w[1:]] == [x.core_hi for x in w[:-1]]  # contiguous, each sample once
    assert max(x.hi - x.lo for x in w) <= 500 + 2 * 100  # no window reads the whole night
    middle = [x for x in w if x.lo >= 650 and x.hi <= 5550]
    assert sum(x.hi - x.lo for x in middle) == 5550 - 650 and all(x.hi - x.lo <= 300 for x in middle)
    assert all(x.lo == x.core_lo and x.hi == x.core_hi for x in middle)
    assert rest_windows(rests, 6000, 1.0, core_s=500, max_s=300) != w  # without context_s: as before


def test_trajectory_with_capped_rests_equals_the_whole(trial, tmp_path):
    """Rests read only 20 s beside each movement (rest-only windows for the rest of them): the trajectories of
    zupt are the whole computation's, every sample once."""
    from imulog.steps.trajectory import run_trajectory
    from imulog.steps.trajectory_windows import TrajectoryWindows

    path, cut = _oriented_and_segmented_twice(trial, tmp_path)
    run_trajectory(path, methods=("zupt",), windows=TrajectoryWindows(core_s=3600.0))
    run_trajectory(cut, methods=("zupt",), windows=TrajectoryWindows(core_s=600.0, context_s=20.0))
    with TrialReader(path) as a, TrialReader(cut) as b:
        rb = b.metadata["imulog.trajectory"]
        assert rb["windows"]["count"] >= 4 and not rb["windows"]["skipped"]
        assert [r["start_ns"] for r in a.metadata["imulog.trajectory"]["repetitions"]] == [
            r["start_ns"] for r in rb["repetitions"]
        ]
        for topic in ("/derived/trajectory/zupt", "/derived/trajectory_baseline/dedrift"):
            x, y = a.read(topic), b.read(topic)
            np.testing.assert_array_equal(x.t_ns, y.t_ns)
            np.testing.assert_allclose(x.values, y.values, atol=1e-6)


def _oriented_and_segmented_twice(trial, tmp_path):
    """Two copies of ``trial`` after orientation and phases (``traj.mcap``, ``cut.mcap``), for whole-vs-windowed runs."""
    from imulog.steps.orientation import run_orientation

    path = tmp_path / "traj.mcap"
    shutil.copy(trial, path)
    run_orientation(path)
    run_phases(path)
    cut = tmp_path / "cut.mcap"
    shutil.copy(path, cut)
    return path, cut
