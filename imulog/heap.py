"""Keep the process heap from growing with a recording's length (glibc only; a no-op elsewhere).

The streaming steps allocate and free the same large numpy temporaries core after core (a few MB each). glibc's
malloc raises its mmap threshold every time such a block is freed (up to 32 MiB), so later blocks of that size
come from the main heap, where they fragment it: over a week of cores the resident set creeps up by tens of MB
although no Python object outlives its core (``tracemalloc`` shows a flat peak). Fixing the threshold at 128 KiB (its initial value),
as :func:`bound_heap` does, turns the dynamic adjustment off (``mallopt(3)``): every block of 128 KiB or more is
mapped on allocation and returned to the system when freed. Measured on ``imulog process metrics`` of a
simulated 1-day and 7-day recording (``benchmarks/bench_long.py``): peak RSS 261 and 309 MB (1.18x) with glibc's
default, 234 and 257 MB (1.10x) with the fixed threshold, and the step was no slower (34 s against 46 s for the
day, on a loaded machine). The core-by-core paths (metrics, orientation, phases of long recordings) call it; short
trials do not, because mapping every temporary afresh costs system time (about 0.4 s on a whole-file Nexus
conversion, measured by the convert benchmark).
"""

from __future__ import annotations

import ctypes
import os

M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter number
MMAP_THRESHOLD_BYTES = 128 << 10  # glibc's own initial value, now fixed
_done = False


def bound_heap(threshold_bytes: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Fix glibc's mmap threshold (bytes) for this process; True when it was set.

    Honours ``MALLOC_MMAP_THRESHOLD_`` if the user set it (glibc then already uses it) and does nothing on
    non-glibc systems (macOS, musl), where the call is unavailable."""
    global _done
    if _done or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt  # the C library the interpreter is linked with
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    _done = bool(mallopt(M_MMAP_THRESHOLD, int(threshold_bytes)))
    return _done
