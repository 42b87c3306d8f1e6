"""Repetition splitting of a multi-task recording and event correction (R2G thesis 3.3.2 and 3.3.1).

* repetition grouping (thesis 3.3.2 and its imulog variant on the movements, the calibration wave left out):
  :mod:`~imulog.process.segmentation.grouping` (:func:`split_repetitions`, :func:`group_movements`,
  :func:`burst_mask`);
* phases the detector missed: :mod:`~imulog.process.segmentation.rescue`;
* :func:`segment_repetitions` (thesis 3.3.1 event correction): in a repetition with more than ``n_phases`` movements, keep the
  ``n_phases`` movements whose durations ``D``, heights ``H`` (peak norm) and gaps ``S`` best match the
  subject's reference (mean over the repetitions that show exactly ``n_phases`` movements), minimising
  ``RMS(D - D*) + RMS(H - H*) + RMS(S - S*)`` exhaustively over all combinations. A repetition with fewer
  movements (two phases fused, or one too low for every detection level) is split at the local minimum of the
  norm, or given the bump of the norm in one of its rests, whichever best matches the reference (imulog
  additions, so that a trial always yields ``n_repetitions x n_phases`` phases).

Units: durations and gaps in seconds, heights in rad/s; intervals are half-open sample ranges.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from imulog.param_rules import check_rules
from imulog.process.segmentation.grouping import (
    assign_to_repetitions,
    burst_mask,
    group_movements,
    split_repetitions,
)

R2G_PHASES: tuple[str, ...] = ("reach", "lift", "return_bottle", "return_hand")


@dataclass(frozen=True)
class RepetitionParams:
    """Parameters of :func:`segment_repetitions`.

    n_repetitions: repetitions in the recording (R2G protocol: 25); 0 = infer from movement count / n_phases.
    n_phases: movements per repetition (R2G: 4).
    activity_fraction: fraction of the maximum norm above which a sample is non-static (thesis: 0.10).
    split: ``"activity"`` (thesis 3.3.2: longest gaps between non-static samples) or ``"movements"``
        (default: longest rests between major movements, see :func:`group_movements`).
    major_fraction: a movement is major when its height is at least this fraction of the median height.
    extra_cut_fraction: rests at least this fraction of the median repetition border also separate groups
        (non-task activity becomes its own group and is dropped), see :func:`group_movements`.
    continuation_gap_s: after event correction, a dropped movement starting within this time (s) of a kept
        phase's end (or ending this close before its start) is absorbed into it as a corrective sub-movement
        (imulog addition; 0 = drop extras as in the thesis).
    split_merged: split a group holding two repetitions (short rest between them), see
        :func:`split_merged_groups` (imulog addition).
    extra_groups: besides ``n_repetitions`` groups, also try partitions into up to this many more groups
        (non-task activity such as a calibration wave takes a group of its own) and keep the partition whose
        ``n_repetitions`` cheapest groups have the lowest summed correction cost (imulog addition).
    burst_gap_s: movements separated by gaps shorter than this (s) are contiguous, see :func:`burst_mask`.
    burst_min_movements: a run of at least this many contiguous movements is a burst of non-task activity
        (the calibration wave of fast alternating rotations) and is left out of the repetitions
        (imulog addition; 0 = off).
    min_height_fraction: only movements at least this fraction of the lowest reference height ``min(H*)``
        enter the search (when at least ``n_phases`` do; the others are corrective sub-movements or fidgets
        and may still be absorbed, see ``continuation_gap_s``) (imulog addition; 0 = all, as in the thesis).
    max_candidates: at most this many movements (the highest) enter the exhaustive search per repetition.
    fused_groups: also try the partition whose repetitions may hold ``n_phases - 1`` movements (two phases fused
        into one movement: the repetition's borders then stay at the longest rests instead of moving a movement
        across a rest to make up the count; imulog addition, issue 19).
    rescue_fraction: a run of the norm in a rest above this fraction of the lowest real movement's height and
        as long as a short movement is a movement the detector missed, see
        :func:`~imulog.process.segmentation.rescue.rescue_missed` (imulog addition, issue 31; 0 = off).
    turned_majors: a movement that turns the wrist at least ``major_fraction`` x the median angle (the norm
        integrated over it, rad) counts as major in the grouping whatever its height (imulog addition, issue 31
        sixth round: a slow, low phase; False = height only, as before).
    tail_bump: the trial's last repetition, short of a phase, may also take it from the bump of the norm in the
        rest after its last movement (imulog addition, issue 31 sixth round; False = only rests between movements).
    labels: phase labels in order.
    """

    n_repetitions: int = 25
    n_phases: int = 4
    activity_fraction: float = 0.10
    split: str = "movements"
    major_fraction: float = 0.5
    extra_cut_fraction: float = 0.5
    continuation_gap_s: float = 1.0
    split_merged: bool = True
    extra_groups: int = 2
    burst_gap_s: float = 0.2
    burst_min_movements: int = 5
    min_height_fraction: float = 0.5
    max_candidates: int = 14
    fused_groups: bool = True
    rescue_fraction: float = 0.5
    turned_majors: bool = True
    tail_bump: bool = True
    labels: tuple[str, ...] = R2G_PHASES
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


@dataclass(frozen=True)
class Phases:
    """Corrected phases: ``start``/``end`` sample ranges, ``repetition`` (1-based), ``phase`` (0-based)."""

    start: np.ndarray
    end: np.ndarray
    repetition: np.ndarray
    phase: np.ndarray
    labels: list[str]
    n_corrected: int  # repetitions whose movement count had to be corrected
    forced: np.ndarray | None = None  # per phase: True when made by cutting a movement (no movement of its own)
    quality: tuple = ()  # per repetition: what event correction did and a confidence, see repetition_quality

    def __len__(self) -> int:
        return len(self.start)


def features(start: np.ndarray, end: np.ndarray, norm: np.ndarray, rate_hz: float):
    """Durations (s), heights (peak norm, rad/s) and gaps to the next movement (s)."""
    start, end = np.asarray(start), np.asarray(end)
    d = (end - start) / rate_hz
    h = np.array([norm[s:e].max() if e > s else 0.0 for s, e in zip(start, end, strict=True)])
    s = (start[1:] - end[:-1]) / rate_hz
    return d, h, s


def turned_angles(start: np.ndarray, end: np.ndarray, norm, rate_hz: float) -> np.ndarray:
    """Angle (rad) each movement ``[start, end)`` turns the wrist: the filtered norm (rad/s, an array or a store)
    integrated over it."""
    return np.array([float(np.sum(np.asarray(norm[a:b]))) / rate_hz for a, b in zip(start, end, strict=True)])


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a**2))) if len(a) else 0.0


def correction_cost(d, h, s, ref_d, ref_h, ref_s) -> float:
    """Thesis 3.3.1 criterion ``RMS(D-D*) + RMS(H-H*) + RMS(S-S*)`` (s, rad/s, s summed as published)."""
    return _rms(d - ref_d) + _rms(h - ref_h) + _rms(s - ref_s)


def best_subset(d, h, start, end, rate_hz, ref, n_phases: int, max_candidates: int) -> tuple[int, ...]:
    """Indices of the ``n_phases`` movements minimising :func:`correction_cost` (exhaustive search)."""
    ref_d, ref_h, ref_s = ref
    idx = np.arange(len(d))
    if len(idx) > max_candidates:
        idx = np.sort(np.argsort(-h, kind="stable")[:max_candidates])
    best, best_cost = tuple(idx[:n_phases]), np.inf
    for combo in combinations(idx, n_phases):
        c = np.array(combo)
        gaps = (start[c[1:]] - end[c[:-1]]) / rate_hz
        cost = correction_cost(d[c], h[c], gaps, ref_d, ref_h, ref_s)
        if cost < best_cost:
            best, best_cost = tuple(int(v) for v in combo), cost
    return best


def _split_candidates(start, end, norm, min_len: int):
    for k in range(len(start)):
        seg = norm[start[k] : end[k]]
        if len(seg) < 3:
            continue
        m = np.flatnonzero((seg[1:-1] < seg[:-2]) & (seg[1:-1] <= seg[2:])) + 1
        for cut in m:
            if cut >= min_len and len(seg) - cut >= min_len:
                yield k, int(start[k] + cut), float(seg[cut])


def _split_to(start, end, norm, rate_hz, ref, n_phases: int, tail: int | None = None):
    """Make up fused or missing phases (fewer than ``n_phases`` movements): split a movement at the local minimum
    of the norm, or (with a reference) take the bump of the norm in a rest between two movements
    (:func:`~imulog.process.segmentation.rescue.bump_in_rest`, at least half the reference's shortest phase),
    or, with ``tail`` (the end of the recording, samples; the trial's last repetition), in the rest after the
    last movement, whichever best matches the reference; while more than one phase is missing, a bump goes
    before a split. Returns the movements and the starts of the phases taken from rests."""
    from imulog.process.segmentation.rescue import bump_in_rest

    start, end = list(start), list(end)
    min_len = max(2, int(0.1 * rate_hz))
    found: set[int] = set()
    while 0 < len(start) < n_phases:
        best, best_cost = None, np.inf
        candidates = [(k, cut, None, value) for k, cut, value in _split_candidates(start, end, norm, min_len)]
        if ref is not None:
            bump_len = max(min_len, int(0.5 * float(np.min(ref[0])) * rate_hz))
            for k in range(len(start) - (0 if tail is not None else 1)):
                bump = bump_in_rest(norm, int(end[k]), int(start[k + 1]) if k + 1 < len(start) else tail, bump_len)
                if bump is not None:
                    candidates.append((k, bump[0], bump[1], -bump[2]))
        for k, a, b, value in candidates:
            s2 = np.array(start[: k + 1] + [a] + start[k + 1 :])
            e2 = np.array(end[:k] + ([a, end[k]] if b is None else [end[k], b]) + end[k + 1 :])
            if ref is not None and len(s2) == n_phases:
                d, h, gaps = features(s2, e2, norm, rate_hz)
                cost = correction_cost(d, h, gaps, *ref)
            else:
                cost = value  # a bump in a rest first (negative), then the deepest minimum
            if cost < best_cost:
                best, best_cost = (k, a, b), cost
        if best is None:
            break
        k, a, b = best
        start.insert(k + 1, a)
        if b is None:  # movement k cut at a
            end.insert(k, a)
        else:  # a bump in the rest after movement k: a phase of its own
            end.insert(k + 1, b)
            found.add(int(a))
    return np.asarray(start, dtype=np.int64), np.asarray(end, dtype=np.int64), found


def _reference(groups, start, end, norm, rate_hz, n_phases, major=None):
    """Mean features (D*, H*, S*) of the groups with exactly ``n_phases`` movements; when there are none, of
    the groups with exactly ``n_phases`` major movements (``major``: boolean mask), using those movements
    (every repetition may carry a corrective sub-movement or a fidget); None when neither exists."""
    good = [g for g in groups if len(g) == n_phases]
    if not good and major is not None:
        good = [g[major[g]] for g in groups if int(major[g].sum()) == n_phases]
    if not good:
        return None
    feats = [features(start[g], end[g], norm, rate_hz) for g in good]
    return tuple(np.mean([f[i] for f in feats], axis=0) for i in range(3))


def _select(
    s, e, norm, rate_hz, ref, params: RepetitionParams, tail: int | None = None
) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """Exactly ``n_phases`` movements of one repetition, their correction cost (inf without reference) and what
    the correction did (``tail``: the end of the recording when this is the trial's last repetition, see
    :func:`_split_to`): ``{"movements", "merged", "dropped", "split", "missing", "forced"}`` (counts; forced:
    per kept phase, True when it was made by cutting a movement)."""
    n = params.n_phases
    info = {"movements": len(s), "merged": 0, "dropped": 0, "split": 0, "missing": 0, "found": 0}
    forced = np.zeros(min(len(s), n), dtype=bool)
    if len(s) > n:
        d, h, _ = features(s, e, norm, rate_hz)
        if ref is None:  # no correct repetition anywhere: keep the highest movements
            keep = np.sort(np.argsort(-h, kind="stable")[:n])
        else:  # sub-movements and fidgets far below the subject's lowest phase are no candidates
            cand = np.flatnonzero(h >= params.min_height_fraction * float(np.min(ref[1])))
            if len(cand) < n:
                cand = np.arange(len(s))
            sub = best_subset(d[cand], h[cand], s[cand], e[cand], rate_hz, ref, n, params.max_candidates)
            keep = cand[np.array(sub)]
        ks, ke = s[keep], e[keep]
        if ref is not None:  # the selection's own cost, before sub-movements lengthen the kept phases
            info["cost"] = correction_cost(*features(ks, ke, norm, rate_hz), *ref)
        if params.continuation_gap_s > 0:  # absorb sub-movements that continue a kept phase
            gap = int(round(params.continuation_gap_s * rate_hz))
            for a, b in zip(s, e, strict=True):
                if a in ks:
                    continue
                after = np.flatnonzero((a >= ke) & (a - ke <= gap))
                before = np.flatnonzero((b <= ks) & (ks - b <= gap))
                if len(after):
                    ke[after[-1]] = max(ke[after[-1]], b)
                    info["merged"] += 1
                elif len(before):
                    ks[before[0]] = min(ks[before[0]], a)
                    info["merged"] += 1
        info["dropped"] = len(s) - n - info["merged"]
        s, e = ks, ke
    elif len(s) < n:
        original = set(np.asarray(s).tolist()) | set(np.asarray(e).tolist())
        s, e, found = _split_to(s, e, norm, rate_hz, ref, n, tail)
        info["found"] = len(found)
        info["split"] = len(s) - info["movements"] - len(found)
        info["missing"] = n - len(s)
        forced = np.array(
            [
                int(a) not in found and (int(a) not in original or int(b) not in original)
                for a, b in zip(s, e, strict=True)
            ]
        )
    cost = np.inf
    if ref is not None and len(s) == n:
        cost = correction_cost(*features(s, e, norm, rate_hz), *ref)
    info["forced"] = forced
    info.setdefault("cost", cost)
    return s, e, cost, info


def _tail(group, start, norm, params: RepetitionParams) -> int | None:
    """The end of the recording (samples) for the group holding the trial's last movement (its last phase may lie
    in the rest after it, under every detection level: issue 31, sixth round), else None."""
    return len(norm) if params.tail_bump and len(group) and int(group[-1]) == len(start) - 1 else None


def _kept_cost(costs: list[float], n_keep: int) -> tuple[int, int, float]:
    """(missing groups, groups without a correction cost, summed finite cost of the ``n_keep`` cheapest
    groups): what :func:`segment_repetitions` keeps, compared in that order."""
    kept = np.asarray(sorted(costs)[:n_keep], dtype=float)
    finite = np.isfinite(kept)  # a group that could not be made into n_phases phases ranks after every made one
    return n_keep - len(kept), int((~finite).sum()), float(np.sum(kept[finite]))


def split_merged_groups(groups, start, end, norm, rate_hz, ref, params: RepetitionParams, n_keep: int) -> list:
    """Split groups that hold two (or more) repetitions separated by an unusually short rest.

    The repetition borders come from the longest rests; when a calibration wave (or other non-task activity)
    takes one of the ``n_keep`` groups, two repetitions separated by a rest no longer than the pauses between
    phases stay in one group. Greedily, a group of at least ``2 n_phases`` movements is cut (between two
    movements, both parts keeping ``n_phases``) where the cheaper of the two parts' correction costs is lowest,
    and the cut is accepted when it lowers the summed correction cost of the ``n_keep`` groups
    :func:`segment_repetitions` would keep (fewer groups than ``n_keep`` count as worse than any cost). A
    repetition with extra sub-movements is not cut: its halves do not look like repetitions, so keeping one
    of them instead of the whole costs more.
    """
    n = params.n_phases

    def cost(g) -> float:
        return _select(start[g], end[g], norm, rate_hz, ref, params, _tail(g, start, norm, params))[2]

    groups = list(groups)
    costs = [cost(g) for g in groups]
    while True:
        current = _kept_cost(costs, n_keep)
        best = None
        for i, g in enumerate(groups):
            if len(g) < 2 * n:
                continue
            for cut in range(n, len(g) - n + 1):
                cl, cr = cost(g[:cut]), cost(g[cut:])
                trial = _kept_cost(costs[:i] + [cl, cr] + costs[i + 1 :], n_keep)
                if trial < current and (best is None or trial < best[0]):
                    best = (trial, i, cut, cl, cr)
        if best is None:
            return groups
        _, i, cut, cl, cr = best
        g = groups[i]
        groups[i : i + 1] = [g[:cut], g[cut:]]
        costs[i : i + 1] = [cl, cr]


def segment_repetitions(
    start: np.ndarray,
    end: np.ndarray,
    norm: np.ndarray,
    rate_hz: float,
    params: RepetitionParams = RepetitionParams(),
) -> Phases:
    """Group movements into repetitions and correct each to exactly ``n_phases`` labelled phases.

    ``start``/``end``: movements (sample ranges, e.g. from DynAMoS); ``norm``: filtered angular-velocity norm
    (rad/s) used for heights, repetition splitting and fused-phase splitting. When more candidate groups than
    ``n_repetitions`` are found, the groups with the highest correction cost (least like a correct
    repetition: calibration waves, fidgeting) are dropped.
    """
    start = np.asarray(start, dtype=np.int64)
    end = np.asarray(end, dtype=np.int64)
    norm = norm if hasattr(norm, "chunks") else np.asarray(norm, dtype=float)  # an array or a store
    n_rep = params.n_repetitions or max(1, int(round(len(start) / params.n_phases)))
    empty = np.zeros(0, dtype=np.int64)
    if len(start) == 0:
        return Phases(empty, empty, empty, empty, [], 0)
    if params.rescue_fraction > 0 and params.split != "activity":
        from imulog.process.segmentation.rescue import rescue_missed

        task = ~burst_mask(start, end, rate_hz, params.burst_gap_s, params.burst_min_movements)
        start, end = rescue_missed(start, end, norm, params.rescue_fraction, task=task)
    heights = features(start, end, norm, rate_hz)[1]
    if params.split == "activity":
        rep_s, rep_e = split_repetitions(norm, n_rep, params.activity_fraction)
        subsets = [(np.arange(len(start)), [assign_to_repetitions(start, end, rep_s, rep_e)])]
    else:
        task = np.flatnonzero(~burst_mask(start, end, rate_hz, params.burst_gap_s, params.burst_min_movements))
        angles = turned_angles(start, end, norm, rate_hz) if params.turned_majors else None
        subsets = [task] if len(task) == len(start) else [task, np.arange(len(start))]
        subsets = [
            (
                idx,
                [
                    group_movements(
                        start[idx],
                        end[idx],
                        heights[idx],
                        n_rep + j,
                        params.n_phases,
                        params.major_fraction,
                        params.extra_cut_fraction,
                        size,
                        None if angles is None else angles[idx],
                    )
                    for size in ([params.n_phases] + ([params.n_phases - 1] if params.fused_groups else []))
                    for j in range(params.extra_groups + 1 if size == params.n_phases else 1)
                    if size >= 1
                ],
            )
            for idx in subsets
            if len(idx)
        ]
    ref, best = None, None
    for idx, partitions in subsets:  # without bursts first; with them only when a repetition would go missing
        if best is not None and best[0][0] == 0:
            break
        for rep in partitions:
            groups = [idx[rep == r] for r in range(int(rep.max()) + 1)]
            groups = [g for g in groups if len(g)]
            if ref is None:  # the subject's correct repetitions, from the first partition that has any
                major = np.zeros(len(start), dtype=bool)
                major[idx] = heights[idx] >= params.major_fraction * np.median(heights[idx])
                ref = _reference(groups, start, end, norm, rate_hz, params.n_phases, major)
            if ref is not None and params.split_merged:
                groups = split_merged_groups(groups, start, end, norm, rate_hz, ref, params, n_rep)
            selected = [
                _select(start[g], end[g], norm, rate_hz, ref, params, _tail(g, start, norm, params)) for g in groups
            ]
            if len(selected) > n_rep:  # drop the groups least like a repetition, keep time order
                order = np.argsort([c for _, _, c, _ in selected], kind="stable")
                keep = np.sort(order[:n_rep])
                selected = [selected[k] for k in keep]
            total = _kept_cost([c for _, _, c, _ in selected], n_rep)
            if best is None or total < best[0]:
                best = (total, selected)
    selected = best[1]
    out_s, out_e, out_r, out_p, out_f = [], [], [], [], []
    corrected = 0
    quality = repetition_quality([(c, info) for _, _, c, info in selected], params.n_phases)
    for r, (s, e, _cost, info) in enumerate(selected):
        corrected += int(info["movements"] != params.n_phases)
        out_f.extend(np.resize(np.asarray(info["forced"], dtype=bool), len(s)) if len(s) else [])
        out_s.extend(s)
        out_e.extend(e)
        out_r.extend([r + 1] * len(s))
        out_p.extend(range(len(s)))
    phase = np.asarray(out_p, dtype=np.int64)
    named = len(params.labels) == params.n_phases
    labels = [params.labels[p] if named else f"phase_{p + 1}" for p in phase]
    return Phases(
        start=np.asarray(out_s, dtype=np.int64),
        end=np.asarray(out_e, dtype=np.int64),
        repetition=np.asarray(out_r, dtype=np.int64),
        phase=phase,
        labels=labels,
        n_corrected=corrected,
        forced=np.asarray(out_f, dtype=bool),
        quality=tuple(quality),
    )


def repetition_quality(selected: list[tuple[float, dict]], n_phases: int) -> list[dict]:
    """Per repetition (time order, 1-based ``repetition``): what event correction did and a confidence.

    ``selected``: (correction cost, info of :func:`_select`) per kept repetition. Counts: ``movements`` detected
    in the repetition, ``merged`` (sub-movements absorbed into a kept phase), ``dropped`` (extra movements
    removed), ``split`` (phases made by cutting a fused movement at a minimum of the norm: invented
    boundaries), ``missing`` (phases that could not be made), ``found`` (phases taken from a bump of the norm in a
    rest between two movements: below every detection level, a movement of their own); ``forced`` = phases of
    the repetition with no movement of their own; ``cost`` = the thesis's criterion ``RMS(D-D*) + RMS(H-H*) + RMS(S-S*)`` of the kept
    movements (before absorbed sub-movements lengthen them) against the subject's reference (None without
    reference).

    ``confidence`` (0..1, a documented heuristic, not a calibrated probability) =
    ``0.5^split x 0.5^missing x 0.8^dropped x 0.95^merged x min(1, sqrt(c_typ / cost))``, with ``c_typ`` the median
    cost of the repetitions that needed no correction (the spread of correct repetitions): a repetition that
    looks like the subject's correct ones and needed nothing scores ~1, every correction lowers it.
    """
    selected = [(info.get("cost", c), info) for c, info in selected]
    costs = [c for c, info in selected if info["movements"] == n_phases and np.isfinite(c)]
    c_typ = float(np.median(costs)) if costs else None
    out = []
    for r, (cost, info) in enumerate(selected):
        conf = 0.5 ** (info["split"] + info["missing"]) * 0.8 ** info["dropped"] * 0.95 ** info["merged"]
        if c_typ is not None and np.isfinite(cost) and cost > c_typ > 0:
            conf *= float(np.sqrt(c_typ / cost))
        elif not np.isfinite(cost):
            conf *= 0.5
        out.append(
            {
                "repetition": r + 1,
                "movements": int(info["movements"]),
                "merged": int(info["merged"]),
                "dropped": int(info["dropped"]),
                "split": int(info["split"]),
                "missing": int(info["missing"]),
                "found": int(info.get("found", 0)),
                "forced": int(np.sum(info["forced"])),
                "cost": round(float(cost), 4) if np.isfinite(cost) else None,
                "confidence": round(float(conf), 3),
            }
        )
    return out
