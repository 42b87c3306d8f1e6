"""Subprocesses of tests, killed with their children on every exit path.

A test that starts a process with :func:`start` (``subprocess.Popen``'s arguments) gets it in a process group of
its own; the autouse fixture :func:`kill_started` (in ``conftest.py``) then kills, after the test whatever its
outcome (passed, failed assertion, ``TimeoutExpired``, interrupted), every process it started that is still
there, with all their descendants: the process groups, and on Linux any descendant found in ``/proc`` (one
that started a session of its own too). A test may stop its processes itself first (a clean Ctrl-C, its own
kill); the fixture is what no exit path can skip. :func:`run` is ``subprocess.run``'s counterpart, which
cleans up after itself (for a thread that outlives a test, as the docs pages' runs do).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

_started: list[subprocess.Popen] = []


def start(args, **kwargs) -> subprocess.Popen:
    """``subprocess.Popen(args, **kwargs)`` in a new session (its own process group), killed after the test."""
    proc = subprocess.Popen(args, start_new_session=True, **kwargs)
    _started.append(proc)
    return proc


def _parents() -> dict[int, int]:
    """pid -> parent pid of every process in ``/proc`` (empty where there is no ``/proc``)."""
    out = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError, ValueError, IndexError):
            fields = stat.read_text().rsplit(")", 1)[1].split()  # after "(comm)", which may hold spaces
            out[int(stat.parent.name)] = int(fields[1])
    return out


def descendants(pid: int) -> list[int]:
    """The pids of ``pid``'s children, their children, ... (Linux ``/proc``; ``[]`` elsewhere)."""
    parents = _parents()
    found, frontier = [], [pid]
    while frontier:
        kids = [p for p, parent in parents.items() if parent in frontier]
        found += kids
        frontier = kids
    return found


def kill(proc: subprocess.Popen) -> None:
    """SIGKILL ``proc``, its process group and its descendants; reap it and close its pipes."""
    # an unreaped leader (running, or a zombie) keeps its pid ours: its descendants can be looked up safely
    victims = [proc.pid, *descendants(proc.pid)] if proc.returncode is None else []
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)  # the group outlives its leader while a member is left
    for pid in victims:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=30)
    for pipe in (proc.stdin, proc.stdout, proc.stderr):
        if pipe is not None:
            with contextlib.suppress(OSError):
                pipe.close()


def run(args, *, timeout: float, **kwargs) -> subprocess.CompletedProcess:
    """``subprocess.run(args, timeout=timeout, **kwargs)`` (``capture_output``, ``text``, ...) in a session of its
    own, whose group and descendants are killed when it returns, fails or times out: ``subprocess.run`` kills only
    the child on a timeout, and a shell's background job (``imulog replay ... &`` in a docs page) outlived it.
    Not left to :func:`kill_started` (it cleans up itself), so it may run on a thread that outlives a test."""
    if kwargs.pop("capture_output", False):
        kwargs.update(stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc = subprocess.Popen(args, start_new_session=True, **kwargs)
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        kill(proc)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def kill_all() -> None:
    """:func:`kill` every process :func:`start` started since the last call."""
    while _started:
        kill(_started.pop())


@pytest.fixture(autouse=True)
def kill_started() -> Iterator[None]:
    """After each test, every process it started with :func:`start` is killed with its children."""
    yield
    kill_all()
