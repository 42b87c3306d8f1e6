"""imulog record / replay over Lab Streaming Layer, on this machine only (LSL resolve scope ``machine``).

The issue's 60 s run: ``IMULOG_RECORD_FULL=1 pytest -q tests/test_record.py`` (a 67 s trial).

A short simulated drinking trial (21 s, IMU 114.9 Hz + Vicon markers 100 Hz) is replayed as two outlets and
recorded: every sample arrives with its values, the two streams keep the source's relative timing, and the
recorded trial goes through orientation, align, phases, trajectory and evaluate like the converted one. Each test
process runs an LSL session and ports of its own (tests/lsl_session.py), so other LSL users of this machine are
neither seen nor disturbed, nor can they hide its streams; every process a test starts is killed with its children
when the test ends, whatever the outcome (tests/procs.py).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from lsl_session import session_config
from procs import start

pytest.importorskip("pylsl")

from imulog.archive import TrialReader  # noqa: E402
from imulog.archive.timeline import TrialAxis  # noqa: E402
from imulog.cli import cli  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FULL_TRIAL = ["--repetitions", "1"]  # the protocol's own timings: 67 s (IMULOG_RECORD_FULL=1, the 60 s run)
SHORT_TRIAL = [
    *("--repetitions", "1", "--set", "opening_static_s=3", "--set", "post_wave_static_s=2"),
    *("--set", "closing_static_s=1", "--set", "static_s=1.5", "--set", "rest_s=1"),
    *("--set", "static_jitter_s=0.1", "--set", "rest_jitter_s=0.1"),
]


def run_cli(*args: str) -> str:
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return result.output


@pytest.fixture(scope="module")
def trial(tmp_path_factory) -> dict[str, Path]:
    """A 21 s drinking trial (with the simulator's sensor noise and dropped IMU samples), converted."""
    folder = tmp_path_factory.mktemp("sim")
    run_cli(
        "simulate", "r2g", "-o", folder / "sim", *(FULL_TRIAL if os.environ.get("IMULOG_RECORD_FULL") else SHORT_TRIAL)
    )
    stem = folder / "sim" / "r2g_s00_t00"
    out = folder / "source.mcap"
    run_cli("convert", f"{stem}_imu.csv", f"{stem}_vicon.csv", "--meta-file", f"{stem}_meta.json", "-o", out)
    return {"mcap": out, "meta": Path(f"{stem}_meta.json"), "dir": folder}


@pytest.fixture
def lsl_env(tmp_path_factory, monkeypatch) -> dict[str, str]:
    """Environment of an LSL session of this test process's own, on this machine only, with ports of its own
    (tests/lsl_session.py: another LSL program on the machine can neither hide its streams nor see them).

    One session per process: liblsl reads its configuration once, so outlets made in the test process itself
    must share the session of the commands it starts."""
    cfg = session_config(tmp_path_factory.getbasetemp())
    monkeypatch.setenv("LSLAPICFG", str(cfg))
    return dict(os.environ, LSLAPICFG=str(cfg), PYTHONPATH=str(ROOT), NO_COLOR="1")


def imulog(env: dict[str, str], *args: str, **kwargs) -> subprocess.Popen:
    """``python -m imulog ARGS`` with pipes (tests/procs.py: killed with its children when the test ends)."""
    return start(
        [sys.executable, "-m", "imulog", *map(str, args)],
        env=env,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kwargs,
    )


def wait_for_line(proc: subprocess.Popen, text: str, timeout_s: float = 30.0) -> list[str]:
    """Read ``proc``'s stderr until a line contains ``text``."""
    deadline = time.monotonic() + timeout_s
    lines = []
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line and proc.poll() is not None:
            break
        lines.append(line)
        if text in line:
            return lines
    proc.kill()
    raise AssertionError(f"no {text!r} from {proc.args}: {''.join(lines)}")


def log_times(path: Path, topic: str) -> tuple[np.ndarray, object]:
    """(MCAP log times in ns, the stream) of a channel."""
    with TrialReader(path) as t:
        stream = t.read(topic)
        imus = {c.topic.split("/")[-1] for c in t.channels if c.topic.startswith("/imu/")}
        axis = TrialAxis(t.metadata, imus)
        return axis.map_for(topic, t.channel(topic).metadata)(stream.t_ns).astype(np.int64), stream


@pytest.mark.slow
def test_replay_and_record_a_drinking_trial(trial, lsl_env, tmp_path):
    out = tmp_path / "live.mcap"
    rec = imulog(
        lsl_env, "record", "-o", out, "--stream", "name=wrist", "--stream", "type=MoCap", "--wait", "60",
        "--meta-file", trial["meta"], "--meta", "operator=test",
    )  # fmt: skip
    play = imulog(lsl_env, "replay", trial["mcap"], "--wait-consumers", "30")
    try:
        play_out, play_err = play.communicate(timeout=150)
        if play.returncode != 0:  # no recorder connected: say what the recorder said
            rec.kill()
            raise AssertionError(f"replay: {play_err}\nrecord: {rec.communicate(timeout=30)[1]}")
        time.sleep(1.0)
        rec.send_signal(signal.SIGINT)  # Ctrl-C: a clean stop with a summary
        rec_out, rec_err = rec.communicate(timeout=30)
    finally:
        for p in (rec, play):
            if p.poll() is None:
                p.kill()
    assert rec.returncode == 0, rec_err
    assert "found 2 stream(s)" in rec_err and "wrist (type IMU, 9 x double64" in rec_err
    assert "wrote" in rec_out and "wrist:" in rec_out and "0 rejected" in rec_out
    assert not Path(str(out) + ".part").exists()

    src_imu_log, src_imu = log_times(trial["mcap"], "/imu/wrist")
    src_mk_log, src_mk = log_times(trial["mcap"], "/markers/vicon")
    rec_imu_log, rec_imu = log_times(out, "/imu/wrist")
    rec_mk_log, rec_mk = log_times(out, "/markers/vicon")
    # at least 99.9 % of the samples (on loopback: all of them), with the source's values
    assert len(rec_imu.t_ns) >= 0.999 * len(src_imu.t_ns) and len(rec_imu.t_ns) <= len(src_imu.t_ns)
    assert len(rec_mk.t_ns) >= 0.999 * len(src_mk.t_ns) and len(rec_mk.t_ns) <= len(src_mk.t_ns)
    n, k = len(rec_imu.t_ns), len(rec_mk.t_ns)
    np.testing.assert_array_equal(rec_imu.acc, src_imu.acc[:n])
    np.testing.assert_array_equal(rec_imu.gyr, src_imu.gyr[:n])
    np.testing.assert_array_equal(rec_imu.mag, src_imu.mag[:n])
    np.testing.assert_array_equal(rec_mk.pos, src_mk.pos[:k])
    assert rec_mk.labels == src_mk.labels
    # relative timing of the two streams: one offset (source axis -> recorder clock) within 2 ms for every sample
    d = np.concatenate([rec_imu.t_ns - src_imu_log[:n], rec_mk.t_ns - src_mk_log[:k]]).astype(np.float64)
    assert np.max(np.abs(d - np.median(d))) < 2e6, np.max(np.abs(d - np.median(d)))
    # the IMU's dropped samples (simulated Bluetooth losses) are gaps in the recording too, not invented samples
    with TrialReader(trial["mcap"]) as src, TrialReader(out) as live:
        assert live.channel("/imu/wrist").metadata["time_gaps"] == src.channel("/imu/wrist").metadata["time_gaps"]
        meta = live.metadata
        assert live.channel("/signals/wrist_lsl_clock").sample_count == n
        clock = live.read("/signals/wrist_lsl_clock").values
    assert meta["imulog.trial"]["operator"] == "test" and meta["imulog.trial"]["task"] == "r2g"
    assert meta["imulog.trial"]["start_time"].endswith("+00:00")
    assert (
        "<name>wrist</name>" in meta["imulog.lsl.wrist"]["xml"]
        and "<unit>rad/s</unit>" in meta["imulog.lsl.wrist"]["xml"]
    )
    assert meta["imulog.record"]["streams"]["wrist"]["samples"] == n
    assert meta["imulog.timeline"]["clocks"] == "shared"
    # raw stamps kept: raw + applied offset = the trial's time
    np.testing.assert_allclose((clock[:, 0] + clock[:, 1]) * 1e9, rec_imu.t_ns, atol=2)
    assert "ok" in run_cli("doctor", out)

    # the recorded trial goes through the processing chain with the converted trial's result
    records = []
    for path in (trial["mcap"], out):
        for step in ("orientation", "align", "phases", "trajectory"):
            run_cli("process", step, path)
        assert "±" in run_cli("evaluate", path)  # the table is printed
        with TrialReader(path) as t:
            records.append(t.metadata["imulog.evaluation"]["methods"])
    # compared at full precision from the imulog.evaluation record: the printed table rounds to 3 significant
    # digits, so a 46.05 cm error can print as 46.0 on one trial and 46.1 on the other
    assert len(records[0]) >= 5 and records[0].keys() == records[1].keys(), records  # one row per method
    for method, rec in records[0].items():  # the same errors (cm), up to the recorder's clock-offset jitter (us)
        for axis in ("x", "y", "z"):
            np.testing.assert_allclose(
                records[1][method]["summary"][axis]["mae_cm"]["mean"],
                rec["summary"][axis]["mae_cm"]["mean"],
                atol=0.05,
                err_msg=f"{method} {axis}",
            )


def test_existing_output_is_refused(trial, lsl_env, tmp_path):
    out = tmp_path / "kept.mcap"
    out.write_bytes(b"not mine")
    rec = imulog(lsl_env, "record", "-o", out, "--wait", "0.2")
    _, err = rec.communicate(timeout=30)
    assert rec.returncode != 0 and "exists (use --overwrite)" in err
    assert out.read_bytes() == b"not mine"
    out.unlink()
    Path(str(out) + ".part").write_bytes(b"cut")
    rec = imulog(lsl_env, "record", "-o", out, "--wait", "0.2")
    _, err = rec.communicate(timeout=30)
    assert rec.returncode != 0 and f"imulog salvage {out}.part" in err


def test_no_matching_stream_names_what_is_visible(lsl_env):
    import pylsl

    info = pylsl.StreamInfo("emg_left", "EMG", 2, 1000, "float32", "emg-1")
    outlet = pylsl.StreamOutlet(info)
    rec = imulog(lsl_env, "record", "-o", "never.mcap", "--stream", "name=wrist", "--wait", "1.5")
    _, err = rec.communicate(timeout=30)
    del outlet
    assert rec.returncode != 0
    assert "no LSL stream matches name=wrist within 1.5 s" in err and "emg_left (type EMG" in err
    bad = imulog(lsl_env, "record", "-o", "never.mcap", "--stream", "colour=red")
    _, err = bad.communicate(timeout=30)
    assert bad.returncode == 2 and "name=, type=, source_id=VALUE" in err


def test_nothing_visible_names_the_lsl_configuration(lsl_env):
    """Nothing in the test's session: the error says which configuration (session, scope, ports) was searched."""
    rec = imulog(lsl_env, "record", "-o", "never.mcap", "--stream", "name=wrist", "--wait", "0.5")
    _, err = rec.communicate(timeout=30)
    cfg = Path(lsl_env["LSLAPICFG"]).read_text().splitlines()
    session = next(ln.split("=")[1].strip() for ln in cfg if ln.startswith("SessionID"))
    assert rec.returncode == 1
    assert f"(visible: none; LSL configuration {lsl_env['LSLAPICFG']}: SessionID {session}, ResolveScope machine" in err


def test_streams_sharing_a_name_are_listed_with_their_source_ids(lsl_env):
    """Two programs' streams of one name: record warns, with each one's source_id, and source_id= picks one."""
    import pylsl

    outlets = [pylsl.StreamOutlet(pylsl.StreamInfo("wrist", "IMU", 3, 100, "float32", f"dev-{k}")) for k in "ab"]
    listed = imulog(lsl_env, "record", "--list", "--wait", "1.5")
    _, err = listed.communicate(timeout=30)
    one = imulog(lsl_env, "record", "--list", "--stream", "source_id=dev-b", "--wait", "5")
    _, err_one = one.communicate(timeout=30)
    del outlets
    assert listed.returncode == 0 and "found 2 stream(s)" in err, err
    assert "warning: 2 streams are named wrist (source_id dev-" in err and "--stream source_id=..." in err
    assert "source_id dev-a on host" in err and "source_id dev-b on host" in err
    assert one.returncode == 0 and "found 1 stream(s)" in err_one and "source_id dev-b" in err_one
    assert "warning" not in err_one


def test_every_stream_events_and_signals_sigterm(lsl_env, tmp_path):
    """Without --stream every visible stream is recorded: an EMG stream as a signal, string markers as events;
    SIGTERM stops cleanly with the summary."""
    import threading

    import pylsl

    emg_info = pylsl.StreamInfo("EMG", "EMG", 2, 200, "double64", "emg-test")
    chans = emg_info.desc().append_child("channels")
    for label in ("biceps", "triceps"):
        ch = chans.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", "mV")
    emg = pylsl.StreamOutlet(emg_info)
    cues = pylsl.StreamOutlet(pylsl.StreamInfo("Cues", "Markers", 1, 0, "string", "cues-test"))
    stop = threading.Event()
    sent = {"emg": 0, "cues": []}

    def push() -> None:
        while not stop.is_set() and sent["emg"] < 2000:
            emg.push_chunk([[0.001 * (sent["emg"] + j), -1.0] for j in range(10)])
            sent["emg"] += 10
            if sent["emg"] % 200 == 0:
                label = f"cue {len(sent['cues'])}"
                cues.push_sample([label])
                sent["cues"].append(label)
            time.sleep(0.05)

    out = tmp_path / "all.mcap"
    rec = imulog(lsl_env, "record", "-o", out, "--wait", "2")
    pusher = threading.Thread(target=push)
    try:
        head = "".join(wait_for_line(rec, "recording into"))
        pusher.start()
        time.sleep(4.0)
        rec.send_signal(signal.SIGTERM)
        rec_out, rec_err = rec.communicate(timeout=30)
    finally:
        stop.set()
        if pusher.is_alive():
            pusher.join()
        if rec.poll() is None:
            rec.kill()
    assert rec.returncode == 0, rec_err
    assert "found 2 stream(s)" in head and "Cues (type Markers, 1 x string, irregular" in head
    assert "2 stream(s)," in rec_out and "emg:" in rec_out and "wrote" in rec_out
    with TrialReader(out) as t:
        signals = t.read("/signals/emg")
        events = t.read("/events/cues")
        assert t.metadata["imulog.device.emg"]["stream_type"] == "EMG"
    assert signals.columns == ["biceps", "triceps"] and signals.units == ["mV", "mV"]
    assert len(signals.t_ns) >= 200
    np.testing.assert_array_equal(signals.values[:, 1], -1.0)
    np.testing.assert_allclose(np.diff(signals.values[:, 0]), 0.001, atol=1e-9)  # consecutive, none lost
    assert events.labels == sent["cues"][: len(events.labels)] and len(events.labels) >= 2


def test_simulate_lsl_streams_the_trial_live(lsl_env, tmp_path):
    """``imulog simulate ... --lsl`` writes the trial files, then streams the trial: record receives it."""
    sim = imulog(lsl_env, "simulate", "r2g", "-o", tmp_path / "sim", *SHORT_TRIAL, "--lsl")
    out = tmp_path / "sim_live.mcap"
    try:
        rec = imulog(lsl_env, "record", "-o", out, "--stream", "name=wrist", "--stream", "name=vicon", "--wait", "30",
                     "--duration", "2")  # fmt: skip
        rec_out, rec_err = rec.communicate(timeout=60)
        assert rec.returncode == 0, rec_err
    finally:
        sim.send_signal(signal.SIGINT)  # Ctrl-C ends the stream
        sim_out, _ = sim.communicate(timeout=30)
    assert sim.returncode == 0 and "streaming r2g_s00_t00 live" in sim_out and "sent wrist" in sim_out
    assert (tmp_path / "sim" / "r2g_s00_t00_meta.json").exists()
    with TrialReader(out) as t:
        # 2 s from the first sample of either stream (the trial's IMU and Vicon do not start at the same moment)
        assert 100 <= t.channel("/imu/wrist").sample_count <= 231
        assert 100 <= t.channel("/markers/vicon").sample_count <= 201
    bad = imulog(lsl_env, "simulate", "home", "-o", tmp_path / "home", "--lsl")
    _, err = bad.communicate(timeout=60)
    assert bad.returncode == 2 and "--lsl streams a lab trial" in err
