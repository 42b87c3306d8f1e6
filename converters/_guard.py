"""Run a third-party reader in a child process under a time and memory limit.

A reader library can loop for ever, exhaust memory or crash (a C++ reader on a corrupt file). :func:`guarded` runs
``fn(*args)`` in a forked child with an address-space limit (the child's size at the fork plus ``memory_bytes``)
and kills it after ``timeout_s``; the parent gets the result (pickled back through a pipe) or a
:class:`GuardError` whose message is one line (timed out, out of memory, crashed with signal N, or the child's
exception as ``Type: message``).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import resource
import signal
from collections.abc import Callable
from typing import Any

DEFAULT_TIMEOUT_S = 60.0
DEFAULT_MEMORY_BYTES = 1 << 30


class GuardError(RuntimeError):
    """The guarded call failed; ``kind`` is ``timeout``, ``memory``, ``crash`` or ``error``; ``exc_type`` names
    the child's exception for ``error`` (for callers that branch on it: never shown to the user)."""

    def __init__(self, kind: str, message: str, exc_type: str = "") -> None:
        super().__init__(message)
        self.kind = kind
        self.exc_type = exc_type


def _vm_size() -> int:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _child(conn, fn: Callable, args: tuple, memory_bytes: int) -> None:
    import faulthandler

    faulthandler.disable()  # a crash is reported by the parent in one line, not as a C stack dump
    try:
        if memory_bytes > 0:
            limit = _vm_size() + memory_bytes
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        result: tuple[str, Any] = ("ok", fn(*args))
    except MemoryError:
        result = ("memory", None)
    except BaseException as e:  # noqa: BLE001 - everything goes back to the parent as one line
        text = str(e).splitlines()[0] if str(e) else ""
        kind = "memory" if "bad_alloc" in text or "std::bad_alloc" in type(e).__name__ else "error"
        result = (kind, (text or "the reader failed without a message", type(e).__name__))
    try:
        conn.send_bytes(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))
    except Exception as e:  # noqa: BLE001 - e.g. an unpicklable result
        conn.send_bytes(pickle.dumps(("error", f"result could not be returned: {e}")))
    finally:
        conn.close()
        os._exit(0)


def guarded(
    fn: Callable,
    *args: Any,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    memory_bytes: int = DEFAULT_MEMORY_BYTES,
) -> Any:
    """``fn(*args)`` in a child process; raises GuardError (one-line message) when it fails in any way."""
    methods = mp.get_all_start_methods()
    ctx = mp.get_context("fork" if "fork" in methods else "spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, memory_bytes), daemon=True)
    proc.start()
    send.close()
    try:
        if not recv.poll(timeout_s):
            raise GuardError("timeout", f"did not finish within {timeout_s:g} s")
        try:
            kind, value = pickle.loads(recv.recv_bytes())
        except EOFError:
            proc.join(5)
            code = proc.exitcode
            if code is not None and code < 0:
                name = signal.Signals(-code).name if -code in signal.valid_signals() else str(-code)
                raise GuardError("crash", f"crashed ({name})") from None
            raise GuardError("crash", f"ended without a result (exit code {code})") from None
    finally:
        recv.close()
        if proc.is_alive():
            proc.kill()
        proc.join(5)
    if kind == "ok":
        return value
    if kind == "memory":
        raise GuardError("memory", f"needed more than {memory_bytes / 2**30:g} GiB of memory")
    message, exc_type = value if isinstance(value, tuple) else (str(value), "")
    raise GuardError("error", message, exc_type)


def _refusals_kept(fn: Callable, *args: Any) -> tuple[str, Any]:
    """``fn(*args)`` with a ConversionError returned as its parts (the parent raises it again, message intact)."""
    from imulog.converters.errors import ConversionError

    try:
        return ("ok", fn(*args))
    except ConversionError as e:
        return ("refused", (e.problem, e.line, e.column))


def guarded_reader(
    path: Any,
    what: str,
    fn: Callable,
    *args: Any,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    memory_bytes: int = DEFAULT_MEMORY_BYTES,
) -> Any:
    """A converter's reading function ``fn(*args)`` (which calls the third-party reader ``what``, e.g. ``h5py``) in
    the guarded child: its ConversionErrors come back unchanged; a hang, crash, runaway allocation or other
    exception becomes a ConversionError naming ``path`` and ``what``."""
    from imulog.converters.errors import ConversionError

    try:
        kind, value = guarded(_refusals_kept, fn, *args, timeout_s=timeout_s, memory_bytes=memory_bytes)
    except GuardError as e:
        raise ConversionError(path, f"{what} failed: {e}" if e.kind == "error" else f"{what} {e}") from None
    if kind == "refused":
        problem, line, column = value
        raise ConversionError(path, problem, line=line, column=column)
    return value
