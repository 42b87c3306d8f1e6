"""What the windowed phases step reads and keeps between its passes: the IMU samples window by window and the
filtered gyroscope norm (in memory for one window, in a temporary file beside the trial for more).

Pure bookkeeping and a temporary file; the numerics are :mod:`imulog.process.segmentation`.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from imulog.process.gaps import GapReport, prepare
from imulog.process.segmentation.reduce import ArrayStore
from imulog.steps.sample_window import SampleWindow

#: opens the IMU samples ``(t_ns, gyr, acc)`` of the recording, block by block (a fresh reader per pass)
Source = Callable[[], AbstractContextManager[SampleWindow]]


class NormFile:
    """float64 values appended to a temporary file and read back by slices (``os.pread``: nothing is mapped, so the
    file's pages never count as the process's memory)."""

    def __init__(self, directory: str | Path | None = None) -> None:
        self._f = tempfile.TemporaryFile(dir=directory, prefix=".imulog-norm-")  # noqa: SIM115 (closed by close())
        self.n = 0

    def append(self, values: np.ndarray) -> None:
        self._f.write(np.ascontiguousarray(values, dtype="<f8").tobytes())
        self.n += len(values)

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, key: slice) -> np.ndarray:
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise TypeError("NormFile reads contiguous slices only")
        a, b, _ = key.indices(self.n)
        if b <= a:
            return np.zeros(0)
        self._f.flush()
        data = os.pread(self._f.fileno(), 8 * (b - a), 8 * a)
        return np.frombuffer(data, dtype="<f8")

    def chunks(self, size: int = 1 << 20) -> Iterator[tuple[int, np.ndarray]]:
        for a in range(0, self.n, size):
            yield a, self[a : a + size]

    def close(self) -> None:
        self._f.close()


class NormMemory(ArrayStore):
    """The norm of a one-window recording, in memory, appended like a :class:`NormFile`."""

    def __init__(self) -> None:
        super().__init__(np.zeros(0))
        self._parts: list[np.ndarray] = []

    def append(self, values: np.ndarray) -> None:
        self._parts.append(np.asarray(values, dtype=float))
        self.array = self._parts[0] if len(self._parts) == 1 else np.concatenate(self._parts)

    def close(self) -> None:
        pass


def array_source(t_ns: np.ndarray, gyr: np.ndarray | None, acc: np.ndarray | None) -> Source:
    """A :data:`Source` over samples already in memory (one block)."""

    @contextmanager
    def open_() -> Iterator[SampleWindow]:
        yield SampleWindow(iter([(np.asarray(t_ns, np.int64), gyr, acc)]), len(t_ns))

    return open_


def trial_source(path: str | Path, topic: str, total: int) -> Source:
    """A :data:`Source` reading ``topic`` of the trial at ``path`` chunk by chunk."""

    @contextmanager
    def open_() -> Iterator[SampleWindow]:
        from imulog.archive import TrialReader

        with TrialReader(path) as trial:
            blocks = ((np.asarray(b.t_ns, np.int64), b.gyr, b.acc) for b in trial.iter_blocks(topic))
            yield SampleWindow(blocks, total)

    return open_


def prepared(
    gyr: np.ndarray, acc: np.ndarray | None, gaps: Any
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, GapReport]:
    """(gyr, acc, unknown, report) of a window, missing samples treated as :mod:`imulog.process.gaps` says: short
    gaps bridged; inside longer ones the gyroscope reads zero (no movement) and the accelerometer is interpolated
    (it only serves boundary refinement near the gap's edges); ``unknown`` marks the samples of no valid run."""
    (gyr, acc), report = prepare([gyr, acc], gaps)
    unknown = np.ones(len(gyr), dtype=bool)
    for a, b in report.runs:
        unknown[a:b] = False
    if unknown.any():
        gyr = np.where(unknown[:, None], 0.0, gyr)
        if acc is not None and not unknown.all():
            ok = ~unknown
            idx = np.arange(len(acc))
            acc = np.column_stack([np.interp(idx, idx[ok], acc[ok, j]) for j in range(3)])
    return gyr, acc, unknown, report
