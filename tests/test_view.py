"""imulog view: read the saved .rrd back with rerun-sdk's reader and check what the viewer would show."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from rerun.chunk import RrdReader

from imulog.archive.clocks import device_imu_of
from imulog.cli import cli
from imulog.model import ImuStream, Intervals, MarkerStream, PoseStream, Recording, SignalStream
from imulog.view import build_blueprint, from_recording, rates, show
from imulog.view import layout as L
from imulog.view.layout import PHASE_COLORS
from imulog.view.rrd import read_column, read_scalars, summarize
from imulog.view.sample import SampleTrialParams, _ref_to_device, phase_intervals_ref_ns, sample_recording

PHASE_LABELS = {"reach", "lift", "return_bottle", "return_hand"}


def _save(tmp_path: Path, recording: Recording, name: str = "trial") -> tuple[Path, list]:
    out = tmp_path / f"{name}.rrd"
    result = show([from_recording(recording, name)], sink="save", save_paths=[out])
    return out, result.logged[0]


def _best_lag_s(t_a_ns, a, t_b_ns, b, max_lag_s: float, step_s: float = 0.002) -> float:
    """Lag (s) to add to series ``a``'s times that best matches ``b`` (max normalised cross-correlation)."""
    lo = max(t_a_ns[0], t_b_ns[0]) / 1e9 + max_lag_s
    hi = min(t_a_ns[-1], t_b_ns[-1]) / 1e9 - max_lag_s
    grid = np.arange(lo, hi, step_s)
    ok_b = np.isfinite(b)
    bb = np.interp(grid, t_b_ns[ok_b] / 1e9, b[ok_b])
    bb = (bb - bb.mean()) / bb.std()
    lags = np.arange(-max_lag_s, max_lag_s + step_s / 2, step_s)
    scores = []
    for lag in lags:
        aa = np.interp(grid, t_a_ns / 1e9 + lag, a)
        scores.append(np.mean((aa - aa.mean()) / aa.std() * bb))
    return float(lags[int(np.argmax(scores))])


def _assert_display_rate(out: Path, cursor: str, series: str) -> np.ndarray:
    """The cursor ``cursor`` moves at the display's rate along the time series ``series`` (same samples):
    rows at sample times, from its first sample to its last; at every sample the cursor shown (latest row at
    or before it) is less than one frame old; no more rows than frames. Returns the cursor's row times."""
    t_cursor, _ = read_column(out, cursor, "Points3D:positions")
    t_samples, _ = read_scalars(out, series)
    assert np.isin(t_cursor, t_samples).all()
    assert t_cursor[0] == t_samples[0] and t_cursor[-1] == t_samples[-1]
    shown = t_cursor[np.searchsorted(t_cursor, t_samples, side="right") - 1]
    assert np.max(t_samples - shown) < 1e9 / rates.DISPLAY_RATE_HZ
    assert len(t_cursor) <= (t_samples[-1] - t_samples[0]) / 1e9 * rates.DISPLAY_RATE_HZ + 2
    assert len(t_cursor) < len(t_samples)  # every stream here is faster than the display
    return t_cursor


@pytest.fixture(scope="module")
def sample_rrd(tmp_path_factory) -> tuple[Path, Recording, list]:
    rec = sample_recording(SampleTrialParams(duration_s=30.0))
    out, logged = _save(tmp_path_factory.mktemp("view"), rec)
    return out, rec, logged


def test_rrd_entities_rows_timeline_and_blueprint(sample_rrd):
    out, rec, _ = sample_rrd
    summary = summarize(out)
    imu = rec.imus[0]
    expected_rows = {
        L.imu_entity("wrist", "acc"): len(imu),
        L.imu_entity("wrist", "gyr"): len(imu),
        L.imu_entity("wrist", "mag"): len(imu),
        L.imu_gyr_norm_entity("wrist"): len(imu),
        L.marker_entity("vicon"): len(rec.markers[0]),
        L.pose_entity(L.CLUSTER_POSE_TOPIC): len(rec.poses[0]),
        L.norm_entity(L.VICON_ANGULAR_VELOCITY_TOPIC): len(rec.signals[2]),
    }
    for s in rec.signals:
        expected_rows[L.signal_entity(s.topic)] = len(s)
        if s.topic.startswith(L.TRAJECTORY_PREFIX):
            _assert_display_rate(out, L.cursor_entity(s.topic), L.signal_entity(s.topic))
            assert "LineStrips3D:strips" in summary[L.path_entity(s.topic)].static_components
    assert summary[L.cursor_entity(L.CLUSTER_POSE_TOPIC)].timelines == {L.TIMELINE}
    t_vicon_cursor, _ = read_column(out, L.cursor_entity(L.CLUSTER_POSE_TOPIC), "Points3D:positions")
    assert np.isin(t_vicon_cursor, rec.poses[0].t_ns).all()
    assert len(t_vicon_cursor) <= len(rec.poses[0]) / 100 * rates.DISPLAY_RATE_HZ + 2  # the pose is at 100 Hz
    for entity, rows in expected_rows.items():
        assert entity in summary, entity
        assert summary[entity].rows == rows, entity
        assert summary[entity].timelines == {L.TIMELINE}, entity
    # every series carries names with units
    assert "SeriesLines:names" in summary[L.imu_entity("wrist", "gyr")].static_components
    # markers: every valid marker sample was sent (the occluded one is not)
    _, marker_rows = read_column(out, L.marker_entity("vicon"), "Points3D:positions")
    assert sum(len(r) for r in marker_rows) == int(rec.markers[0].valid.sum())
    # the evaluation panel and the default blueprint travel with the recording
    assert "TextDocument:text" in summary[L.evaluation_entity()].static_components
    assert len(RrdReader(out).blueprints()) == 1


def test_phases_and_static_states_on_reference_clock(sample_rrd):
    out, rec, _ = sample_rrd
    t, states = read_column(out, L.signal_entity("/derived/phases/wrist"), "StateChange:state")
    phases = rec.events[0]
    starts = [(ti, s) for ti, s in zip(t, states, strict=True) if s[0]]
    assert {s[0].rsplit(" ", 1)[0] for _, s in starts} == PHASE_LABELS
    assert len(starts) == len(phases)
    # phases were written on the IMU device clock; shown on the reference clock they match the truth
    true_start, true_end, true_labels, true_tasks = phase_intervals_ref_ns(30.0)
    got_t = np.array([ti for ti, _ in starts])
    assert np.max(np.abs(got_t - true_start)) <= 2  # ns (rounding of the inverse clock map)
    # lane 1 reads on its own when zoomed in: "reach 3"; lane 2 spans the repetition: "rep 3"
    assert [s[0] for _, s in starts] == [f"{lab} {k}" for lab, k in zip(true_labels, true_tasks, strict=True)]
    assert [s[1] for _, s in starts] == [f"rep {k}" for k in true_tasks]
    # every numbered label keeps its phase's colour; repetitions alternate two greys
    config = next(
        c.to_record_batch()
        for c in RrdReader(out).stream().to_chunks()
        if c.entity_path == "/derived/phases/wrist" and c.is_static
    )
    values = config.column("StateConfiguration:values").to_pylist()[0]
    colours = dict(zip(values, config.column("StateConfiguration:colors").to_pylist()[0], strict=True))
    for lab, k in zip(true_labels, true_tasks, strict=True):
        assert colours[f"{lab} {k}"] == PHASE_COLORS[lab]
    assert colours["rep 1"] != colours["rep 2"] == colours["rep 4"]
    # the phase log: one row per phase at its start, coloured like the lane, with repetition and duration
    t_log, text = read_column(out, L.phase_log_entity("/derived/phases/wrist"), "TextLog:text")
    np.testing.assert_array_equal(t_log, got_t)
    first = text[0][0] if isinstance(text[0], list) else text[0]
    assert first == f"rep {true_tasks[0]} · {true_labels[0]} · {(true_end[0] - true_start[0]) / 1e9:.2f} s"
    _, log_colours = read_column(out, L.phase_log_entity("/derived/phases/wrist"), "TextLog:color")
    flat = [c[0] if isinstance(c, list) else c for c in log_colours]
    assert flat == [PHASE_COLORS[lab] for lab in true_labels]
    # static/moving lane: "moving" starts exactly when the first reach starts
    t_s, st = read_column(out, L.state_entity("/derived/static/wrist"), "StateChange:state")
    first_moving = t_s[[s == ["moving"] for s in st].index(True)]
    assert abs(int(first_moving) - int(true_start[0])) < 1e9 / 115 + 1


def test_imu_and_vicon_overlap_and_line_up_after_alignment(sample_rrd, tmp_path):
    out, rec, _ = sample_rrd
    summary = summarize(out)
    imu, vicon = summary[L.imu_gyr_norm_entity("wrist")], summary[L.marker_entity("vicon")]
    # the IMU device clock starts ~1.23 s away from the Vicon clock; after alignment the ranges overlap
    assert rec.imus[0].t_ns[0] < -1e9
    overlap = min(imu.t_max_ns, vicon.t_max_ns) - max(imu.t_min_ns, vicon.t_min_ns)
    assert overlap > 0.9 * (vicon.t_max_ns - vicon.t_min_ns)
    t_i, g = read_scalars(out, L.imu_gyr_norm_entity("wrist"))
    t_v, w = read_scalars(out, L.norm_entity(L.VICON_ANGULAR_VELOCITY_TOPIC))
    assert abs(_best_lag_s(t_i, g[:, 0], t_v, w[:, 0], 0.5)) <= 0.004

    # a wrong alignment (offset 250 ms short) is visibly wrong on the same timeline
    wrong = sample_recording(SampleTrialParams(duration_s=30.0, alignment={"offset_ns": 1_234_567_890 - 250_000_000}))
    out_wrong, _ = _save(tmp_path, wrong, "wrong")
    t_i, g = read_scalars(out_wrong, L.imu_gyr_norm_entity("wrist"))
    t_v, w = read_scalars(out_wrong, L.norm_entity(L.VICON_ANGULAR_VELOCITY_TOPIC))
    assert _best_lag_s(t_i, g[:, 0], t_v, w[:, 0], 0.5) == pytest.approx(0.25, abs=0.004)


def test_real_broad_trial_alignment_and_rows(shared_data, tmp_path):
    """BROAD (real myon IMU + OptiTrack, synchronised): shift the IMU clock, view, check it lines up again."""
    h5py = pytest.importorskip("h5py")
    with h5py.File(shared_data / "broad" / "02_undisturbed_slow_rotation_B.hdf5") as f:
        rate = float(f.attrs["sampling_rate"])
        acc, gyr, mag = f["imu_acc"][:], f["imu_gyr"][:], f["imu_mag"][:]
        pos, quat = f["opt_pos"][:], f["opt_quat"][:]
    n = 60 * int(rate)  # first minute keeps the test fast
    acc, gyr, mag, pos, quat = acc[:n], gyr[:n], mag[:n], pos[:n], quat[:n]
    t_ref = np.rint(np.arange(n) * 1e9 / rate).astype(np.int64)
    alignment = {"imu": "/imu/broad", "offset_ns": 3_000_000_000, "drift_ppm": 100.0, "t0_ns": 0}
    # device clock chosen so that the alignment formula maps it back onto the optical clock
    t_dev = _ref_to_device(t_ref, alignment)
    # optical angular velocity from consecutive quaternions: 2 * vec(q_i^-1 q_i+1) / dt
    q0, q1 = quat[:-1], quat[1:]
    w0, v0, w1, v1 = q0[:, :1], -q0[:, 1:], q1[:, :1], q1[:, 1:]
    vec = w0 * v1 + w1 * v0 + np.cross(v0, v1)
    sign = np.sign(w0 * w1 - np.sum(v0 * v1, axis=1, keepdims=True))
    omega = 2 * sign * vec * rate
    t_mid = (t_ref[:-1] + t_ref[1:]) // 2
    rec = Recording(
        imus=[ImuStream("broad", t_dev, acc=acc, gyr=gyr, mag=mag)],
        signals=[SignalStream(L.VICON_ANGULAR_VELOCITY_TOPIC, t_mid, ["wx", "wy", "wz"], ["rad/s"] * 3, omega)],
        poses=[PoseStream(L.CLUSTER_POSE_TOPIC, t_ref, pos, quat)],
        metadata={"imulog.alignment": alignment},
    )
    out, logged = _save(tmp_path, rec, "broad")
    summary = summarize(out)
    assert summary[L.imu_entity("broad", "gyr")].rows == n
    assert summary[L.pose_entity(L.CLUSTER_POSE_TOPIC)].rows == n  # NaN (lost tracking) rows stay, empty
    assert abs(summary[L.imu_entity("broad", "gyr")].t_min_ns - t_ref[0]) <= 2  # ns
    assert not logged[0].unaligned_imus
    t_i, g = read_scalars(out, L.imu_gyr_norm_entity("broad"))
    t_v, w = read_scalars(out, L.norm_entity(L.VICON_ANGULAR_VELOCITY_TOPIC))
    assert abs(_best_lag_s(t_i, g[:, 0], t_v, w[:, 0], 0.2, step_s=1 / rate)) <= 2 / rate


def test_unknown_derived_channels_and_no_alignment(tmp_path):
    t = np.arange(200, dtype=np.int64) * 10_000_000
    rec = Recording(
        imus=[ImuStream("ankle", t, gyr=np.ones((200, 3)))],
        signals=[SignalStream("/derived/emg/envelope", t, ["biceps", "triceps"], ["mV", "mV"], np.ones((200, 2)))],
        events=[Intervals("/derived/movements/ankle", [0, 5 * 10**8], [10**8, 5 * 10**8], ["movement", "heel"])],
    )
    out, logged = _save(tmp_path, rec, "generic")
    summary = summarize(out)
    assert summary["/derived/emg/envelope"].rows == 200
    static_names = next(
        c.to_record_batch().column("SeriesLines:names").to_pylist()[0]
        for c in RrdReader(out).stream().to_chunks()
        if c.entity_path == "/derived/emg/envelope" and c.is_static
    )
    assert static_names == ["emg/envelope biceps (mV)", "emg/envelope triceps (mV)"]
    # the zero-length interval is an event, the other a state
    assert summary["/derived/movements/ankle/events"].rows == 1
    assert summary["/derived/movements/ankle"].rows == 2  # start + reset
    assert logged[0].unaligned_imus == ["ankle"]
    assert [e.path for e in logged[0].by_role("signal")] == ["/derived/emg/envelope"]
    build_blueprint(logged)  # builds with the generic channel in the derived tab


def test_overlay_puts_trials_side_by_side(tmp_path):
    a = from_recording(sample_recording(SampleTrialParams(duration_s=10.0, methods=("zupt",))), "run")
    b = from_recording(sample_recording(SampleTrialParams(duration_s=10.0, methods=("ekf",))), "run")
    out = tmp_path / "overlay.rrd"
    result = show([a, b], sink="save", save_paths=[out], overlay=True)
    summary = summarize(out)
    assert len(RrdReader(out).recordings()) == 1
    _assert_display_rate(out, "/run/world/cursors/trajectory/zupt", "/run/derived/trajectory/zupt")
    _assert_display_rate(out, "/run_2/world/cursors/trajectory/ekf", "/run_2/derived/trajectory/ekf")
    assert "/run/imu/wrist/gyr_norm" in summary and "/run_2/imu/wrist/gyr_norm" in summary
    # one colour per method across the overlaid trials
    colours = [
        c.to_record_batch().column("Points3D:colors").to_pylist()[0]
        for c in RrdReader(out).stream().to_chunks()
        if c.is_static and c.entity_path.endswith(("cursors/trajectory/zupt", "cursors/trajectory/ekf"))
    ]
    assert len(colours) == 2 and colours[0] != colours[1]
    assert [t.prefix for t in result.logged[0]] == ["/run", "/run_2"]


def test_clock_rule():
    assert device_imu_of("/imu/wrist") == "wrist"
    assert device_imu_of("/derived/orientation/wrist") == "wrist"
    assert device_imu_of("/derived/trajectory/zupt") is None
    assert device_imu_of("/markers/vicon") is None
    assert device_imu_of("/derived/phases/wrist", {"clock": "reference"}) is None
    assert device_imu_of("/derived/foo", {"clock": "/imu/wrist"}) == "wrist"
    # what the steps write: phases follow imulog.timing["clock"]; per-IMU derived channels of a known IMU
    timing = {"imulog.timing": {"clock": "reference"}}
    assert device_imu_of("/derived/phases/wrist", step_records=timing) is None
    assert device_imu_of("/derived/phases/wrist", step_records={"imulog.timing": {"clock": "device"}}) == "wrist"
    unaligned_traj = {"imulog.trajectory": {"clock": "device", "imu": "/imu/wrist"}}
    assert device_imu_of("/derived/trajectory/zupt", step_records=unaligned_traj) == "wrist"
    assert device_imu_of("/derived/metrics/distance/wrist", imu_names={"wrist"}) == "wrist"
    assert device_imu_of("/derived/reference/orientation/wrist", imu_names={"wrist"}) is None
    assert device_imu_of("/derived/vicon/angular_velocity", imu_names={"angular_velocity"}) is None


def test_cli_save_default_without_display_and_errors(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    result = runner.invoke(cli, ["view", "--sample", "8"])
    assert result.exit_code == 0, result.output
    assert "no display found" in result.output
    assert (tmp_path / "sample.rrd").is_file()
    assert summarize(tmp_path / "sample.rrd")[L.imu_entity("wrist", "acc")].rows == int(9 * 115)

    result = runner.invoke(cli, ["view", "--sample", "8", "--spawn", "--web"])
    assert result.exit_code != 0 and "choose one of" in result.output
    # --save combines with --web: the file is written and the viewer URL printed
    args = ["view", "--sample", "8", "--save", "both.rrd", "--web", "--port", "0", "--grpc-port", "0"]
    result = runner.invoke(cli, [*args, "--serve-seconds", "0"])
    assert result.exit_code == 0, result.output
    assert "Rerun web viewer: http://127.0.0.1:" in result.output and "saved both.rrd" in result.output
    assert summarize(tmp_path / "both.rrd")[L.imu_entity("wrist", "acc")].rows == int(9 * 115)
    result = runner.invoke(cli, ["view", "--sample", "8", "--spawn"])
    assert result.exit_code != 0 and "needs a display" in result.output
    result = runner.invoke(cli, ["view", "missing.mcap"])
    assert result.exit_code != 0 and "missing.mcap" in result.output


def test_cli_on_archive_when_available(tmp_path):
    """Through the real archive: rows equal the channels' sample counts recorded in the MCAP file."""
    archive = pytest.importorskip("imulog.archive")
    if not hasattr(archive, "write_trial") or not hasattr(archive, "TrialReader"):
        pytest.skip("imulog.archive.write_trial/TrialReader not landed yet")
    trial = archive.write_trial(tmp_path / "t.mcap", sample_recording(SampleTrialParams(duration_s=10.0)))
    result = CliRunner().invoke(cli, ["view", str(trial), "--save", str(tmp_path / "t.rrd")])
    assert result.exit_code == 0, result.output
    summary = summarize(tmp_path / "t.rrd")
    with archive.TrialReader(trial) as reader:
        counts = {c.topic: c.sample_count for c in reader.channels}
    assert summary[L.imu_entity("wrist", "gyr")].rows == counts["/imu/wrist"]
    assert summary[L.marker_entity("vicon")].rows == counts["/markers/vicon"]
    assert summary["/derived/trajectory/zupt"].rows == counts["/derived/trajectory/zupt"]

    # several files: one recording each into a folder, or one overlaid recording
    other = archive.write_trial(tmp_path / "u.mcap", sample_recording(SampleTrialParams(duration_s=5.0)))
    result = CliRunner().invoke(cli, ["view", str(trial), str(other), "--save", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert summarize(tmp_path / "out" / "u.rrd")[L.imu_entity("wrist", "gyr")].rows == int(6 * 115)
    result = CliRunner().invoke(cli, ["view", str(trial), str(other), "--save", str(tmp_path / "both.rrd")])
    assert result.exit_code != 0 and "--overlay" in result.output
    result = CliRunner().invoke(
        cli, ["view", str(trial), str(other), "--overlay", "--save", str(tmp_path / "both.rrd")]
    )
    assert result.exit_code == 0, result.output
    both = summarize(tmp_path / "both.rrd")
    assert both["/t/imu/wrist/gyr"].rows == counts["/imu/wrist"] and both["/u/imu/wrist/gyr"].rows == int(6 * 115)


def test_simulated_trial_imu_lands_on_true_reference_times(tmp_path):
    """Simulator ground truth: with the true alignment every IMU sample sits at its exact reference time."""
    simulate = pytest.importorskip("imulog.simulate").simulate
    sim = simulate("r2g", subject=0, trial=0, seed=1, repetitions=2, opening_static_s=5.0)
    rec = sim.recording
    truth = sim.truth
    phases = Intervals("/derived/phases/wrist", truth.phases.start_ns, truth.phases.end_ns, truth.phases.labels)
    rec = Recording(
        imus=rec.imus,
        markers=rec.markers,
        events=[phases],
        metadata={
            **rec.metadata,
            "imulog.alignment": truth.alignment,
            "imulog.timing": {"imu": "/imu/wrist", "clock": "reference"},
        },
    )
    out, _ = _save(tmp_path, rec, "sim")
    t_gyr, _ = read_scalars(out, L.imu_entity("wrist", "gyr"))
    assert len(t_gyr) == len(rec.imus[0]) == len(truth.imu_t_ref_ns)
    assert np.max(np.abs(t_gyr - truth.imu_t_ref_ns)) <= 1  # ns
    t_ph, states = read_column(out, "/derived/phases/wrist", "StateChange:state")
    starts = t_ph[[bool(s[0]) for s in states]]
    np.testing.assert_array_equal(starts, np.sort(truth.phases.start_ns))  # already reference clock: unchanged
    summary = summarize(out)
    assert summary[L.marker_entity("vicon")].rows == len(rec.markers[0])


def test_archive_and_steps_pipeline(tmp_path):
    """simulator -> archive -> orientation, align, phases, trajectory, evaluate steps -> `imulog view`."""
    simulate = pytest.importorskip("imulog.simulate").simulate
    archive = pytest.importorskip("imulog.archive")
    from imulog.steps.align import run_align
    from imulog.steps.evaluate import run_evaluate
    from imulog.steps.metrics import run_metrics
    from imulog.steps.orientation import run_orientation
    from imulog.steps.phases import run_phases
    from imulog.steps.trajectory import run_trajectory

    sim = simulate("r2g", subject=0, trial=0, seed=0, repetitions=5)
    trial = archive.write_trial(tmp_path / "sim.mcap", sim.recording)
    for step in (run_orientation, run_align, run_phases, run_trajectory, run_evaluate, run_metrics):
        step(trial)
    out = tmp_path / "sim.rrd"
    result = CliRunner().invoke(cli, ["view", str(trial), "--save", str(out)])
    assert result.exit_code == 0, result.output
    assert "warning" not in result.output  # aligned: nothing left on a device clock
    summary = summarize(out)
    with archive.TrialReader(trial) as reader:
        counts = {c.topic: c.sample_count for c in reader.channels}
        stored_phases = reader.read("/derived/phases/wrist")
        methods = reader.metadata["imulog.trajectory"]["methods"]
    for topic, n in counts.items():
        if topic.startswith(("/imu/", "/derived/vicon/angular", "/derived/static/", "/derived/trajectory/")):
            entity = L.imu_entity(topic.split("/")[2], "gyr") if topic.startswith("/imu/") else topic
            assert summary[entity].rows == n, topic
    assert summary[L.pose_entity(L.CLUSTER_POSE_TOPIC)].rows == counts[L.CLUSTER_POSE_TOPIC]
    for method in methods:  # every IMU reconstruction: a coloured path, a cursor and an error series
        topic = f"/derived/trajectory/{method}"
        _assert_display_rate(out, L.cursor_entity(topic), L.signal_entity(topic))
        assert summary[L.error_entity(topic)].rows == counts[topic]
        assert "LineStrips3D:strips" in summary[L.path_entity(topic)].static_components
    text = next(c for c in RrdReader(out).stream().to_chunks() if c.entity_path == L.evaluation_entity())
    text = text.to_record_batch().column("TextDocument:text").to_pylist()[0][0]
    assert all(f"| {m} |" in text for m in methods), text
    # the clinical metrics panel shows the imulog.metrics record
    text = next(c for c in RrdReader(out).stream().to_chunks() if c.entity_path == L.metrics_entity())
    text = text.to_record_batch().column("TextDocument:text").to_pylist()[0][0]
    with archive.TrialReader(trial) as reader:
        usage = reader.metadata["imulog.metrics"]["arm_usage.overall_percent"]
    assert "## arm usage" in text and f"| overall_percent | {usage:.4g}" in text, text  # the panel shows 4 digits
    # every stored phase is a state on the timeline (what the segmentation found, faithfully)
    phase_t, states = read_column(out, "/derived/phases/wrist", "StateChange:state")
    started = [s[0] for s in states if s[0]]
    assert len(started) == len(stored_phases) > 0
    # "reach 3": the stored label and repetition, in time order; a forced phase keeps its " (forced)" suffix
    parsed = [re.fullmatch(r"(\w+) (\d+)( \(forced\))?", s) for s in started]
    assert all(parsed), started
    order = np.argsort(stored_phases.start_ns, kind="stable")
    assert [(m[1], int(m[2])) for m in parsed] == [
        (str(stored_phases.labels[i]), int(stored_phases.task_index[i])) for i in order
    ]
    assert {m[1] for m in parsed} == set(stored_phases.labels) <= PHASE_LABELS
    # the phases step wrote them on the reference clock (imulog.timing): shown unchanged
    np.testing.assert_array_equal(phase_t[[bool(s[0]) for s in states]], np.sort(stored_phases.start_ns))
    imu, vicon = summary[L.imu_gyr_norm_entity("wrist")], summary[L.norm_entity(L.VICON_ANGULAR_VELOCITY_TOPIC)]
    assert imu.t_min_ns < vicon.t_max_ns and vicon.t_min_ns < imu.t_max_ns
    t_i, g = read_scalars(out, L.imu_gyr_norm_entity("wrist"))
    t_v, w = read_scalars(out, L.norm_entity(L.VICON_ANGULAR_VELOCITY_TOPIC))
    assert abs(_best_lag_s(t_i, g[:, 0], t_v, w[:, 0], 0.3, step_s=0.005)) <= 0.01


def test_repetition_displacements_are_anchored_on_vicon(tmp_path):
    """Per-repetition displacements (what the trajectory step writes) land on the true path in 3D; error 0."""
    rec = sample_recording(SampleTrialParams(duration_s=20.0, methods=()))
    pose = rec.poses[0]
    start_ref, end_ref, _, _ = phase_intervals_ref_ns(20.0)
    rep_starts = start_ref[::4]  # reach starts = repetition starts
    inside = (pose.t_ns >= rep_starts[0]) & (pose.t_ns <= end_ref[-1])
    t = pose.t_ns[inside]
    rep = np.searchsorted(rep_starts, t, side="right") - 1
    start_pos = pose.position[np.searchsorted(pose.t_ns, rep_starts)]
    displacement = pose.position[inside] - start_pos[rep]
    rec.signals.append(SignalStream("/derived/trajectory/truth", t, ["x", "y", "z"], ["m"] * 3, displacement, "world"))
    rec.metadata["imulog.trajectory"] = {
        "imu": "/imu/wrist",
        "clock": "reference",
        "frame": "world",
        "origin": "repetition_start",
        "repetitions": [{"index": i + 1, "start_ns": int(s)} for i, s in enumerate(rep_starts)],
    }
    out, logged = _save(tmp_path, rec, "anchored")
    t_c, cursor = read_column(out, L.cursor_entity("/derived/trajectory/truth"), "Points3D:positions")
    _assert_display_rate(out, L.cursor_entity("/derived/trajectory/truth"), "/derived/trajectory/truth")
    at = np.searchsorted(t, t_c)  # the cursor's rows are samples of the trajectory: on the true path there
    np.testing.assert_allclose(np.array([c[0] for c in cursor]), pose.position[inside][at], atol=1e-6)
    t_e, err = read_scalars(out, L.error_entity("/derived/trajectory/truth"))
    assert len(t_e) == len(t) and np.nanmax(err) < 1e-3  # cm
    assert logged[0].by_role("error")


def test_cli_no_alignment_warning_for_imu_only_trials(tmp_path):
    """An IMU-only trial (e.g. x-io Fusion text, a home recording): nothing to align with, so no warning (it
    used to tell the user to run `imulog process align`, which cannot work without markers)."""
    from imulog.archive import write_trial

    t = np.arange(300, dtype=np.int64) * 10_000_000
    imu = ImuStream("wrist", t, acc=np.tile([0.0, 0.0, 9.81], (300, 1)), gyr=np.zeros((300, 3)))
    path = tmp_path / "imu_only.mcap"
    write_trial(path, Recording(imus=[imu]))
    res = CliRunner().invoke(cli, ["view", str(path), "--save", str(tmp_path / "x.rrd")])
    assert res.exit_code == 0, res.output
    assert "warning:" not in res.output and "imulog.alignment" not in res.output
    # with markers and no alignment the warning stays
    markers = MarkerStream("vicon", t, ["O"], np.zeros((300, 1, 3)))
    write_trial(tmp_path / "lab.mcap", Recording(imus=[imu], markers=[markers]))
    res = CliRunner().invoke(cli, ["view", str(tmp_path / "lab.mcap"), "--save", str(tmp_path / "y.rrd")])
    assert res.exit_code == 0 and "warning:" in res.output and "imulog process align" in res.output


def test_every_orientation_is_a_moving_frame_beside_the_cluster(sample_rrd, tmp_path):
    """Derived orientations (and a device's own, /orientation/*) as Transform3D + axes in the 3D view."""
    from imulog.process import quaternion as quat
    from imulog.view.frames import BESIDE_CLUSTER_M

    out, rec, logged = sample_rrd
    orientation = next(s for s in rec.signals if s.topic == "/derived/orientation/wrist")
    entity = L.imu_frame_entity(orientation.topic)
    summary = summarize(out)
    assert summary[entity].rows == len(orientation) and summary[entity].timelines == {L.TIMELINE}
    assert "TransformAxes3D:axis_length" in summary[entity].static_components
    t, xyzw = read_column(out, entity, "Transform3D:quaternion")
    _, shift = read_column(out, entity, "Transform3D:translation")
    q = np.array([r[0] for r in xyzw], dtype=np.float64)[:, [3, 0, 1, 2]]
    rot = rec.metadata["imulog.alignment"]["rotation_global_to_world"]
    want = quat.multiply(np.asarray(rot, np.float64)[None], orientation.values)
    assert np.allclose(np.abs(np.sum(q * want, axis=1)), 1.0, atol=1e-6)  # the same rotation (sign free)
    pose = rec.poses[0]  # the Vicon cluster: the IMU frame sits beside it at every instant
    pos = np.array([r[0] for r in shift], dtype=np.float64)
    beside = np.column_stack([np.interp(t, pose.t_ns, pose.position[:, k]) for k in range(3)]) + BESIDE_CLUSTER_M
    np.testing.assert_allclose(pos, beside, atol=1e-5)
    assert np.ptp(pos, axis=0).max() > 0.05 and np.ptp(q, axis=0).max() > 0.1  # it moves and turns
    assert [e.path for e in logged[0].by_role("imu_frame")] == [entity]
    # a device's own orientation (an Xsens export's quaternions), IMU-only: at the world origin, drawn as is
    t_dev = np.arange(200, dtype=np.int64) * 10_000_000
    angle = np.linspace(0, 2, 200)
    q_dev = np.column_stack([np.cos(angle / 2), np.zeros(200), np.zeros(200), np.sin(angle / 2)])
    device = SignalStream("/orientation/shank", t_dev, ["qw", "qx", "qy", "qz"], ["1"] * 4, q_dev)
    imu = ImuStream("shank", t_dev, acc=np.zeros((200, 3)), gyr=np.zeros((200, 3)))
    out2, logged2 = _save(tmp_path, Recording(imus=[imu], signals=[device]), "device")
    t2, xyzw2 = read_column(out2, L.imu_frame_entity("/orientation/shank"), "Transform3D:quaternion")
    np.testing.assert_allclose(np.array([r[0] for r in xyzw2])[:, [3, 0, 1, 2]], q_dev, atol=1e-6)
    assert [e.role for e in logged2[0].entities if e.topic == "/orientation/shank"] == ["orientation", "imu_frame"]
