"""Run reprocessing steps over many trials: in this process, in local worker processes, or on a Dask cluster.

    from imulog.batch import run
    report = run("archive/**/*.mcap", ["orientation", "align", "phases", "trajectory", "evaluate"],
                 workers=2, options={"phases": {"repetitions": 25}})
    print(report.summary())

Every file is independent: a failing file is recorded in the report and the others go on. Files are handed
out a few at a time (at most ``2 * workers`` in flight), so memory does not grow with the archive. The
driver keeps a ledger (:mod:`imulog.batch.ledger`) so a rerun skips finished files without opening them,
and each step skips itself when its inputs and parameters are already recorded in the file, so an
interrupted batch rerun finishes only what is left.
"""

from __future__ import annotations

import glob
import os
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imulog.batch.ledger import Ledger, default_ledger_path, plan_hash
from imulog.batch.registry import FileResult, normalize_options, parse_steps, plan_fingerprint, run_file

AUTO = "auto"


def expand_paths(items: str | os.PathLike[str] | Iterable[str | os.PathLike[str]]) -> list[str]:
    """Files from paths, folders (every ``*.mcap`` below) and glob patterns (``**`` recursive), sorted, unique.

    A path that does not exist is kept (the batch reports it as failed); a pattern matching nothing is dropped.
    """
    if isinstance(items, str | os.PathLike):
        items = [items]
    out: list[str] = []
    for item in items:
        text = os.fspath(item)
        if any(ch in text for ch in "*?["):
            out.extend(sorted(p for p in glob.glob(text, recursive=True) if os.path.isfile(p)))
        elif os.path.isdir(text):
            out.extend(sorted(str(p) for p in Path(text).rglob("*.mcap") if p.is_file() and not p.name.startswith(".")))
        else:
            out.append(text)
    seen: set[str] = set()
    unique = []
    for p in out:
        key = os.path.abspath(p)
        if key not in seen:
            seen.add(key)
            unique.append(p)
    return unique


@dataclass
class BatchReport:
    """Outcome of :func:`run`: one :class:`FileResult` per file, in input order."""

    steps: list[str]
    options: dict[str, dict[str, Any]]
    files: list[FileResult] = field(default_factory=list)
    seconds: float = 0.0
    engine: str = "serial"
    workers: int = 1
    ledger: str | None = None

    def count(self, status: str) -> int:
        return sum(f.status == status for f in self.files)

    @property
    def processed(self) -> int:
        """Files where at least one step computed and wrote."""
        return self.count("processed")

    @property
    def up_to_date(self) -> int:
        """Files with nothing to do (ledger pre-check or every step already recorded)."""
        return self.count("up_to_date")

    @property
    def prechecked(self) -> int:
        """Up-to-date files skipped by the ledger without being opened."""
        return sum(f.prechecked for f in self.files)

    @property
    def failed(self) -> int:
        return self.count("failed")

    @property
    def cancelled(self) -> int:
        """Files not run because the batch stopped early (``continue_on_error=False``)."""
        return self.count("cancelled")

    @property
    def ok(self) -> bool:
        return self.failed == 0 and self.cancelled == 0

    @property
    def steps_computed(self) -> int:
        return sum(f.computed for f in self.files)

    @property
    def steps_skipped(self) -> int:
        return sum(len(f.steps) - f.computed for f in self.files)

    @property
    def files_per_s(self) -> float:
        return len(self.files) / self.seconds if self.seconds > 0 else float("nan")

    def failures(self) -> list[FileResult]:
        return [f for f in self.files if f.status == "failed"]

    def step_seconds(self) -> dict[str, list[float]]:
        """Wall time (s) of each computed (not skipped) step, per step name."""
        out: dict[str, list[float]] = {}
        for f in self.files:
            for s in f.steps:
                if not s.skipped:
                    out.setdefault(s.step, []).append(s.seconds)
        return out

    def summary(self) -> str:
        """A few lines for people: counts, time, failures with their reason."""
        lines = [
            f"{len(self.files)} files, steps {','.join(self.steps)} ({self.engine}, {self.workers} worker"
            f"{'s' if self.workers != 1 else ''}): {self.processed} processed, {self.up_to_date} up to date "
            f"({self.prechecked} by the ledger pre-check), {self.failed} failed"
            + (f", {self.cancelled} cancelled" if self.cancelled else "")
            + f"; {self.steps_computed} steps computed, {self.steps_skipped} skipped; "
            f"{self.seconds:.1f} s ({self.files_per_s:.2f} files/s)"
        ]
        for f in self.failures():
            lines.append(f"FAILED {f.path}: {f.error}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "steps": self.steps,
            "options": self.options,
            "engine": self.engine,
            "workers": self.workers,
            "seconds": self.seconds,
            "ledger": self.ledger,
            "counts": {
                "files": len(self.files),
                "processed": self.processed,
                "up_to_date": self.up_to_date,
                "prechecked": self.prechecked,
                "failed": self.failed,
                "cancelled": self.cancelled,
                "steps_computed": self.steps_computed,
                "steps_skipped": self.steps_skipped,
            },
            "files": [f.to_dict() for f in self.files],
        }


# ---------------------------------------------------------------------------------------------- engines


def _run_serial(todo, plan, force, on_done, should_stop) -> None:
    for i, path in todo:
        if should_stop():
            return
        on_done(i, run_file(path, plan, force))


def _run_processes(todo, plan, force, on_done, should_stop, workers: int) -> None:
    """Local worker processes (spawn: safe with threads, numba and any platform).

    If a worker process dies (killed, out of memory, a crash in native code), the pool breaks: the files that
    were in flight are retried one at a time, each in a fresh single-worker pool, so only a file that kills its
    worker again is reported failed; the rest of the queue then continues in a new pool.
    """
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    queue = list(reversed(todo))

    def finish(fut, i: int, path: str) -> bool:
        """Report the future's result; False when the pool broke under it."""
        try:
            result = fut.result()
        except BrokenProcessPool:
            return False
        except Exception as exc:  # e.g. a result that cannot be pickled: report the file
            result = FileResult(path, "failed", error=f"worker error: {type(exc).__name__}: {exc}")
        on_done(i, result)
        return True

    while queue and not should_stop():
        suspects: list[tuple[int, str]] = []
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
            inflight: dict[Any, tuple[int, str]] = {}
            while queue or inflight:
                while queue and len(inflight) < 2 * workers and not should_stop():
                    i, path = queue.pop()
                    inflight[pool.submit(run_file, path, plan, force)] = (i, path)
                if not inflight:
                    break
                done, _ = wait(list(inflight), return_when=FIRST_COMPLETED)
                for fut in done:
                    i, path = inflight.pop(fut)
                    if not finish(fut, i, path):
                        suspects.append((i, path))
                if suspects:  # the pool is broken: everything still in flight is a suspect too
                    suspects.extend(inflight.values())
                    break
        for i, path in sorted(suspects):
            with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as alone:
                fut = alone.submit(run_file, path, plan, force)
                if not finish(fut, i, path):
                    on_done(i, FileResult(path, "failed", error="the worker process died while processing this file"))


def _run_dask(todo, plan, force, on_done, should_stop, scheduler, workers: int) -> int:
    """Tasks on a dask.distributed cluster (``scheduler``: an address or a ``distributed.Client``)."""
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - dask is an optional extra
        raise RuntimeError("--dask-scheduler needs dask.distributed: pip install 'imulog[dask]'") from exc

    own = not isinstance(scheduler, Client)
    client = Client(scheduler) if own else scheduler
    try:
        n_workers = max(1, len(client.scheduler_info().get("workers", {})))
        limit = max(2 * n_workers, 2 * workers, 2)
        queue = list(reversed(todo))
        keys: dict[str, tuple[int, str]] = {}
        ac = as_completed()

        def submit() -> None:
            i, path = queue.pop()
            fut = client.submit(run_file, path, plan, force, pure=False)
            keys[fut.key] = (i, path)
            ac.add(fut)

        while queue and len(keys) < limit:
            submit()
        for fut in ac:
            i, path = keys.pop(fut.key)
            try:
                result = fut.result()
            except Exception as exc:  # the task itself died (worker lost...): report the file
                result = FileResult(path, "failed", error=f"dask task failed: {type(exc).__name__}: {exc}")
            on_done(i, result)
            if queue and not should_stop():
                submit()
        return n_workers
    finally:
        if own:
            client.close()


# ---------------------------------------------------------------------------------------------- API


def run(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    steps: str | list[str] | tuple[str, ...],
    *,
    workers: int = 1,
    dask_scheduler: Any = None,
    options: dict[str, dict[str, Any]] | None = None,
    progress: bool = True,
    force: bool = False,
    continue_on_error: bool = True,
    ledger: str | os.PathLike[str] | None = AUTO,
    on_file: Callable[[FileResult], None] | None = None,
) -> BatchReport:
    """Run ``steps`` on every trial in ``paths`` (files, folders, glob patterns); return a :class:`BatchReport`.

    steps: names from :data:`imulog.batch.registry.STEPS`, run in dependency order.
    workers: local processes (1 = in this process). dask_scheduler: a scheduler address (``tcp://host:8786``)
        or a ``distributed.Client``; runs the files as Dask tasks instead (workers must see the same paths).
    options: ``{step: {option: value}}`` (see :mod:`imulog.batch.registry`); validated before any file.
    force: recompute every step even when up to date (also bypasses the ledger).
    continue_on_error: False stops handing out files after the first failure (the rest are ``cancelled``).
    ledger: the pre-check file; ``"auto"`` = ``.imulog-batch.jsonl`` beside the trials, None = no ledger.
    on_file: called in this process with each :class:`FileResult` as it completes.
    """
    step_names = parse_steps(steps)
    opts = normalize_options(step_names, options)
    plan = [(s, opts[s]) for s in step_names]
    pid = plan_hash(plan_fingerprint(step_names, opts))
    files = expand_paths(paths)
    if ledger == AUTO:
        ledger = default_ledger_path(files)
    book = Ledger(ledger)
    engine = "dask" if dask_scheduler is not None else ("processes" if workers > 1 else "serial")
    report = BatchReport(step_names, opts, engine=engine, workers=max(1, workers), ledger=str(ledger or "") or None)
    results: list[FileResult | None] = [None] * len(files)
    t0 = time.perf_counter()
    bar = None
    if progress and files:
        from imulog.console import progress_bar  # tqdm on a terminal, plain lines in logs

        bar = progress_bar(len(files), "batch", unit="file")
    state = {"failed": 0}

    def on_done(i: int, result: FileResult) -> None:
        results[i] = result
        if result.status == "failed":
            state["failed"] += 1
        elif not result.prechecked:
            try:
                book.record(result.path, pid)
            except OSError as exc:  # a read-only folder: keep going without the pre-check
                print(f"imulog batch: cannot write the ledger {book.path}: {exc}", file=sys.stderr)
                book.path = None
        if on_file is not None:
            on_file(result)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(failed=state["failed"], refresh=False)

    def should_stop() -> bool:
        return not continue_on_error and state["failed"] > 0

    try:
        todo = []
        for i, path in enumerate(files):
            if not force and book.is_current(path, pid):
                on_done(i, FileResult(path, "up_to_date", prechecked=True, worker="ledger"))
            else:
                todo.append((i, path))
        if todo:
            if dask_scheduler is not None:
                report.workers = _run_dask(todo, plan, force, on_done, should_stop, dask_scheduler, workers)
            elif workers > 1:
                _run_processes(todo, plan, force, on_done, should_stop, min(workers, len(todo)))
            else:
                _run_serial(todo, plan, force, on_done, should_stop)
    finally:
        book.close()
        if bar is not None:
            bar.close()
    report.files = [r if r is not None else FileResult(files[i], "cancelled") for i, r in enumerate(results)]
    report.seconds = time.perf_counter() - t0
    return report
