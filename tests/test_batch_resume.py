"""Killing a batch mid-way (SIGKILL) and rerunning it: no corrupted file, no step computed twice."""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time

import pytest
from procs import start

from imulog.archive import TrialReader
from imulog.archive.journal import journal_path
from imulog.batch import run
from imulog.batch.ledger import LEDGER_NAME
from imulog.batch.simulated import simulate_archive
from imulog.batch.verify import check_archive

STEPS = "orientation,align,phases,trajectory,evaluate"
N_STEPS = 5


def _ledger_lines(path) -> int:
    try:
        return sum(1 for line in path.read_text().splitlines() if line.strip())
    except FileNotFoundError:
        return 0


def test_killed_batch_resumes_without_repeating_work(tmp_path):
    root = tmp_path / "archive"
    paths = simulate_archive(root, subjects=4, trials=1, repetitions=3, opening_static_s=5.0)
    ledger = root / LEDGER_NAME
    mtimes = [p.stat().st_mtime_ns for p in paths]
    cmd = [sys.executable, "-c", "from imulog.cli import main; main()", "batch", f"{root}/**/*.mcap"]
    cmd += ["--steps", STEPS, "--repetitions", "3", "-q"]
    proc = start(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # a session of its own (tests/procs.py)
    try:
        deadline = time.monotonic() + 120
        while _ledger_lines(ledger) < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        # ... and the next file has at least one step appended (so one file is killed half-processed)
        # (an append writes into the file in place: it is committed once its journal is gone, docs/archive.md)
        third = paths[2]
        while (
            proc.poll() is None
            and time.monotonic() < deadline
            and (third.stat().st_mtime_ns == mtimes[2] or journal_path(third).exists())
        ):
            time.sleep(0.005)
        assert proc.poll() is None, proc.communicate()
        os.killpg(proc.pid, signal.SIGKILL)  # the batch's own process group (it and any children)
    finally:
        if proc.poll() is None:
            proc.wait(timeout=30)
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    finished = _ledger_lines(ledger)
    assert 2 <= finished < len(paths)
    # no corrupted file after the kill: every trial passes the doctor (CRCs, summary, decoding, raw hash)
    assert check_archive(paths) == {}
    runs_before = {}
    for p in paths:
        with TrialReader(p) as trial:
            runs_before[str(p)] = len(trial.runs())
    committed = sum(runs_before.values())
    assert committed < len(paths) * N_STEPS  # the kill left work to do
    assert any(0 < n < N_STEPS for n in runs_before.values())  # ... including a half-processed file

    report = run(root, STEPS, options={"phases": {"repetitions": 3}}, progress=False)
    assert report.ok and report.failed == 0
    assert report.prechecked == finished  # files finished before the kill: skipped without being opened
    assert report.processed == len(paths) - finished
    # no work repeated: exactly the steps that had not been committed before the kill were computed
    assert report.steps_computed == len(paths) * N_STEPS - committed
    for f in report.files:
        if f.prechecked:
            assert runs_before[f.path] == N_STEPS and f.steps == []
        else:  # steps committed before the kill skip themselves; the rest run once
            assert len([s for s in f.steps if s.skipped]) == runs_before[f.path]
            assert len([s for s in f.steps if not s.skipped]) == N_STEPS - runs_before[f.path]
        with TrialReader(f.path) as trial:
            assert len(trial.runs()) == N_STEPS  # one run per step, none twice
    assert check_archive(paths) == {}
    assert not list(root.rglob("*.tmp"))  # temporary files of the killed writer are gone


@pytest.mark.slow
def test_worker_process_killed_mid_batch_is_retried(tmp_path):
    """A local worker process dies (SIGKILL) mid-batch: its files are retried in a fresh process, none lost."""
    root = tmp_path / "archive"
    paths = simulate_archive(root, subjects=4, trials=1, repetitions=3, opening_static_s=5.0)
    killed: list[int] = []

    def killer() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not killed:
            # a worker is busy once a file has been touched by a step
            busy = any(p.stat().st_mtime_ns != m for p, m in zip(paths, mtimes, strict=True))
            children = multiprocessing.active_children()
            if busy and children:
                os.kill(children[0].pid, signal.SIGKILL)
                killed.append(children[0].pid)
            time.sleep(0.01)

    mtimes = [p.stat().st_mtime_ns for p in paths]
    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    report = run(root, STEPS, options={"phases": {"repetitions": 3}}, progress=False, workers=2)
    thread.join(timeout=5)
    assert killed
    assert report.failed == 0 and report.processed == len(paths)
    assert check_archive(paths) == {}
    for p in paths:
        with TrialReader(p) as trial:
            assert len(trial.runs()) == N_STEPS
