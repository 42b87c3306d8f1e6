"""Terminal habits shared by the commands: colour only when wanted, progress that suits the output.

* ``NO_COLOR`` (https://no-color.org): any non-empty value turns colour off (``imulog.cli.main``
  passes ``color=False`` to click, so ``click.secho`` prints plain text).
* Progress: a live bar (tqdm) on a terminal; on a log file or pipe, plain lines at every 10 % and at
  the end, never ``\\r`` redraws.
* A closed pipe (``imulog evaluate trial.mcap | head -1``): :func:`broken_pipe` finds it (raised, or behind the
  one-line error a command made of an ``OSError``), and ``imulog.cli.LazyGroup`` ends the process with
  :func:`exit_closed_pipe`: silently, by SIGPIPE, as ``ls`` and ``git`` do (status 141 in a shell).
"""

from __future__ import annotations

import io
import os
import sys
from collections.abc import Iterator, Sequence
from typing import Any, NoReturn, TextIO, TypeVar

T = TypeVar("T")


def broken_pipe(exc: BaseException) -> BrokenPipeError | None:
    """The ``BrokenPipeError`` behind ``exc`` (itself, or the error a command turned into a
    ``click.ClickException``: its ``__cause__`` or ``__context__``), else None. A command's ``except OSError``
    around its output catches the pipe its reader closed; this tells that apart from a real file error."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, BrokenPipeError):
            return current
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return None


def exit_closed_pipe() -> NoReturn:
    """End the process the way Unix tools do when the reader of their output has gone (``ls | head``): silently,
    killed by SIGPIPE (exit status 141 in a shell; ``-13`` for ``subprocess``). Where there is no SIGPIPE
    (Windows), or stdout is no file (click's test runner), exit status 1, silently. Stdout is pointed at the
    null device first, so nothing left in its buffer is flushed into the closed pipe."""
    import signal

    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        real = True
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        real = False
    if real and hasattr(signal, "SIGPIPE"):
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGPIPE)
    sys.exit(1)


def no_color() -> bool:
    """True when the user asked for no colour (``NO_COLOR`` set and not empty)."""
    return bool(os.environ.get("NO_COLOR"))


class LineProgress:
    """A tqdm-compatible progress reporter for non-terminals: one plain line per 10 % step."""

    def __init__(self, total: int, desc: str, unit: str = "it", file: TextIO | None = None, step: float = 0.1):
        self.total = max(0, int(total))
        self.desc = desc
        self.unit = unit
        self.file = file if file is not None else sys.stderr
        self.n = 0
        self.step = step
        self._next = step
        self._postfix = ""
        self._closed = False

    def _line(self) -> None:
        pct = 100.0 * self.n / self.total if self.total else 100.0
        extra = f" {self._postfix}" if self._postfix else ""
        print(f"{self.desc}: {self.n}/{self.total} {self.unit} ({pct:.0f} %){extra}", file=self.file, flush=True)

    def update(self, n: int = 1) -> None:
        """Count ``n`` more; one line when a 10 % mark was passed (one, however many marks this update passed: 4 of 8
        files passes 40 % and 50 %)."""
        self.n += n
        passed = False
        while self.total and self.n / self.total >= self._next - 1e-12 and self._next <= 1.0 + 1e-12:
            passed = True
            self._next += self.step
        if passed and self.n < self.total:
            self._line()

    def set_postfix(self, refresh: bool = True, **values: Any) -> None:
        self._postfix = " ".join(f"{k}={v}" for k, v in values.items())

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._line()

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress_bar(total: int, desc: str, unit: str = "it", file: TextIO | None = None):
    """tqdm on a terminal, :class:`LineProgress` otherwise (same ``update``/``set_postfix``/``close``)."""
    stream = file if file is not None else sys.stderr
    if stream.isatty():
        from tqdm import tqdm

        return tqdm(total=total, unit=unit, desc=desc, file=stream, dynamic_ncols=True)
    return LineProgress(total, desc, unit, stream)


def window_progress(items: Sequence[T], desc: str, unit: str = "h", file: TextIO | None = None) -> Iterator[T]:
    """Yield ``items`` (a step's windows, an hour of recording each); with more than one and stderr a terminal, a
    live bar ticks once per item, so a week's ``imulog process orientation`` shows how far it is. In logs and pipes
    nothing is printed (the step prints what it wrote when done), nor for a recording of one window."""
    stream = file if file is not None else sys.stderr
    if len(items) <= 1 or not stream.isatty():
        yield from items
        return
    bar = progress_bar(len(items), desc, unit, stream)
    try:
        for item in items:
            yield item
            bar.update(1)
    finally:
        bar.close()
