"""Find the markers that move with the IMU: rigid marker triads ranked against the gyroscope.

Any lab names its markers differently (``Subject:Marker`` in Nexus, other cluster names, markers on the
trunk, the upper arm, the other hand). The search

1. measures every marker pair's distance over (a subsample of) the frames: a pair is rigid when the
   distance's standard deviation is under ``max_distance_sd_m`` or ``max_relative_sd`` of the distance
   (skin markers on one segment: 1-3 mm, shoe markers 20 cm apart up to 5 mm; a marker plate: < 0.5 mm), both markers are visible together often enough and far enough apart;
2. lists the triads whose three pairs are rigid and whose triangle is not flat (smallest height at least
   ``min_height_m``), most rigid first, keeping at most ``max_triads`` and no two sharing two markers
   (they would be the same segment);
3. scores every triad at a coarse rate (``coarse_hz``) by the peak normalised cross-correlation of its
   angular-velocity norm with the gyroscope's norm over +-``max_lag_s`` (the R2G thesis's criterion);
4. refines the best ``refine`` triads with the full clock fit (windows across the trial) and ranks them by
   how well the gyroscope, rotated by the least-squares constant rotation, reproduces the triad's angular
   velocity vector (``vector_match``, an R^2: 1 for a rigid body carrying the IMU; markers on another
   segment rotate differently and score lower even when their norms correlate);
5. extends the winner with every marker rigid to all three of its markers (within ``extend_sd_factor``
   times the triad's own spread), kept only when the fit does not get worse.

When no triad reaches ``min_vector_match`` (a single marker on the wrist, or clusters only on other
segments), the caller aligns on one marker's acceleration instead (:func:`rank_markers`): the norm of the
marker's second derivative plus gravity against the accelerometer norm (both rotation invariant), or of
the gravity-free accelerations when the IMU orientation is known. Positions in m, times in int64 ns.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from imulog.param_rules import check_rules

__all__ = [
    "Candidate",
    "SearchParams",
    "SearchResult",
    "acceleration_norm",
    "base_name",
    "candidate_triads",
    "pair_rigidity",
    "rank_markers",
    "resolve_markers",
    "triad_omega_norm",
]

NS = 1_000_000_000
G = 9.80665


@dataclass(frozen=True)
class SearchParams:
    """Cluster search settings (m, Hz).

    ``max_distance_sd_m`` 4 mm or ``max_relative_sd`` 2 % of the distance, whichever is larger: pairs whose
    distance varies more are not rigid; ``min_distance_m`` 1 cm and
    ``min_height_m`` 8 mm: triads too small or too flat give a noisy rotation; ``min_visible`` 0.5: the
    fraction of frames where all markers of a pair/triad are visible; ``rigidity_frames`` frames used for the
    distance statistics; ``max_triads`` triads scored; ``coarse_hz`` their correlation grid; ``refine``
    triads given the full clock fit; ``min_vector_match`` 0.7: below this R^2 the triad is not on the IMU's
    segment and a single marker's acceleration is used; ``extend_sd_factor`` and ``extend_floor_m``: markers
    rigid within max(factor x the triad's spread, floor) of all three join the cluster.
    """

    max_distance_sd_m: float = 0.004
    max_relative_sd: float = 0.02
    min_distance_m: float = 0.01
    min_height_m: float = 0.008
    min_visible: float = 0.5
    rigidity_frames: int = 2000
    max_triads: int = 40
    coarse_hz: float = 25.0
    refine: int = 4
    min_vector_match: float = 0.7
    extend_sd_factor: float = 2.0
    extend_floor_m: float = 0.001
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


@dataclass
class Candidate:
    """One scored marker set: ``rigidity_m`` the largest pair-distance sd, ``ncc`` the coarse peak correlation
    of the angular-velocity norms, ``vector_match`` (R^2) and ``offset_ns`` after refinement (else None)."""

    markers: tuple[str, ...]
    rigidity_m: float
    ncc: float = float("nan")
    vector_match: float | None = None
    offset_ns: int | None = None
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        out = {
            "markers": list(self.markers),
            "rigidity_mm": round(self.rigidity_m * 1e3, 3),
            "ncc": None if not np.isfinite(self.ncc) else round(float(self.ncc), 4),
            "vector_match": None if self.vector_match is None else round(float(self.vector_match), 4),
        }
        if self.offset_ns is not None:
            out["offset_ns"] = int(self.offset_ns)
        return out


@dataclass
class SearchResult:
    """Candidates best first (``candidates[0]`` the choice), how many triads there were and were scored."""

    candidates: list[Candidate]
    n_triads: int
    n_scored: int
    seconds: float = 0.0


def base_name(label: str) -> str:
    """``Subject:Marker`` -> ``Marker`` (Nexus prefixes the subject's name)."""
    return label.rsplit(":", 1)[-1]


def resolve_markers(labels: list[str], names: list[str] | tuple[str, ...]) -> list[int]:
    """Indices of ``names`` in ``labels``, each matched exactly or without the ``Subject:`` prefix.

    Raises ValueError naming the markers not found (and listing the available ones), or an ambiguous name.
    """
    out, missing = [], []
    for name in names:
        exact = [i for i, lab in enumerate(labels) if lab == name]
        if exact:
            out.append(exact[0])
            continue
        base = [i for i, lab in enumerate(labels) if base_name(lab) == base_name(name)]
        if len(base) == 1:
            out.append(base[0])
        elif len(base) > 1:
            raise ValueError(f"marker {name!r} is ambiguous: {', '.join(labels[i] for i in base)}; give the prefix")
        else:
            missing.append(name)
    if missing:
        raise ValueError(f"marker(s) {', '.join(missing)} not in the marker stream (have {', '.join(labels)})")
    return out


def pair_rigidity(pos_m: np.ndarray, params: SearchParams = SearchParams()) -> tuple[np.ndarray, ...]:
    """Pair statistics over at most ``rigidity_frames`` evenly spread frames of ``pos_m`` (N, M, 3).

    Returns ``(sd_m, mean_m, covisible)`` (M, M): the distance's standard deviation and mean, and the
    fraction of frames where both markers are visible (NaN statistics below 10 common frames).
    """
    pos = np.asarray(pos_m, dtype=np.float64)
    n = len(pos)
    idx = np.unique(np.linspace(0, n - 1, min(n, params.rigidity_frames)).astype(int))
    p = pos[idx]
    d = np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1)  # (F, M, M)
    ok = np.isfinite(d)
    cnt = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ok, d, 0.0).sum(axis=0) / cnt
        var = np.where(ok, (d - mean[None]) ** 2, 0.0).sum(axis=0) / np.maximum(cnt - 1, 1)
    sd = np.sqrt(var)
    sd[cnt < 10] = np.nan
    mean[cnt < 10] = np.nan
    return sd, mean, cnt / len(idx)


def _height(a: float, b: float, c: float) -> float:
    """Smallest height (m) of a triangle with sides a, b, c (Heron)."""
    s = 0.5 * (a + b + c)
    area2 = max(s * (s - a) * (s - b) * (s - c), 0.0)
    return 2.0 * np.sqrt(area2) / max(a, b, c)


def candidate_triads(pos_m: np.ndarray, params: SearchParams = SearchParams()) -> tuple[list[tuple], int]:
    """Rigid, non-flat triads ``[(i, j, k, rigidity_m)]`` most rigid first, at most ``max_triads``, no two
    sharing two markers; and the number of rigid triads found before that pruning."""
    sd, mean, cov = pair_rigidity(pos_m, params)
    m = sd.shape[0]
    limit = np.maximum(params.max_distance_sd_m, params.max_relative_sd * np.nan_to_num(mean))
    rigid = (sd <= limit) & (mean >= params.min_distance_m) & (cov >= params.min_visible)
    np.fill_diagonal(rigid, False)
    triads = []
    for i in range(m):
        nbr = np.flatnonzero(rigid[i])
        nbr = nbr[nbr > i]
        for j, k in combinations(nbr, 2):
            if not rigid[j, k]:
                continue
            if _height(mean[i, j], mean[i, k], mean[j, k]) < params.min_height_m:
                continue
            triads.append((i, int(j), int(k), float(max(sd[i, j], sd[i, k], sd[j, k]))))
    total = len(triads)
    # most rigid first; among equally rigid ones the larger triangle
    triads.sort(key=lambda t: (round(t[3], 4), -(mean[t[0], t[1]] + mean[t[0], t[2]] + mean[t[1], t[2]])))
    chosen: list[tuple] = []
    for t in triads:
        s = set(t[:3])
        if any(len(s & set(c[:3])) >= 2 for c in chosen):
            continue
        chosen.append(t)
        if len(chosen) >= params.max_triads:
            break
    return chosen, total


def extend_cluster(
    pos_m: np.ndarray, triad: tuple[int, int, int], rigidity_m: float, params: SearchParams
) -> list[int]:
    """The triad plus every marker rigid (sd within max(factor x rigidity, floor), at most the rigidity
    limit) to all three of it."""
    sd, mean, cov = pair_rigidity(pos_m, params)
    limit = min(max(params.extend_sd_factor * rigidity_m, params.extend_floor_m), params.max_distance_sd_m)
    out = list(triad)
    for j in range(sd.shape[0]):
        if j in out:
            continue
        if all(
            sd[i, j] <= limit and mean[i, j] >= params.min_distance_m and cov[i, j] >= params.min_visible for i in triad
        ):
            out.append(j)
    return out


def triad_omega_norm(pos_m: np.ndarray, rate_hz: float) -> np.ndarray:
    """Angular-velocity norm (N,) rad/s of the frame built on three (filtered) markers (N, 3, 3)."""
    from imulog.process.alignment_frames import angular_velocity_from_rotations, cluster_frame_oxy

    r = cluster_frame_oxy(pos_m[:, 0], pos_m[:, 1], pos_m[:, 2])
    return np.linalg.norm(angular_velocity_from_rotations(r, rate_hz), axis=1)


def acceleration_norm(pos_m: np.ndarray, rate_hz: float, vertical: np.ndarray | None) -> np.ndarray:
    """Norm (N,) m/s^2 of a (filtered) marker's acceleration (second central difference); with ``vertical``
    (unit vector, up in the marker frame) the specific force ``|a + g up|`` an accelerometer measures."""
    p = np.asarray(pos_m, dtype=np.float64)
    dt = 1.0 / rate_hz
    a = np.full_like(p, np.nan)
    a[1:-1] = (p[2:] - 2 * p[1:-1] + p[:-2]) / dt**2
    if vertical is not None:
        a = a + G * np.asarray(vertical, dtype=np.float64)
    return np.linalg.norm(a, axis=1)


def away_from_gaps(missing: np.ndarray, rate_hz: float, margin_s: float = 0.2) -> np.ndarray:
    """True where no missing sample lies within ``margin_s``: the filter's edge transients and the
    derivatives next to a long marker gap are not trusted."""
    miss = np.asarray(missing, dtype=bool)
    if miss.ndim > 1:
        miss = miss.any(axis=tuple(range(1, miss.ndim)))
    k = max(1, int(round(margin_s * rate_hz)))
    near = np.convolve(miss.astype(np.int64), np.ones(2 * k + 1, dtype=np.int64), mode="same") > 0
    return ~near


def lowpass_vector(x: np.ndarray, rate_hz: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass of (N, D) samples (the IMU side); NaN rows are bridged linearly for the
    filter, and the output is NaN there and 0.2 s around them."""
    a = np.asarray(x, dtype=np.float64)
    ok = np.all(np.isfinite(a), axis=1)
    if ok.sum() < 10:
        return np.full_like(a, np.nan)
    idx = np.arange(len(a))
    filled = np.column_stack([np.interp(idx, idx[ok], a[ok, j]) for j in range(a.shape[1])])
    from scipy import signal  # lazy: `imulog info` and the viewer import this module, not the filter

    sos = signal.butter(order, min(cutoff_hz, 0.45 * rate_hz), fs=rate_hz, output="sos")
    out = signal.sosfiltfilt(sos, filled, axis=0)
    out[~away_from_gaps(~ok, rate_hz)] = np.nan  # the bridge and the filter's response to it
    return out


VERTICALS = {
    "+z": (0.0, 0.0, 1.0),
    "+y": (0.0, 1.0, 0.0),
    "+x": (1.0, 0.0, 0.0),
    "-z": (0.0, 0.0, -1.0),
    "-y": (0.0, -1.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
}


def rank_markers(
    t_imu_ns: np.ndarray,
    acc_norm_imu: np.ndarray,
    t_ref_ns: np.ndarray,
    pos_filtered_m: np.ndarray,
    labels: list[str],
    rate_hz: float,
    *,
    gravity_free: bool,
    max_lag_s: float,
    params: SearchParams = SearchParams(),
    missing: np.ndarray | None = None,
) -> list[Candidate]:
    """Markers ranked by the coarse peak correlation of their acceleration norm with the IMU's.

    ``acc_norm_imu``: the (low-passed) accelerometer norm (specific force) or, with ``gravity_free``, the
    norm of the gravity-free acceleration. Without ``gravity_free`` the markers are ranked with +z up, then
    every axis direction is tried as the vertical for the best three and the best kept
    (``extra["vertical"]``). Markers visible in under ``min_visible`` of the frames are skipped.
    """
    from imulog.process.alignment_lag import estimate_lag

    step = max(1, int(round(rate_hz / params.coarse_hz)))
    t_c = np.asarray(t_ref_ns)[::step]

    def score(j: int, verticals: dict) -> Candidate | None:
        p = pos_filtered_m[:, j]
        best = None
        for key, up in verticals.items():
            an = acceleration_norm(p, rate_hz, None if up is None else np.asarray(up))
            if missing is not None:
                an[~away_from_gaps(missing[:, j], rate_hz)] = np.nan
            an = an[::step]
            try:
                est = estimate_lag(
                    t_imu_ns, acc_norm_imu, t_c, an, window_s=1e12, max_lag_s=max_lag_s, grid_hz=params.coarse_hz
                )
            except ValueError:
                continue
            if best is None or est.score > best[0].score:
                best = (est, key)
        if best is None:
            return None
        c = Candidate((labels[j],), 0.0, ncc=best[0].score, offset_ns=best[0].offset_ns)
        c.extra["vertical"], c.extra["index"] = best[1], j
        return c

    visible = [
        j
        for j in range(len(labels))
        if np.mean(np.all(np.isfinite(pos_filtered_m[:, j]), axis=1)) >= params.min_visible
    ]
    # rank with the usual vertical (+z, Vicon and most labs) or gravity-free, then try every axis on the best few
    first = {"none": None} if gravity_free else {"+z": VERTICALS["+z"]}
    out = [c for c in (score(j, first) for j in visible) if c is not None]
    out.sort(key=lambda c: -c.ncc)
    if not gravity_free:
        for k, c in enumerate(out[:3]):
            out[k] = score(c.extra["index"], VERTICALS) or c
        out.sort(key=lambda c: -c.ncc)
    return out
