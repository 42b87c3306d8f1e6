"""The optimisation's start blended per axis by the rests (issue 31 point 2, docs/accuracy.md):
:func:`imulog.process.trajectory_repetitions.rest_blend_weight` on synthetic repetitions with known truth."""

from __future__ import annotations

import numpy as np

from imulog.process.minjerk import R2GWaypoints, r2g_reference
from imulog.process.trajectory_repetitions import Repetition, rest_blend_weight, rest_positions

RATE = 50.0
WAY = R2GWaypoints(bottle_m=(0.30, 0.17, 0.05), mouth_m=(-0.20, 0.17, 0.42))
PHASES = 1.0 + np.array([[0.0, 1.2], [3.2, 4.6], [6.6, 7.9], [9.9, 11.0]])  # s from each window's start


def _trial(n_reps: int, rng: np.random.Generator, jitter_m: float = 0.01):
    """Windows of 13 s, each a minimum-jerk repetition whose waypoints are the reference's plus a per-repetition
    jitter (the hand never puts the bottle and itself back exactly): (t, truth, static, repetitions)."""
    n = int(13.0 * RATE)
    t = np.arange(n_reps * n) / RATE
    truth = np.zeros((len(t), 3))
    static = np.ones(len(t), dtype=bool)
    reps = []
    for k in range(n_reps):
        sl = slice(k * n, (k + 1) * n)
        b = PHASES + t[k * n]
        way = R2GWaypoints(
            bottle_m=tuple(np.asarray(WAY.bottle_m) + rng.normal(0.0, jitter_m, 3)),
            mouth_m=tuple(np.asarray(WAY.mouth_m) + rng.normal(0.0, jitter_m, 3)),
        )
        truth[sl] = r2g_reference(t[sl], b, way)
        for s, e in b:
            static[sl][(t[sl] > s) & (t[sl] < e)] = False
        reps.append(Repetition(k, k * n, (k + 1) * n, b))
    return t, truth, static, reps


def _error(t: np.ndarray, reps, per_rest_m: np.ndarray) -> np.ndarray:
    """A systematic start error: ``per_rest_m`` (4, 3) m at the bottle, mouth, bottle and home rests of every
    repetition, reached by straight ramps over each phase (its velocity integral over the repetition is what it
    leaves at home)."""
    out = np.zeros((len(t), 3))
    for rep in reps:
        tt = t[rep.start : rep.stop]
        levels = np.vstack([np.zeros(3), per_rest_m])
        for j in range(3):
            xs = np.r_[tt[0], rep.phase_bounds_s.reshape(-1), tt[-1]]  # 10 knots: rest, 4 x (start, end), rest
            ys = np.repeat(levels[:, j], 2)  # flat through each rest, a ramp over each phase
            out[rep.start : rep.stop, j] = np.interp(tt, xs, ys)
    return out


def test_rest_positions_are_the_displacements_at_each_rest():
    t, truth, static, reps = _trial(1, np.random.default_rng(0), jitter_m=0.0)
    got = rest_positions(t, truth, static, reps[0])
    want = np.array([WAY.bottle_m, WAY.mouth_m, WAY.bottle_m, (0.0, 0.0, 0.0)])
    assert np.allclose(got, want, atol=1e-9)


def test_a_compensation_that_moves_the_rests_away_is_dropped_and_one_that_brings_them_back_kept():
    rng = np.random.default_rng(3)
    t, truth, static, reps = _trial(10, rng)
    # 2 cm at the rests against the hand's 1-cm scatter per repetition (with ten repetitions the weight's own
    # standard error is then about 0.15; at 1 cm it is about 0.3)
    err = _error(t, reps, np.array([[0.02, -0.016, 0.0], [0.024, 0.02, 0.0], [0.018, -0.012, 0.0], [0.0, 0.0, 0.0]]))
    # measured right, compensated wrong in x and y (a compensation whose time course is wrong): w -> 0
    w = rest_blend_weight(t, truth, truth + err, static, reps, WAY)
    assert w[0] < 0.35 and w[1] < 0.35, w
    # measured wrong, the compensation removes it: w -> 1
    w = rest_blend_weight(t, truth + err, truth, static, reps, WAY)
    assert w[0] > 0.8 and w[1] > 0.8, w
    # z: the compensation does not move the rests there, so it is kept whole
    assert w[2] == 1.0
