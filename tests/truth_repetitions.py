"""Test helper: a simulated R2G trial's true repetitions, as the trajectory optimisation takes them."""

from __future__ import annotations

import numpy as np

from imulog.process.trajectory_opt import Repetition


def true_repetitions(sim) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[Repetition]]:
    """Times (s), true positions relative to each repetition's start (m), the true static mask and the
    repetitions (true phases, 1 s of rest either side)."""
    t = (sim.truth.t_ns - sim.truth.t_ns[0]) * 1e-9
    ph = sim.truth.phases
    reps = []
    for rep in sorted(set(ph.task_index.tolist())):
        sel = ph.task_index == rep
        b = np.c_[ph.start_ns[sel], ph.end_ns[sel]] * 1e-9 - sim.truth.t_ns[0] * 1e-9
        i0, i1 = np.searchsorted(t, b[0, 0] - 1.0), np.searchsorted(t, b[-1, 1] + 1.0)
        reps.append(Repetition(int(rep), int(i0), int(i1), b))
    rel = np.full_like(sim.truth.position, np.nan)
    for r in reps:
        rel[r.start : r.stop] = sim.truth.position[r.start : r.stop] - sim.truth.position[r.start]
    return t, rel, np.asarray(sim.truth.static_mask, dtype=bool), reps
