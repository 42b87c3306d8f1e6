"""``imulog record`` killed with SIGKILL: the cut ``.part`` file salvages into a trial that passes doctor and holds
every sample that arrived up to at most 1 s before the kill (chunks are flushed every 0.5 s). A kill before the
first samples were written leaves only the file's start, which salvage names as such
(`tests/test_record_units.py`).

One replay of the short drinking trial runs while recorders are started and killed at random moments (seeded),
one after the other; ``IMULOG_RECORD_KILLS`` sets how many (3 in CI; the issue's 20 as a bench run:
``IMULOG_RECORD_KILLS=20 pytest tests/test_record_crash.py``, each kill takes about 4 s of the replay, so the
replay is repeated as often as needed).
"""

from __future__ import annotations

import json
import os
import random
import signal
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pylsl")

import test_record as base  # noqa: E402

from imulog.archive import TrialReader  # noqa: E402

trial, lsl_env = base.trial, base.lsl_env  # the fixtures
imulog, log_times, run_cli, wait_for_line = base.imulog, base.log_times, base.run_cli, base.wait_for_line

KILLS = int(os.environ.get("IMULOG_RECORD_KILLS", "3"))


def _replay(env, source: Path):
    return imulog(env, "replay", source)


@pytest.mark.slow
def test_sigkill_then_salvage(trial, lsl_env, tmp_path):
    rng = random.Random(29)
    src_log, src = log_times(trial["mcap"], "/imu/wrist")
    play = _replay(lsl_env, trial["mcap"])
    replay_started = time.time()
    lost: list[float] = []
    try:
        for k in range(KILLS):
            if time.time() - replay_started > 15:  # the 21 s trial is running out: start it again
                play.kill()
                play.wait()
                play = _replay(lsl_env, trial["mcap"])
                replay_started = time.time()
            out = tmp_path / f"cut{k}.mcap"
            rec = imulog(
                lsl_env, "record", "-o", out, "--stream", "name=wrist", "--stream", "name=vicon", "--wait", "30"
            )
            wait_for_line(rec, "first samples written")  # the kill lands after the first fsync
            time.sleep(rng.uniform(0.8, 3.0))
            killed_at = time.time()
            os.kill(rec.pid, signal.SIGKILL)
            rec.wait()
            part = Path(str(out) + ".part")
            assert part.exists() and not out.exists()
            lost.append(_check_salvaged(part, tmp_path / f"salvaged{k}.mcap", killed_at, src, src_log))
        print(f"{KILLS} kills: at most {max(lost):.2f} s of IMU samples lost before a kill")
    finally:
        play.kill()
        play.wait()


def _check_salvaged(part: Path, fixed: Path, killed_at: float, src, src_log: np.ndarray) -> float:
    """Salvage ``part``, check it; how many s before the kill its first missing IMU sample was due."""
    report = json.loads(run_cli("salvage", part, "-o", fixed, "--json"))
    assert report, report
    doctor = run_cli("doctor", fixed)
    assert ": ok" in doctor, doctor
    rec_log, rec = log_times(fixed, "/imu/wrist")
    with TrialReader(fixed) as t:
        assert "/markers/vicon" in t.topics() and "imulog.lsl.wrist" in t.metadata
    assert len(rec.t_ns) > 0
    # the recorder joined the replay mid-trial: find its first sample in the source by value
    rows = np.hstack([src.acc, src.gyr, src.mag])
    head = np.hstack([rec.acc, rec.gyr, rec.mag])[:5]
    first = [k for k in range(len(rows) - len(head) + 1) if np.array_equal(rows[k : k + len(head)], head)]
    assert len(first) == 1, first
    k0, n = first[0], len(rec.t_ns)
    np.testing.assert_array_equal(rec.acc, src.acc[k0 : k0 + n])  # every sample up to the cut, unchanged
    np.testing.assert_array_equal(rec.gyr, src.gyr[k0 : k0 + n])
    if k0 + n >= len(src.t_ns):
        return 0.0
    # when the first sample that is missing was due (on the recording's wall-clock axis)
    due = (rec_log[0] + (src_log[k0 + n] - src_log[k0])) / 1e9
    assert due >= killed_at - 1.0, f"lost {killed_at - due:.2f} s before the kill"
    return killed_at - due
