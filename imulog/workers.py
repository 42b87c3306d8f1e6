"""The package's worker threads: chunks compressed by the archive writer and source files hashed while a converter
parses them share one small pool (zstd, crc32 and hashlib release the GIL).

``IMULOG_COMPRESS_THREADS=0`` runs everything at once on the calling thread.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

T = TypeVar("T")

PIPELINE = os.environ.get("IMULOG_COMPRESS_THREADS", "1") != "0"  # work on the worker threads
COMPRESS_THREADS = min(2, os.cpu_count() or 1)  # worker threads (each compresses one chunk at a time)

_EXECUTOR: ThreadPoolExecutor | None = None


def worker_pool() -> ThreadPoolExecutor:
    """The shared worker threads, started on first use."""
    global _EXECUTOR
    if _EXECUTOR is None:
        _EXECUTOR = ThreadPoolExecutor(max_workers=COMPRESS_THREADS, thread_name_prefix="imulog-chunk")
    return _EXECUTOR


def in_background(fn: Callable[..., T], *args: Any) -> Future[T]:
    """``fn(*args)`` on the worker threads, or at once when they are switched off (``IMULOG_COMPRESS_THREADS=0``)."""
    if PIPELINE:
        return worker_pool().submit(fn, *args)
    done: Future[T] = Future()
    done.set_result(fn(*args))
    return done


def _forget_executor() -> None:  # a forked child does not inherit the worker threads
    global _EXECUTOR
    _EXECUTOR = None


os.register_at_fork(after_in_child=_forget_executor)
