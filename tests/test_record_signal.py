"""Ctrl-C while the record / replay loop waits: the stop handler must not deadlock on the event's own lock.

The loops wait with ``stop.wait(...)`` in the main thread, and Python runs a signal handler in the main thread
between bytecodes, so the handler can run while ``Event.wait`` holds the event's (non-reentrant) lock. A handler
that called ``stop.set()`` there waited for that lock forever (``imulog simulate --lsl`` once hung 30 s after
Ctrl-C in CI). The race is made certain here by holding the lock while the signal arrives."""

from __future__ import annotations

import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import os, signal, threading
    from imulog.commands.record import _stop_on_signals

    stop = threading.Event()
    _stop_on_signals(stop)
    with stop._cond:  # what Event.wait holds for a moment on every call
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):  # the handler runs between these bytecodes, the lock held
            pass
    print("stopped" if stop.wait(10) else "not stopped")
    """
)


def test_ctrl_c_while_the_loop_holds_the_stop_events_lock_stops_it():
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "stopped"
