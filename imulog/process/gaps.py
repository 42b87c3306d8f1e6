"""Gaps in sampled signals: the one rule every step applies to missing samples (pure numpy).

A sample is *missing* when any of the step's input columns is NaN (validity = ``isfinite``; converters store empty
or NaN cells and dropped packets as NaN, never as zeros). The rule:

1. gaps of at most ``max_bridge_samples`` consecutive missing samples are *bridged*: each column is linearly
   interpolated between the valid samples on either side (an IMU that lost one or two packets); the number of
   bridged gaps and samples goes into the run's provenance (``imulog.run.<n>["gaps"]``);
2. longer gaps *split* the signal into valid runs: filters and integrators restart at the start of each run
   (nothing is carried across a gap whose motion is unknown) and the outputs are NaN inside the gap;
3. runs shorter than ``min_run_samples`` are left out (NaN outputs): too short to initialise a filter.

Never interpolated silently: :class:`GapReport` says what was bridged and split, and the steps record it in the
run's provenance (with the :class:`GapParams` used). The steps take ``gaps=GapParams(...)`` from Python only; the
parameters are not part of a step's up-to-date check, so rerun with ``force=True`` after changing them.
Gaps at the start or end of a recording are never bridged (there is no sample on one side).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from imulog.numeric import finite_rows


@dataclass(frozen=True)
class GapParams:
    """How a step treats missing samples.

    max_bridge_samples: longest gap bridged by linear interpolation, samples (default 5: 43 ms at 115 Hz, 50 ms
        at 100 Hz; short enough that a wrist cannot change orientation or velocity much in it).
    min_run_samples: shortest valid run that is processed, samples (shorter runs give NaN outputs).
    """

    max_bridge_samples: int = 5
    min_run_samples: int = 10

    def __post_init__(self) -> None:
        if self.max_bridge_samples < 0 or self.min_run_samples < 1:
            raise ValueError(
                f"need max_bridge_samples >= 0 and min_run_samples >= 1, got {self.max_bridge_samples}, "
                f"{self.min_run_samples}"
            )


@dataclass(frozen=True)
class GapReport:
    """What :func:`prepare` found and did (all counts in samples, runs as half-open index ranges)."""

    n_samples: int
    missing: int  # samples missing in the input
    bridged_gaps: int  # gaps bridged by interpolation
    bridged_samples: int
    runs: tuple[tuple[int, int], ...]  # valid runs after bridging, processed separately
    skipped_samples: int  # samples left NaN: in long gaps or in runs shorter than min_run_samples
    params: GapParams = field(default_factory=GapParams)

    @property
    def split(self) -> bool:
        """True when the signal had to be processed in more than one run (or not from its first sample)."""
        return len(self.runs) != 1 or self.runs[0] != (0, self.n_samples)

    def as_dict(self) -> dict:
        """JSON-able summary for the run's provenance (``imulog.run.<n>["gaps"]``)."""
        return {
            "rule": "bridge gaps <= max_bridge_samples linearly; split at longer gaps; restart per run",
            "max_bridge_samples": self.params.max_bridge_samples,
            "min_run_samples": self.params.min_run_samples,
            "missing_samples": self.missing,
            "bridged_gaps": self.bridged_gaps,
            "bridged_samples": self.bridged_samples,
            "runs": [list(r) for r in self.runs],
            "skipped_samples": self.skipped_samples,
        }


def valid_mask(*arrays: np.ndarray | None) -> np.ndarray:
    """(N,) True where every column of every given array is finite."""
    present = [np.asarray(a, dtype=np.float64) for a in arrays if a is not None]
    if not present:
        raise ValueError("valid_mask needs at least one array")
    ok = np.ones(len(present[0]), dtype=bool)
    for a in present:
        flat = a.reshape(len(a), -1)
        if not np.isfinite(flat).all():  # one fast pass: most windows have no missing sample
            ok &= finite_rows(flat)
    return ok


def runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open ``(start, stop)`` index ranges of the True runs of a boolean mask."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def prepare(
    arrays: Sequence[np.ndarray | None], params: GapParams | None = None
) -> tuple[list[np.ndarray | None], GapReport]:
    """Bridge short gaps of ``arrays`` (same length, NaN = missing) and find the valid runs.

    Returns copies of the arrays with short gaps interpolated (long gaps stay NaN) and the report. A sample is
    missing when any column of any array is non-finite.
    """
    p = params or GapParams()
    n = len(next(a for a in arrays if a is not None))
    ok = valid_mask(*arrays)
    bridge = np.zeros(n, dtype=bool)
    bridged_gaps = 0
    for a, b in runs_of(~ok):
        if a > 0 and b < n and b - a <= p.max_bridge_samples:
            bridge[a:b] = True
            bridged_gaps += 1
    out: list[np.ndarray | None] = []
    idx = np.arange(n)
    for arr in arrays:
        if arr is None:
            out.append(None)
            continue
        x = np.array(arr, dtype=np.float64, copy=True)
        if bridge.any():
            flat = x.reshape(n, -1)
            for j in range(flat.shape[1]):
                flat[bridge, j] = np.interp(idx[bridge], idx[ok], flat[ok, j])
        out.append(x)
    usable = ok | bridge
    runs = tuple(r for r in runs_of(usable) if r[1] - r[0] >= p.min_run_samples)
    kept = sum(b - a for a, b in runs)
    report = GapReport(
        n_samples=n,
        missing=int(n - ok.sum()),
        bridged_gaps=bridged_gaps,
        bridged_samples=int(bridge.sum()),
        runs=runs,
        skipped_samples=int(n - kept),
        params=p,
    )
    return out, report


def per_run(
    fn: Callable[..., np.ndarray | tuple[np.ndarray, ...]],
    report: GapReport,
    *arrays: np.ndarray | None,
) -> tuple[np.ndarray, ...]:
    """Apply ``fn(*run_slices)`` to each valid run and assemble its outputs (NaN outside the runs).

    ``fn`` returns one array or a tuple of arrays, each with one row per input sample of the run; outputs of
    boolean or integer type are assembled as float (NaN in the gaps).
    """
    if report.runs == ((0, report.n_samples),):  # one run over every sample: its outputs as they are, as float
        res = fn(*arrays)
        return tuple(np.asarray(r, dtype=np.float64) for r in (res if isinstance(res, tuple) else (res,)))
    outputs: list[np.ndarray] | None = None
    for a, b in report.runs:
        res = fn(*[None if x is None else x[a:b] for x in arrays])
        res = res if isinstance(res, tuple) else (res,)
        if outputs is None:
            outputs = [np.full((report.n_samples, *np.shape(r)[1:]), np.nan) for r in res]
        for o, r in zip(outputs, res, strict=True):
            o[a:b] = r
    if outputs is None:
        raise ValueError(
            f"no valid run of at least {report.params.min_run_samples} samples "
            f"({report.missing} of {report.n_samples} samples missing)"
        )
    return tuple(outputs)
