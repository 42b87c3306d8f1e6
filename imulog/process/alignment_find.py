"""Which markers carry the IMU: the marker search (:mod:`imulog.process.alignment_search`) ranks rigid triads,
and each candidate is aligned (:func:`imulog.process.alignment.align`) until one reproduces the gyroscope.
Above both modules it uses (split from ``alignment_search`` to break their import cycle, issue 24).
"""

from __future__ import annotations

import numpy as np

from imulog.process.alignment_search import (
    Candidate,
    SearchParams,
    SearchResult,
    candidate_triads,
    extend_cluster,
    triad_omega_norm,
)


def find_cluster(
    t_imu_ns: np.ndarray,
    gyr_rad_s: np.ndarray,
    t_ref_ns: np.ndarray,
    labels: list[str],
    pos_m: np.ndarray,
    rate_hz: float,
    params,
) -> tuple[SearchResult, object | None, dict | None]:
    """Search the rigid marker set that carries the IMU (see the module docstring).

    ``params`` an :class:`imulog.process.alignment.AlignmentParams`. Returns the search result (candidates
    best first), and for the best refined candidate its :class:`ClusterKinematics` and alignment record
    (None, None when no triad exists).
    """
    import time

    from imulog.process import alignment as al

    t_start = time.perf_counter()
    sp: SearchParams = params.search
    t_ref = np.asarray(t_ref_ns, dtype=np.int64)
    t_imu = np.asarray(t_imu_ns, dtype=np.int64)
    pos = np.asarray(pos_m, dtype=np.float64)
    filt, _ = al.lowpass_markers(pos, rate_hz, params.filter)
    triads, total = candidate_triads(filt, sp)
    if not triads:
        return SearchResult([], total, 0, time.perf_counter() - t_start), None, None
    wn_dev = np.linalg.norm(np.asarray(gyr_rad_s, dtype=np.float64), axis=1)
    step = max(1, int(round(rate_hz / sp.coarse_hz)))
    t_c = t_ref[::step]
    cands = []
    for i, j, k, rig in triads:
        wn = triad_omega_norm(filt[::step][:, [i, j, k]], rate_hz / step)
        c = Candidate((labels[i], labels[j], labels[k]), rig)
        c.extra["index"] = (i, j, k)
        try:
            est = al.estimate_lag(
                t_imu, wn_dev, t_c, wn, window_s=1e12, max_lag_s=params.max_lag_s, grid_hz=sp.coarse_hz
            )
            c.ncc, c.extra["coarse_offset_ns"] = est.score, est.offset_ns
        except ValueError:
            c.ncc = -1.0
        cands.append(c)
    cands.sort(key=lambda c: -c.ncc)
    best = None
    for c in cands[: max(1, sp.refine)]:
        idx = list(c.extra["index"])
        try:
            ck = al.kinematics_from_filtered(t_ref, [labels[i] for i in idx], filt[:, idx], rate_hz)
            rec = al.align(t_imu, gyr_rad_s, ck, params, coarse_offset_ns=c.extra.get("coarse_offset_ns"))
        except ValueError:
            continue
        c.vector_match, c.offset_ns = float(np.nan_to_num(rec["vector_match"], nan=-1.0)), int(rec["offset_ns"])
        if best is None or c.vector_match > best[0].vector_match:
            best = (c, ck, rec)
    refined = sorted([c for c in cands if c.vector_match is not None], key=lambda c: -c.vector_match)
    others = [c for c in cands if c.vector_match is None]
    result = SearchResult(refined + others, total, len(cands))
    if best is None:
        result.seconds = time.perf_counter() - t_start
        return result, None, None
    c, ck, rec = best
    ext = extend_cluster(filt, c.extra["index"], c.rigidity_m, sp)
    if len(ext) > 3:
        try:
            ck2 = al.kinematics_from_filtered(t_ref, [labels[i] for i in ext], filt[:, ext], rate_hz)
            rec2 = al.align(t_imu, gyr_rad_s, ck2, params, coarse_offset_ns=rec["offset_ns"])
            if np.nan_to_num(rec2["vector_match"], nan=-1.0) >= c.vector_match - 0.005:
                ext_c = Candidate(tuple(labels[i] for i in ext), c.rigidity_m, c.ncc, float(rec2["vector_match"]))
                ext_c.offset_ns, ext_c.extra = (
                    int(rec2["offset_ns"]),
                    {"index": tuple(ext), "from_triad": list(c.markers)},
                )
                result.candidates.insert(0, ext_c)
                ck, rec = ck2, rec2
        except ValueError:
            pass
    result.seconds = time.perf_counter() - t_start
    return result, ck, rec
