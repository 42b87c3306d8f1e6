"""DynAMoS's merge/split (Dotti et al. 2024): the event-driven implementation makes exactly the published
one-change-at-a-time sequence, and converges on a week's worth of movements in seconds."""

from __future__ import annotations

import time

import numpy as np

from imulog.process.segmentation.dynamos import _local_minima, postprocess


def published(start, end, norm, alpha=0.8, beta=1.4, max_iterations=10_000):
    """The method as written: after every change recompute the median; merge the shortest outlier that can be
    merged (closest neighbour first), else split the longest one that can be split (lowest minimum first)."""
    s, e = [int(v) for v in start], [int(v) for v in end]
    changes = 0
    for _ in range(max_iterations):
        if len(s) < 2:
            break
        dur = np.subtract(e, s)
        med = float(np.median(dur))
        lo, hi = alpha * med, beta * med
        changed = False
        for i in np.argsort(dur, kind="stable"):
            if dur[i] >= lo:
                break
            cands = ([(s[i] - e[i - 1], i - 1)] if i > 0 else []) + (
                [(s[i + 1] - e[i], i + 1)] if i < len(s) - 1 else []
            )
            for _gap, j in sorted(cands):
                a, b = min(i, j), max(i, j)
                if lo <= e[b] - s[a] <= hi:
                    e[a] = e[b]
                    del s[b], e[b]
                    changed = True
                    break
            if changed:
                break
        if not changed:
            for i in np.argsort(-dur, kind="stable"):
                if dur[i] <= hi:
                    break
                seg = norm[s[i] : e[i]]
                minima = _local_minima(seg)
                for m in minima[np.argsort(seg[minima], kind="stable")]:
                    cut = s[i] + int(m)
                    if lo <= cut - s[i] <= hi and lo <= e[i] - cut <= hi:
                        s.insert(i + 1, cut)
                        e.insert(i, cut)
                        changed = True
                        break
                if changed:
                    break
        if not changed:
            break
        changes += 1
    return np.array(s), np.array(e), changes


def _movements(rng, k, lengths=None):
    gaps = rng.integers(1, 80, k)
    durs = rng.integers(1, 400, k) if lengths is None else rng.choice(lengths, k)
    start = np.cumsum(gaps + np.r_[0, durs[:-1]])
    end = start + durs
    n = int(end[-1] + 10)
    norm = np.abs(np.sin(np.arange(n) / rng.uniform(3, 30))) + rng.normal(0, 0.05, n)
    return start, end, norm


def test_the_same_changes_as_the_published_sequence():
    rng = np.random.default_rng(11)
    for case in range(300):
        lengths = [5, 20, 50, 100, 100, 100, 250, 600] if case % 3 == 0 else None
        start, end, norm = _movements(rng, int(rng.integers(2, 60)), lengths)
        stats: dict = {}
        got = postprocess(start, end, norm, 0.8, 1.4, 10_000, stats)
        s, e, changes = published(start, end, norm)
        np.testing.assert_array_equal(got[0], s, err_msg=f"case {case}")
        np.testing.assert_array_equal(got[1], e, err_msg=f"case {case}")
        assert stats["changes"] == changes
    # the bound on changes is the published loop's
    start, end, norm = _movements(np.random.default_rng(2), 60, [5, 20, 50, 100, 100, 100, 250, 600])
    assert published(start, end, norm)[2] > 3
    s, e, changes = published(start, end, norm, max_iterations=3)
    got = postprocess(start, end, norm, 0.8, 1.4, 3)
    assert changes == 3 and np.array_equal(got[0], s) and np.array_equal(got[1], e)


def test_tens_of_thousands_of_movements_converge_in_seconds():
    rng = np.random.default_rng(0)
    k = 30_000  # about a week of daily-life movements
    durs = np.maximum(5, rng.lognormal(np.log(150), 0.7, k).astype(int))
    start = np.cumsum(rng.integers(50, 3000, k) + np.r_[0, durs[:-1]])
    end = start + durs
    norm = np.abs(np.sin(np.arange(int(end[-1]) + 10) / 17.0)) + rng.normal(0, 0.05, int(end[-1]) + 10)
    stats: dict = {}
    t0 = time.perf_counter()
    s, e = postprocess(start, end, norm, 0.8, 1.4, 10**9, stats)
    elapsed = time.perf_counter() - t0
    assert stats["changes"] > 10_000  # more than the default bound: the published loop would have stopped short
    assert elapsed < 30.0, elapsed  # ~3 s on the shared 2-core machine; the one-change-per-pass loop took minutes
    again: dict = {}
    postprocess(s, e, norm, 0.8, 1.4, 10**9, again)
    assert again["changes"] == 0  # converged: no outlier can be merged or split any more
