"""Which IMU is on which rigid body: the pairing of a rigid-body setup (``/poses/*``), cheap where the data allow.

Every IMU is first scored against every body by the correlation of the angular-velocity norms
(:func:`imulog.process.alignment_setup.coarse_scores`, the marker setup's coarse score: no frame alignment needed, a
whole recording at 25 Hz); the full alignment (:func:`imulog.steps.align_pose.align_on_body`: clock fit over windows,
IMU-to-body rotation, vector match) runs only for each IMU's best ``params.search.refine`` bodies (4 by default),
and for every other body of an IMU the pairing leaves without one. IMUs and bodies are then paired one to one by
the summed vector match (:func:`imulog.process.alignment_setup.pair_one_to_one`). An 11 x 11 setup runs 44 full
alignments instead of 121, plus 7 for each IMU no body aligns; a setup of 4 bodies or fewer runs them all, as before. Each body's kinematics are made
once (:func:`imulog.steps.align_pose.pose_body`), not once per IMU. Pure functions, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from imulog.process import alignment as al
from imulog.steps.align_pose import PoseBody, align_on_body


@dataclass
class ImuInput:
    """One IMU of the setup on its device clock: ``t_ns`` int64 ns, ``gyr`` (N, 3) rad/s or None, ``orientation``
    the orientation step's (t_ns, w,x,y,z quaternions) or None, ``acc_global`` (t_ns, m/s^2) or None."""

    t_ns: np.ndarray
    gyr: np.ndarray | None
    orientation: tuple[np.ndarray, np.ndarray] | None = None
    acc_global: tuple[np.ndarray, np.ndarray] | None = None


@dataclass
class PoseSetupSearch:
    """What the search did: ``candidates[imu][body]`` the full alignment's record or why it failed (the bodies it
    was run for), ``coarse[imu][body]`` the coarse score of every pair (None: not computable), ``aligned`` the
    number of full alignments run."""

    candidates: dict[str, dict[str, dict | str]] = field(default_factory=dict)
    coarse: dict[str, dict[str, float | None]] = field(default_factory=dict)
    aligned: int = 0

    def summary(self) -> dict:
        """The ``search`` entry of the main alignment record: pairs scored coarsely and aligned in full."""
        return {"pairs_scored": sum(len(c) for c in self.coarse.values()), "pairs_aligned": self.aligned}


def _coarse_reference(body: PoseBody, coarse_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """The body's angular-velocity norm (rad/s) on about a ``coarse_hz`` grid: (t_ns, norm)."""
    step = max(1, int(round(body.rate_hz / coarse_hz)))
    ck = body.kinematics
    return ck.t_ns[::step], np.linalg.norm(ck.omega_local_rad_s[::step], axis=1)


def search_pose_setup(
    imus: dict[str, ImuInput], bodies: dict[str, PoseBody | str], params: al.AlignmentParams
) -> tuple[dict[str, str], dict[str, str], PoseSetupSearch]:
    """Pair the IMUs with the bodies (``bodies``: topic -> its :class:`PoseBody`, or why it cannot be aligned on).
    Returns (IMU -> body, IMU -> why it has none, the search)."""
    from imulog.process.alignment_setup import coarse_scores

    usable = [b for b, v in bodies.items() if isinstance(v, PoseBody)]
    refs = [_coarse_reference(bodies[b], params.search.coarse_hz) for b in usable]  # type: ignore[arg-type]
    search = PoseSetupSearch()
    order: dict[str, list[str]] = {}
    for n, d in imus.items():
        search.candidates[n] = {b: v for b, v in bodies.items() if isinstance(v, str)}
        if d.gyr is None:
            ncc = np.full(len(usable), -1.0)
        else:
            ncc, _ = coarse_scores(d.t_ns, d.gyr, refs, params)
        search.coarse[n] = {b: (round(float(s), 4) if s > -1.0 else None) for b, s in zip(usable, ncc, strict=True)}
        order[n] = [usable[i] for i in np.argsort(-ncc, kind="stable")]

    def run(n: str, todo: list[str]) -> None:
        d = imus[n]
        for b in todo:
            try:
                search.candidates[n][b] = align_on_body(n, d.t_ns, d.gyr, bodies[b], params, d.orientation)  # type: ignore[arg-type]
            except ValueError as exc:
                search.candidates[n][b] = str(exc)
            search.aligned += 1

    for n in imus:
        run(n, order[n][: max(1, params.search.refine)])
    while True:
        pairs, why = pair_imus_with_bodies(_in_body_order(search.candidates, bodies), params.search.min_vector_match)
        left = {n: [b for b in order[n] if b not in search.candidates[n]] for n in imus if n not in pairs}
        left = {n: todo for n, todo in left.items() if todo}
        if not left:  # every IMU is paired or was tried against every body
            return pairs, why, search
        for n, todo in left.items():
            run(n, todo)


def _in_body_order(candidates: dict[str, dict], bodies: dict[str, object]) -> dict[str, dict]:
    return {n: {b: c[b] for b in bodies if b in c} for n, c in candidates.items()}


def pair_imus_with_bodies(
    candidates: dict[str, dict[str, dict | str]], min_vector_match: float
) -> tuple[dict[str, str], dict[str, str]]:
    """``candidates[imu][body]``: the record of that pair's alignment, or why it failed. Returns (IMU -> body paired
    one to one by the summed vector match, IMU -> why it has none)."""
    from imulog.process.alignment_setup import pair_one_to_one

    imus = list(candidates)
    bodies = sorted({b for c in candidates.values() for b in c})
    score = np.full((len(imus), len(bodies)), np.nan)
    for i, imu in enumerate(imus):
        for j, body in enumerate(bodies):
            got = candidates[imu].get(body)
            if isinstance(got, dict):
                score[i, j] = float(got.get("vector_match") or np.nan)
    pairs = {imus[i]: bodies[j] for i, j in pair_one_to_one(score, min_vector_match)}
    why = {}
    for i, imu in enumerate(imus):
        if imu in pairs:
            continue
        finite = np.isfinite(score[i])
        if finite.any():
            j = int(np.nanargmax(score[i]))
            taken = [k for k, v in pairs.items() if v == bodies[j]]
            why[imu] = f"best body {bodies[j]} (vector match {score[i, j]:.3f})" + (
                f" is {taken[0]}'s" if taken else f" under {min_vector_match:g}"
            )
        else:  # every body failed (a still IMU, no gyroscope): one reason stands for all
            reasons = [str(v) for v in candidates[imu].values()]
            why[imu] = f"no body aligns with it, {len(reasons)} tried; first: {reasons[0]}" if reasons else "no body"
    return pairs, why
