"""Keep the process heap from growing with a recording's length (glibc only; a no-op elsewhere).

The streaming steps allocate and free the same large numpy temporaries core after core (a few MB each). glibc's
malloc raises its mmap threshold every time such a block is freed (up to 32 MiB), so later blocks of that size
come from the main heap, where they fragment it: over a week of cores the resident set creeps up by tens of MB
although no Python object outlives its core (``tracemalloc`` shows a flat peak). Fixing the threshold at 128 KiB (its initial value),
as :func:`bound_heap` does, turns the dynamic adjustment off (``mallopt(3)``): every block of 128 KiB or more is
mapped on allocation and returned to the system when freed. Measured on ``imulog process metrics`` of a
simulated 1-day and 7-day recording (``benchmarks/bench_long.py``): peak RSS 261 and 309 MB (1.18x) with glibc's
default, 234 and 257 MB (1.10x) with the fixed threshold, and the step was no slower (34 s against 46 s for the
day, on a loaded machine). The window-by-window paths of trajectory and kinematics call it; short
trials do not, because mapping every temporary afresh costs system time (about 0.4 s on a whole-file Nexus
conversion, measured by the convert benchmark).

That system time is not small on the longest steps: every temporary of an hour's core (a column of 360,000
samples is 2.9 MB) is mapped, faulted in page by page and unmapped again. ``imulog process orientation`` of a
simulated day spent 8.7 s of its 26 s CPU in the kernel (3.3 M minor page faults) with the 128 KiB threshold.
:func:`reuse_heap` does the opposite: blocks up to 32 MiB come from the heap and freed memory is kept there (trim
threshold 256 MiB, top pad 64 MiB), so the next core reuses the pages already faulted in: 0.4 s system time
(83 k faults), peak RSS 438 MB against 389 MB, on the same day (loaded machine, ``/usr/bin/time``). Orientation,
phases and metrics call it: with it their peak RSS grew 1.05-1.07x from a simulated day to a week
(docs/long_recordings.md), within issue 24's 1.15x, where glibc's default had given metrics 1.18x.

``imulog convert`` in pieces uses :func:`bound_heap` for readers whose pieces vary in size (text, XDF, BIDS: with
:func:`reuse_heap` their peak grew more from 1 to 4 hours, e.g. BIDS 1.69x -> 1.79x, Xsens 1.11x -> 1.18x,
``benchmarks/bench_convert_pieces.py``) and :func:`reuse_heap` for fixed-size pieces (``Converter.fixed_pieces``:
the ``.cwa``), where a simulated day then spent 0.3 s in the kernel instead of 5.1 s (1.8 M minor faults).
"""

from __future__ import annotations

import ctypes
import os

M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3  # glibc's mallopt parameter numbers
MMAP_THRESHOLD_BYTES = 128 << 10  # glibc's own initial value, now fixed
REUSE_MMAP_BYTES = 32 << 20  # the largest threshold glibc accepts on 64-bit systems (HEAP_MAX_SIZE / 2)
REUSE_TRIM_BYTES = 256 << 20  # freed memory kept at the top of the heap before it is returned
REUSE_PAD_BYTES = 64 << 20  # extra heap requested at each growth (fewer brk calls)
_done = False


def bound_heap(threshold_bytes: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Fix glibc's mmap threshold (bytes) for this process; True when it was set.

    Honours ``MALLOC_MMAP_THRESHOLD_`` if the user set it (glibc then already uses it) and does nothing on
    non-glibc systems (macOS, musl), where the call is unavailable."""
    global _done
    if _done or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    mallopt = _mallopt()
    if mallopt is None:
        return False
    _done = bool(mallopt(M_MMAP_THRESHOLD, int(threshold_bytes)))
    return _done


def reuse_heap() -> bool:
    """Keep freed blocks below 32 MiB in the heap for the next core to reuse (no page faults again); True when
    set. Like :func:`bound_heap`, honours the user's ``MALLOC_*`` settings and is a no-op without glibc; the
    first of the two called in a process wins."""
    global _done
    if _done or any(k.startswith("MALLOC_") for k in os.environ):
        return False
    mallopt = _mallopt()
    if mallopt is None:
        return False
    _done = bool(mallopt(M_MMAP_THRESHOLD, REUSE_MMAP_BYTES))
    if _done:
        mallopt(M_TRIM_THRESHOLD, REUSE_TRIM_BYTES)
        mallopt(M_TOP_PAD, REUSE_PAD_BYTES)
    return _done


def _mallopt():
    """glibc's ``mallopt`` (from the C library the interpreter is linked with), or None where there is none."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return None
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return mallopt
