"""tests/procs.py: a process a test starts dies with its children when the test ends, on every exit path (here: a
``communicate`` that timed out, the way ``test_simulate_lsl_streams_the_trial_live`` left its ``imulog simulate
--lsl`` streaming before)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from procs import kill_all, start

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states in /proc")

TESTS = Path(__file__).resolve().parent

#: a parent that starts a child in a session of its own (out of the parent's process group), prints both pids and
#: sleeps: what ``imulog simulate --lsl`` or ``imulog record --view`` (with its Rerun server) look like to a test
FAMILY = (
    "import subprocess, sys, time\n"
    "kid = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(300)'], start_new_session=True)\n"
    "print(f'{kid.pid}', flush=True)\n"
    "time.sleep(300)\n"
)


def alive(pid: int) -> bool:
    """``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def wait_dead(pids: list[int], timeout_s: float = 10.0) -> list[int]:
    """The pids still alive after ``timeout_s`` (killed processes are reaped by their parent or init)."""
    deadline = time.monotonic() + timeout_s
    while any(alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return [p for p in pids if alive(p)]


def test_kill_all_takes_the_children_along():
    proc = start([sys.executable, "-c", FAMILY], stdout=subprocess.PIPE, text=True)
    kid = int(proc.stdout.readline())
    assert alive(proc.pid) and alive(kid)
    kill_all()
    assert wait_dead([proc.pid, kid]) == []
    assert proc.returncode is not None and proc.stdout.closed


INNER = """
import subprocess, sys
sys.path.insert(0, {tests!r})
from procs import kill_started, start  # noqa: F401  (the autouse fixture, as tests/conftest.py has it)

def test_times_out():
    proc = start([sys.executable, "-c", {family!r}], stdout=subprocess.PIPE, text=True)
    kid = proc.stdout.readline().strip()
    with open({pids!r}, "w") as f:
        f.write(f"{{proc.pid}} {{kid}}")
    proc.communicate(timeout=0.2)  # TimeoutExpired: the test fails here, nothing after it runs
"""


def test_a_test_that_times_out_leaves_no_process(tmp_path):
    pids = tmp_path / "pids.txt"
    inner = tmp_path / "test_inner.py"
    inner.write_text(INNER.format(tests=str(TESTS), family=FAMILY, pids=str(pids)))
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly", str(inner)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert done.returncode == 1 and "TimeoutExpired" in done.stdout, done.stdout + done.stderr
    started = [int(p) for p in pids.read_text().split()]
    assert len(started) == 2
    assert wait_dead(started) == [], f"left running: {started}"


@pytest.mark.parametrize("timeout", [0.5, 30.0])
def test_run_ends_a_shells_background_job(tmp_path, timeout):
    """procs.run (the docs pages' runs): a shell's background job ends with the shell, whether the shell times out
    or returns (subprocess.run killed the shell alone on a timeout, and nothing on a return)."""
    from procs import run

    pid_file = tmp_path / "job.pid"
    # (a job that keeps the shell's output pipes open makes communicate wait for it: the timeout case then)
    script = f"sleep 300 > /dev/null 2>&1 & echo $! > {pid_file}; " + ("sleep 300" if timeout < 1 else "true")
    if timeout < 1:
        with pytest.raises(subprocess.TimeoutExpired):
            run(["bash", "-c", script], timeout=timeout, capture_output=True, text=True)
    else:
        assert run(["bash", "-c", script], timeout=timeout, capture_output=True, text=True).returncode == 0
    assert wait_dead([int(pid_file.read_text())]) == []
