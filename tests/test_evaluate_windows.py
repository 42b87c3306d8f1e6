"""The evaluate step window by window (issue 24): the per-repetition errors read span by span equal the whole
computation's on a simulated drinking trial, with the reference occluded around a span's edge."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from read_spy import record_reads
from test_trajectory_steps import _write_with_inputs

from imulog.archive import TrialReader
from imulog.model import SignalStream
from imulog.process.trajectory_opt import BASELINE
from imulog.simulate.core import simulate
from imulog.steps.evaluate import compute_evaluation, error_rows, interpolate_reference, read_reference, run_evaluate
from imulog.steps.evaluate_windows import spans_of, windowed_rows
from imulog.steps.trajectory import run_trajectory


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    sim = simulate("r2g", subject=1, seed=3, repetitions=5)
    path = tmp_path_factory.mktemp("evalwin") / "trial.mcap"
    _write_with_inputs(path, sim)
    run_trajectory(path)
    return path


def _whole(trial, channels, source, reps, max_gap_s=0.05):
    trajs = {m: (trial.read(t).t_ns, trial.read(t).values) for m, t in channels.items()}
    return compute_evaluation(
        trajs,
        read_reference(trial, source),
        reference_topic=source,
        windows=reps,
        max_gap_s=max_gap_s,
        baseline=BASELINE,
    )


def test_spans_group_consecutive_repetitions_within_the_span():
    reps = [{"start_ns": int(a * 1e9), "end_ns": int((a + 2) * 1e9)} for a in (0, 3, 10, 11, 30)]
    assert [len(g) for g in spans_of(reps, 12.0)] == [3, 1, 1]  # 0-12 s; 11-13 would make it 13 s; 30-32 alone
    assert [len(g) for g in spans_of(reps, 1.0)] == [1] * 5  # a repetition longer than the span is its own


@pytest.mark.parametrize("span_s", [0.5, 7.0, 1e9])
def test_windowed_rows_equal_the_whole(evaluated, span_s):
    with TrialReader(evaluated) as trial:
        reps = trial.metadata["imulog.trajectory"]["repetitions"]
        topics = trial.topics()
        channels = {m: f"/derived/trajectory/{m}" for m in ("ddi", "zupt", "optimized")}
        channels = {m: t for m, t in channels.items() if t in topics}
        channels[BASELINE] = f"/derived/trajectory_baseline/{BASELINE}"
        assert len(reps) >= 4 and len(channels) >= 3
        source = "/markers/vicon:O"
        whole = _whole(trial, channels, source, reps)
        rows = windowed_rows(trial, channels, source, reps, 0.05, error_rows, interpolate_reference, span_s=span_s)
    for m in channels:
        assert len(rows[m]) == len(whole["methods"][m]["repetitions"]) == len(reps)
        for a, b in zip(rows[m], whole["methods"][m]["repetitions"], strict=True):
            assert a == b  # the same floats: the same samples and interpolation


def test_step_record_equals_the_whole_and_an_occluded_edge(evaluated, tmp_path):
    """The step (windowed) gives the whole computation's record; with the reference missing for 2 s before a
    repetition (so the first valid sample of its span follows a long gap) the rows still match."""
    path = tmp_path / "occluded.mcap"
    shutil.copy(evaluated, path)
    _, record = run_evaluate(path, force=True)
    with TrialReader(path) as trial:
        reps = trial.metadata["imulog.trajectory"]["repetitions"]
        channels = {m: f"/derived/trajectory/{m}" for m in record["methods"] if m != BASELINE}
        channels[BASELINE] = f"/derived/trajectory_baseline/{BASELINE}"
        whole = _whole(trial, channels, record["reference"], reps)
    assert record["methods"].keys() == whole["methods"].keys()
    for m in whole["methods"]:
        assert record["methods"][m]["repetitions"] == whole["methods"][m]["repetitions"]
        assert record["methods"][m]["summary"] == whole["methods"][m]["summary"]
    # an occlusion that ends exactly on a trajectory sample inside the second repetition's span
    with TrialReader(path) as trial:
        t_ref, pos = read_reference(trial, record["reference"])
        s = trial.read(channels["zupt"])
    # the reference resampled onto the trajectory's times, so a valid reference sample falls on a trajectory one
    t_ref, pos = np.asarray(s.t_ns, np.int64), interpolate_reference(t_ref, pos, s.t_ns, 0.05)
    r = reps[1]
    inside = np.flatnonzero((t_ref >= r["start_ns"]) & (t_ref <= r["end_ns"]))
    head = t_ref[inside[len(inside) // 4]]
    pos[(t_ref < head) & (t_ref >= int(r["start_ns"]) - int(3e9))] = np.nan  # 3 s occluded before it
    stream = SignalStream("/ref", t_ref, ["x", "y", "z"], ["m"] * 3, pos)

    class Patched:
        def __init__(self, trial):
            self.trial = trial

        def __getattr__(self, name):
            return getattr(self.trial, name)

    with TrialReader(path) as trial:
        trajs = {m: (trial.read(t).t_ns, trial.read(t).values) for m, t in channels.items()}
        whole = compute_evaluation(trajs, (t_ref, pos), reference_topic="o", windows=reps, baseline=BASELINE)

        class Reader(Patched):
            def read(self, topic, start_ns=None, end_ns=None):
                if topic != "/ref":
                    return self.trial.read(topic, start_ns, end_ns)
                from imulog.archive import codec

                return codec.select_time(stream, start_ns, end_ns)

            def iter_blocks(self, topic, start_ns=None, end_ns=None):
                yield self.read(topic, start_ns, end_ns)

        rows = windowed_rows(Reader(trial), channels, "/ref", reps, 0.05, error_rows, interpolate_reference, span_s=0.5)
    for m in channels:
        assert rows[m] == whole["methods"][m]["repetitions"]


def _walking_foot(hours: float, rate: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    """(t_ns, gyroscope rad/s) of a foot walking throughout: strides of 1.2 +- 0.03 s, each a 0.6-s swing and a
    rest (the stride period and the rests walking_trial looks for)."""
    rng = np.random.default_rng(0)
    n = int(hours * 3600 * rate)
    t = np.arange(n) / rate
    starts = np.cumsum(rng.normal(1.2, 0.03, int(t[-1] / 1.1)))
    k = np.searchsorted(starts, t) - 1
    ph = np.where(k >= 0, t - starts[np.maximum(k, 0)], 1.0)
    swing = np.where(ph < 0.6, 5.0 * np.sin(np.pi * ph / 0.6), 0.0)
    gyr = np.column_stack([0.3 * swing, swing, 0.1 * swing]) + rng.normal(0.0, 0.01, (n, 3))
    return (t * 1e9).astype(np.int64), gyr


def test_walking_of_a_long_trial_reads_its_middle_hour_not_the_whole_channel(tmp_path, monkeypatch):
    """Deciding whether to evaluate per stride must not load a week's gyroscope (issue 24): a 2-h trial is read in
    its middle hour, and the verdict is the one from the whole gyroscope."""
    from imulog.archive import write_trial
    from imulog.model import ImuStream, Recording
    from imulog.steps.evaluate import walking_of
    from imulog.steps.gait_evaluate import walking_trial

    t_ns, gyr = _walking_foot(2.0)
    acc = np.tile([0.0, 0.0, 9.81], (len(t_ns), 1))
    path = tmp_path / "walk.mcap"
    write_trial(path, Recording(imus=[ImuStream(name="foot", t_ns=t_ns, acc=acc, gyr=gyr)]))
    whole = walking_trial({}, {"foot": (gyr, 100.0)})
    assert whole is not None and whole["period_s"] == pytest.approx(1.2, abs=0.05)

    reads = record_reads(monkeypatch)
    got = walking_of(path)
    assert got == whole
    imu_reads = [r for r in reads if r[0] == "/imu/foot"]
    assert imu_reads, "the gyroscope was not read"
    for _, lo, hi in imu_reads:
        assert lo is not None and hi is not None and (hi - lo) <= 3600e9 + 1, "read the whole 2-h channel"
    reads.clear()
    assert walking_of(path, span_s=3 * 3600.0) == whole  # within the span: read whole, as before
    assert [r[1:] for r in reads if r[0] == "/imu/foot"] == [(None, None)]


class _RefReader:
    """A TrialReader whose ``/ref`` channel is ``stream``, recording every read as (topic, start_ns, end_ns)."""

    def __init__(self, trial, stream):
        self.trial, self.stream, self.reads = trial, stream, []

    def __getattr__(self, name):
        return getattr(self.trial, name)

    def read(self, topic, start_ns=None, end_ns=None):
        self.reads.append((topic, start_ns, end_ns))
        if topic != "/ref":
            return self.trial.read(topic, start_ns, end_ns)
        from imulog.archive import codec

        return codec.select_time(self.stream, start_ns, end_ns)

    def iter_blocks(self, topic, start_ns=None, end_ns=None):
        yield self.read(topic, start_ns, end_ns)


@pytest.mark.parametrize("whole_window", [False, True])
def test_trajectories_are_read_only_where_the_reference_is(evaluated, whole_window):
    """A trajectory longer than its reference (a week at home after an hour in the lab, issue 24) is read only
    within the reference's valid extent, even in one span over every repetition or one window over the whole
    channel (no repetitions), and the rows are still the whole computation's."""
    from imulog.steps.evaluate import WHOLE_NS

    with TrialReader(evaluated) as trial:
        reps = trial.metadata["imulog.trajectory"]["repetitions"]
        channels = {"zupt": "/derived/trajectory/zupt", BASELINE: f"/derived/trajectory_baseline/{BASELINE}"}
        t_ref, pos = read_reference(trial, "/markers/vicon:O")
        s = trial.read(channels["zupt"])
    t_ref, pos = np.asarray(t_ref, np.int64), np.array(pos, np.float64)
    # the reference covers the second repetition and 1 s either side, with an occluded tail: its valid extent
    # ends before the channel does
    a, b = int(reps[1]["start_ns"]) - int(1e9), int(reps[1]["end_ns"]) + int(1e9)
    keep = (t_ref >= a) & (t_ref <= b)
    t_ref, pos = t_ref[keep], pos[keep]
    pos[t_ref > b - int(0.5e9)] = np.nan
    ok = np.all(np.isfinite(pos), axis=1)
    first, last = int(t_ref[ok][0]), int(t_ref[ok][-1])
    assert int(s.t_ns[0]) < first and last < int(s.t_ns[-1])  # the trajectory outlasts the reference both sides
    stream = SignalStream("/ref", t_ref, ["x", "y", "z"], ["m"] * 3, pos)
    windows = [{"index": -1, "start_ns": -WHOLE_NS, "end_ns": WHOLE_NS}] if whole_window else reps
    with TrialReader(evaluated) as trial:
        trajs = {m: (trial.read(t).t_ns, trial.read(t).values) for m, t in channels.items()}
        whole = compute_evaluation(
            trajs, (t_ref, pos), reference_topic="o", windows=None if whole_window else reps, baseline=BASELINE
        )
        reader = _RefReader(trial, stream)
        rows = windowed_rows(reader, channels, "/ref", windows, 0.05, error_rows, interpolate_reference, span_s=1e9)
    for m in channels:
        assert rows[m], m
        assert rows[m] == whole["methods"][m]["repetitions"]
    traj_reads = [r for r in reader.reads if r[0] in channels.values()]
    assert traj_reads
    for _, lo, hi in traj_reads:
        assert lo is not None and hi is not None and first <= lo and hi <= last + 1, "read beyond the reference"


def test_foot_evaluation_reads_the_imu_only_around_its_cluster(shared_data, tmp_path, monkeypatch):
    """Per-stride evaluation reads each foot IMU and its gravity-free acceleration over the cluster pose's span
    (mapped to the device clock) and the margin, not the whole channel (issue 24: a week's IMU with an hour of
    markers). The real gaitmap trial is within the default margin (read whole, as before); with the margin at 0
    its IMU outlasts the markers by 16 ms, so the reads are bounded, and the strides are still evaluated."""
    from click.testing import CliRunner

    from imulog.cli import cli
    from imulog.process.alignment_clock import reference_to_device
    from imulog.steps import align
    from imulog.steps.common import alignment_for, cluster_pose_topic
    from imulog.steps.gait_evaluate import foot_span

    root = shared_data / "gaitmap_foot"
    path = tmp_path / "gait.mcap"
    run = CliRunner()
    res = run.invoke(cli, ["convert", str(root / "imu_sample.csv"), str(root / "mocap_sample.csv"), "-o", str(path)])
    assert res.exit_code == 0, res.output
    assert run.invoke(cli, ["process", "align", str(path), "--no-resample"]).exit_code == 0
    feet = ("left_sensor", "right_sensor")
    with TrialReader(path) as trial:
        recs = {n: alignment_for(trial.metadata, f"/imu/{n}") for n in feet}
        poses = {n: cluster_pose_topic(n, trial.topics(), trial.metadata) for n in feet}
        assert all(foot_span(trial, f"/imu/{n}", poses[n], recs[n]) == (None, None) for n in feet)
        monkeypatch.setattr(align, "MARGIN_S", 0.0)
        spans = {n: foot_span(trial, f"/imu/{n}", poses[n], recs[n]) for n in feet}
        for n in feet:
            p = trial.channel(poses[n])
            lo, hi = (int(v) for v in reference_to_device(np.array([p.start_ns, p.end_ns]), recs[n]))
            assert spans[n] == (lo, hi + 1)
            assert trial.channel(f"/imu/{n}").end_ns >= hi + 1  # the IMU outlasts its cluster
    reads = record_reads(monkeypatch)
    _, record = run_evaluate(path, strides=True, force=True)
    assert set(record["feet"]) == set(feet)
    assert all(r["count"] >= 28 for r in record["feet"].values())
    for n in feet:
        got = [r[1:] for r in reads if r[0] in (f"/imu/{n}", f"/derived/acc_global/{n}")]
        assert got and all(g == spans[n] for g in got), (n, got)


def test_walking_is_judged_where_the_reference_is(tmp_path):
    """A long recording is judged walking or not on the hour around its optical reference's middle (issue 24):
    a simulated week's wrist walks in the middle of the week but not in its lab hour, where it is evaluated. Here
    a 2-h foot stands still for 40 min, then walks, with markers for the first 30 min: not a walking trial (its
    middle hour, read before, walks); without the markers, the middle hour decides as before."""
    from imulog.archive import write_trial
    from imulog.model import ImuStream, MarkerStream, Recording
    from imulog.steps.evaluate import judged_span, walking_of

    t_ns, gyr = _walking_foot(2.0)
    gyr = np.where((t_ns < 2400e9)[:, None], np.random.default_rng(1).normal(0.0, 0.01, gyr.shape), gyr)
    acc = np.tile([0.0, 0.0, 9.81], (len(t_ns), 1))
    imu = ImuStream(name="foot", t_ns=t_ns, acc=acc, gyr=gyr)
    lab = t_ns < 1800e9
    markers = MarkerStream("vicon", t_ns[lab], ["O"], np.zeros((int(lab.sum()), 1, 3)))
    with_ref, without = tmp_path / "lab.mcap", tmp_path / "home.mcap"
    write_trial(with_ref, Recording(imus=[imu], markers=[markers]))
    write_trial(without, Recording(imus=[imu]))
    assert walking_of(without) is not None  # the middle hour walks
    with TrialReader(with_ref) as trial:
        mid = (int(t_ns[lab][0]) + int(t_ns[lab][-1])) // 2  # the markers' middle (no alignment: same clock)
        assert judged_span(trial, "/imu/foot", 3600.0) == (mid - int(1800e9), mid + int(1800e9))
    assert walking_of(with_ref) is None
