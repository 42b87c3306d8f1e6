"""imulog.heap: freed large blocks go back to the system (glibc), so long steps do not creep up core by core."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

PROBE = textwrap.dedent(
    """
    import sys
    import numpy as np
    from imulog.heap import bound_heap

    def rss_kb():
        for line in open("/proc/self/status"):
            if line.startswith("VmRSS:"):
                return int(line.split()[1])

    if sys.argv[1] == "bound":
        assert bound_heap()
    big = np.ones(24 << 17)  # 24 MiB: mapped; freeing it raises glibc's dynamic mmap threshold
    del big
    before = rss_kb()
    mid = np.ones(16 << 17)  # 16 MiB: from the heap once the threshold was raised, mapped with bound_heap
    del mid
    print(rss_kb() - before)
    """
)


def _retained_kb(mode: str) -> int:
    env = {"PATH": "/usr/bin:/bin"}  # no MALLOC_* variables from the caller
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, env=env, check=True)
    return int(out.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt; a no-op elsewhere")
def test_freed_large_arrays_return_to_the_system():
    default = _retained_kb("default")
    if default < 12_000:
        pytest.skip(f"this C library does not keep freed 16 MiB blocks ({default} kB retained): nothing to fix")
    assert _retained_kb("bound") < 4_000  # the 16 MiB block was unmapped on free


def test_bound_heap_respects_the_users_setting(monkeypatch):
    import imulog.heap as heap

    monkeypatch.setattr(heap, "_done", False)
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "65536")
    assert heap.bound_heap() is False


FAULTS = textwrap.dedent(
    """
    import resource
    import sys
    import numpy as np
    from imulog.heap import bound_heap, reuse_heap

    assert (reuse_heap if sys.argv[1] == "reuse" else bound_heap)()
    np.ones(360_000)  # one hour's column at 100 Hz (2.9 MB) once, so both start from a heap that held one
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(20):  # the same temporary core after core
        a = np.ones(360_000)
        del a
    print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    """
)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt; a no-op elsewhere")
def test_reuse_heap_faults_a_repeated_temporary_in_once():
    """20 allocations of the same 2.9 MB temporary: mapped afresh each time with bound_heap (about 700 page
    faults each), the heap's pages reused with reuse_heap."""
    env = {"PATH": "/usr/bin:/bin"}
    runs = {}
    for mode in ("bound", "reuse"):
        out = subprocess.run([sys.executable, "-c", FAULTS, mode], capture_output=True, text=True, env=env, check=True)
        runs[mode] = int(out.stdout.strip())
    assert runs["bound"] > 20 * 500  # each block faulted in again, 4 KiB page by page
    assert runs["reuse"] < runs["bound"] / 10
