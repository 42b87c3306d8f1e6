"""Whole setups: several IMUs and every marker of the trial, aligned together (issue 27).

1. The marker triads (:func:`imulog.process.alignment_search.candidate_triads`, any naming) are scored once
   against every IMU's gyroscope (coarse correlation of the angular-velocity norms), the best ``refine`` per
   IMU get the full clock fit and the vector match (R^2 of the cluster's angular velocity explained by the
   rotated gyroscope).
2. IMUs and triads are paired one to one (:func:`pair_one_to_one`, the assignment maximising the summed
   vector match; pairs under ``min_vector_match`` are not made): two IMUs never share a cluster.
3. Each paired triad is extended with the markers rigid to it, then every marker that is not rigid with the
   others over the trial is dropped (:func:`prune_cluster`: leave-one-out rigid fit). A point on a
   neighbouring segment near the joint (a shank point beside a foot cluster) keeps its distances to the
   cluster's markers within a few mm, so the pair test accepts it, but it leaves the rigid body the others
   define as the joint turns.
4. The IMUs of one recording share a clock: their windows' lags are pooled into one offset and drift
   (:func:`imulog.process.alignment.fit_window_lags`); an IMU without a cluster gets that clock and no frame.

Pure functions on arrays: positions in m, times in int64 ns.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "PruneParams",
    "SetupMatch",
    "coarse_scores",
    "find_setup_clusters",
    "pair_one_to_one",
    "pooled_clock",
    "prune_cluster",
    "recording_groups",
]


@dataclass(frozen=True)
class PruneParams:
    """Leave-one-out rigidity of a cluster's markers (m).

    A marker is dropped when its residual from the rigid body of the others (RMS over the frames where all
    are visible) exceeds ``factor`` times the median residual of the cluster's three most rigid markers and
    ``floor_m``; at
    most ``frames`` evenly spread frames are used; the cluster keeps at least 3 markers."""

    factor: float = 2.0
    floor_m: float = 0.002
    frames: int = 2000


def _rigid_fit(p_others: np.ndarray, p_marker: np.ndarray) -> np.ndarray:
    """Residual (F,) m of a marker against the rigid body of ``p_others`` (F, K, 3), K >= 3, all finite."""
    from imulog.process.alignment_frames import cluster_frame_oxy, cluster_frame_svd

    r0 = cluster_frame_oxy(p_others[:, 0], p_others[:, 1], p_others[:, 2])
    local = np.einsum("nji,nmj->mi", r0, p_others - p_others[:, :1]) / len(p_others)
    r, origin = cluster_frame_svd(p_others, local)
    rel = np.einsum("nji,nj->ni", r, p_marker - origin)  # the marker in the others' frame
    pred = origin + np.einsum("nij,j->ni", r, np.mean(rel, axis=0))
    return np.linalg.norm(p_marker - pred, axis=1)


def prune_cluster(
    pos_m: np.ndarray, index: Sequence[int], params: PruneParams = PruneParams()
) -> tuple[list[int], dict[int, float]]:
    """Markers of ``index`` (columns of ``pos_m`` (N, M, 3), filtered) rigid with each other over the trial.

    Returns ``(kept, residual_m)``: the kept column indices in the given order, and every tested marker's
    leave-one-out residual (RMS, m). Markers are removed one at a time, worst first, while one exceeds the
    limit and more than three remain; a cluster of three is returned as given (no marker can be tested)."""
    kept = [int(i) for i in index]
    residual: dict[int, float] = {}
    while len(kept) > 3:
        p = np.asarray(pos_m, dtype=np.float64)[:, kept]
        full = np.flatnonzero(np.all(np.isfinite(p.reshape(len(p), -1)), axis=1))
        if len(full) < 10:
            break
        full = full[np.unique(np.linspace(0, len(full) - 1, min(len(full), params.frames)).astype(int))]
        p = p[full]
        res = {}
        for k, m in enumerate(kept):
            others = [j for j in range(len(kept)) if j != k]
            res[m] = float(np.sqrt(np.mean(_rigid_fit(p[:, others], p[:, k]) ** 2)))
        residual.update(res)
        worst = max(res, key=res.get)
        # the yardstick is the three most rigid markers' residual: a foreign marker inflates every other
        # marker's residual too, so the median of all would let a second one stay
        limit = max(params.factor * float(np.median(sorted(res.values())[:3])), params.floor_m)
        if res[worst] <= limit:
            break
        kept.remove(worst)
    return kept, residual


def pair_one_to_one(score: np.ndarray, min_score: float) -> list[tuple[int, int]]:
    """Pairs ``(row, column)`` of the assignment that maximises the summed ``score`` (rows: IMUs, columns:
    clusters; NaN = not scored), one column per row at most, keeping only pairs scoring ``min_score`` or more."""
    from scipy.optimize import linear_sum_assignment

    s = np.asarray(score, dtype=np.float64)
    if s.size == 0:
        return []
    ok = np.isfinite(s) & (s >= min_score)
    cost = np.where(ok, -s, 1e6)
    rows, cols = linear_sum_assignment(cost)
    return [(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if ok[r, c]]


def coarse_scores(
    t_dev_ns: np.ndarray, gyr_rad_s: np.ndarray, references: Sequence[tuple[np.ndarray, np.ndarray]], params
) -> tuple[np.ndarray, dict[int, int]]:
    """The cheap score that ranks an IMU's candidate references before any full alignment: the correlation of the
    gyroscope's norm with each reference's angular-velocity norm (``references``: (t_ref_ns, norm rad/s) on a
    coarse grid), one lag over the whole recording within ``params.max_lag_s``, on a ``params.search.coarse_hz``
    grid (:func:`imulog.process.alignment.estimate_lag`). Returns (score per reference, -1 where none could be
    computed; coarse offset ns by reference index). The norm needs no frame alignment, so it ranks before any."""
    from imulog.process import alignment as al

    wn_dev = np.linalg.norm(np.asarray(gyr_rad_s, dtype=np.float64), axis=1)
    ncc = np.full(len(references), -1.0)
    coarse: dict[int, int] = {}
    for c, (t_c, wn) in enumerate(references):
        try:
            est = al.estimate_lag(
                t_dev_ns, wn_dev, t_c, wn, window_s=1e12, max_lag_s=params.max_lag_s, grid_hz=params.search.coarse_hz
            )
        except ValueError:
            continue
        ncc[c], coarse[c] = est.score, est.offset_ns
    return ncc, coarse


def recording_groups(
    names: Sequence[str],
    device_meta: Mapping[str, Mapping[str, Any]],
    times: Mapping[str, np.ndarray | tuple[int, int, int]],
) -> list[list[str]]:
    """IMUs that share one clock: the same ``recording`` (or ``master``) in their device records, the same
    source file, or identical time stamps (sample-aligned files of one station). ``times``: per IMU its whole
    channel's time stamps (int64 ns), or their (count, first ns, last ns) from the archive's channel summary; not
    the stretch read around the optical data, which two recordings time-stamped alike from their own starts share
    however long each is. Groups in ``names`` order."""
    parent = {n: n for n in names}

    def find(n: str) -> str:
        while parent[n] != n:
            n = parent[n]
        return n

    def key_of(n: str) -> list[tuple]:
        meta = device_meta.get(n) or {}
        keys = [("k", str(meta[k])) for k in ("recording", "master") if meta.get(k)]
        if meta.get("source"):
            keys.append(("source", str(meta["source"])))
        span = times[n]
        if isinstance(span, tuple):
            if span[0]:
                keys.append(("time", *map(int, span)))
        else:
            t = np.asarray(span, dtype=np.int64)
            if len(t):
                keys.append(("time", len(t), int(t[0]), int(t[-1])))
        return keys

    first: dict[tuple, str] = {}
    for n in names:
        for k in key_of(n):
            if k in first:
                parent[find(n)] = find(first[k])
            else:
                first[k] = n
    groups: dict[str, list[str]] = {}
    for n in names:
        groups.setdefault(find(n), []).append(n)
    return list(groups.values())


def pooled_clock(records: Sequence[Mapping[str, Any]], params) -> dict:
    """One clock (offset, drift and uncertainties: :func:`imulog.process.alignment.fit_window_lags`) from the
    windows of several IMUs' alignments of one recording; ``windows`` lists them with their ``imu``."""
    from imulog.process.alignment import fit_window_lags

    windows, widths = [], []
    for rec in records:
        for w in rec.get("windows") or []:
            w2 = dict(w)
            w2["imu"] = rec.get("imu")
            if w2.get("why") == "outlier":  # an IMU's own outlier may fit the pooled line: test it again
                w2["used"], w2["why"] = True, None
            windows.append(w2)
            widths.append(float(w.get("width_s") or 0.0))
    if not any(w.get("used") for w in windows):
        raise ValueError("no usable window in any IMU of the recording")
    clock = fit_window_lags(windows, float(np.median(widths)), params)
    for w in windows:
        if w.get("why") is None:
            w.pop("why", None)
    clock["windows"] = windows
    return clock


@dataclass
class SetupMatch:
    """One IMU's cluster: its :class:`~imulog.process.alignment.ClusterKinematics`, its own alignment record
    (clock of its own windows), and what the search found (``info``: markers, triad, rejected markers with
    their leave-one-out residual, vector match, runner-up)."""

    kinematics: Any
    record: dict
    info: dict


def find_setup_clusters(
    imus: Mapping[str, tuple[np.ndarray, np.ndarray]],
    t_ref_ns: np.ndarray,
    labels: Sequence[str],
    pos_m: np.ndarray,
    rate_hz: float,
    params,
    prune: PruneParams = PruneParams(),
) -> tuple[dict[str, SetupMatch], dict[str, Any]]:
    """Pair every IMU (name -> (t_dev_ns, gyr rad/s)) with its rigid marker cluster, one to one.

    ``params`` an :class:`imulog.process.alignment.AlignmentParams`. Returns the matches of the paired IMUs and
    a search summary (triads found and scored, the vector-match table of the refined pairs, seconds).
    """
    import time

    from imulog.process import alignment as al
    from imulog.process.alignment_search import candidate_triads, extend_cluster, triad_omega_norm

    t_start = time.perf_counter()
    sp = params.search
    labels = list(labels)
    t_ref = np.asarray(t_ref_ns, dtype=np.int64)
    filt, _ = al.lowpass_markers(np.asarray(pos_m, dtype=np.float64), rate_hz, params.filter)
    triads, total = candidate_triads(filt, sp)
    names = list(imus)
    summary: dict[str, Any] = {"triads_found": total, "triads_scored": len(triads), "pairs": {}}
    if not triads:
        summary["seconds"] = round(time.perf_counter() - t_start, 2)
        return {}, summary
    step = max(1, int(round(rate_hz / sp.coarse_hz)))
    t_c = t_ref[::step]
    wn_tri = [triad_omega_norm(filt[::step][:, list(t[:3])], rate_hz / step) for t in triads]
    score = np.full((len(names), len(triads)), np.nan)
    records: dict[tuple[int, int], tuple[Any, dict]] = {}
    for r, name in enumerate(names):
        t_dev, gyr = imus[name]
        ncc, coarse = coarse_scores(t_dev, gyr, [(t_c, wn) for wn in wn_tri], params)
        for c in np.argsort(-ncc)[: max(1, sp.refine)]:
            if ncc[c] <= 0:
                continue
            idx = list(triads[c][:3])
            try:
                ck = al.kinematics_from_filtered(t_ref, [labels[i] for i in idx], filt[:, idx], rate_hz)
                rec = al.align(t_dev, gyr, ck, params, coarse_offset_ns=coarse.get(int(c)))
            except ValueError:
                continue
            score[r, c] = float(np.nan_to_num(rec["vector_match"], nan=-1.0))
            records[(r, int(c))] = (ck, rec)
        summary["pairs"][name] = {
            ",".join(labels[i] for i in triads[c][:3]): round(float(score[r, c]), 4)
            for c in np.flatnonzero(np.isfinite(score[r]))
        }
    matches: dict[str, SetupMatch] = {}
    for r, c in pair_one_to_one(score, sp.min_vector_match):
        name = names[r]
        t_dev, gyr = imus[name]
        ck, rec = records[(r, c)]
        tri = list(triads[c][:3])
        vm = score[r, c]
        others = [(score[r, k], k) for k in np.flatnonzero(np.isfinite(score[r])) if k != c]
        runner = max(others) if others else None
        info: dict[str, Any] = {
            "markers": list(ck.markers),
            "triad": [labels[i] for i in tri],
            "rigidity_mm": round(triads[c][3] * 1e3, 3),
            "vector_match": round(float(vm), 4),
            "runner_up": None
            if runner is None
            else {"markers": [labels[i] for i in triads[runner[1]][:3]], "vector_match": round(float(runner[0]), 4)},
            "selection": "setup search",
        }
        ext = extend_cluster(filt, tuple(tri), triads[c][3], sp)
        kept, resid = prune_cluster(filt, ext, prune)
        rejected = [labels[i] for i in ext if i not in kept]
        if resid:
            info["residual_mm"] = {labels[i]: round(v * 1e3, 2) for i, v in resid.items()}
        if rejected:
            info["rejected_markers"] = rejected
        if sorted(kept) != sorted(tri) and len(kept) >= 3:
            try:
                ck2 = al.kinematics_from_filtered(t_ref, [labels[i] for i in kept], filt[:, kept], rate_hz)
                rec2 = al.align(t_dev, gyr, ck2, params, coarse_offset_ns=rec["offset_ns"])
                if np.nan_to_num(rec2["vector_match"], nan=-1.0) >= vm - 0.005 or not set(tri) <= set(kept):
                    ck, rec = ck2, rec2
                    info["markers"] = list(ck2.markers)
                    info["vector_match"] = round(float(rec2["vector_match"]), 4)
            except ValueError:
                pass
        matches[name] = SetupMatch(ck, rec, info)
    summary["seconds"] = round(time.perf_counter() - t_start, 2)
    return matches, summary
