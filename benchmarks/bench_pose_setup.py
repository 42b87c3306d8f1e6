"""Rigid-body setups: the pairing of IMUs with bodies (``imulog process align`` on ``/poses/*``) before and after the
coarse ranking, wall time in one process, and the same pairs and records checked.

    python benchmarks/bench_pose_setup.py                   # 11 IMUs x 11 bodies, 30 s (about a minute)
    python benchmarks/bench_pose_setup.py --imus 3          # the tests' setup: 3 x 3

The simulator (:func:`imulog.simulate.setup.simulate_setup`, ``rigid_bodies``) gives 3 IMUs with a body each
(upper arm, forearm, trunk); a larger setup joins the simulated setups of seeds 0, 1, ... (IMUs and bodies renamed
``s{seed}_...``, one station clock: the same offset and drift) and keeps the first ``--imus`` of each. Before: every
IMU against every body in full (:func:`imulog.steps.align_pose.compute_pose_alignment`, what the step ran until
this script was added), then the one-to-one pairing; after: :func:`imulog.steps.align_pose_search.search_pose_setup`
(each body's kinematics once, the full alignment for each IMU's best ``refine`` bodies by the coarse score, every
body for an IMU left without one) and the paired IMUs' streams.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def joined_setup(imus: int, duration_s: float):
    """(IMU name -> ImuStream, body topic -> PoseStream) of ``imus`` IMUs and as many bodies."""
    from dataclasses import replace

    from imulog.simulate.setup import simulate_setup

    out_imus, out_bodies = {}, {}
    seed = 0
    while len(out_imus) < imus:
        rec = simulate_setup(seed=seed, duration_s=duration_s, rigid_bodies=True).recording
        for s, p in zip(rec.imus, rec.poses, strict=True):
            if len(out_imus) < imus:
                out_imus[f"s{seed}_{s.name}"] = replace(s, name=f"s{seed}_{s.name}")
                topic = p.topic.replace("/poses/", f"/poses/s{seed}_")
                out_bodies[topic] = replace(p, topic=topic)
        seed += 1
    return out_imus, out_bodies


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--imus", type=int, default=11, help="IMUs, and as many bodies")
    ap.add_argument("--duration", type=float, default=30.0, help="seconds of each simulated setup")
    args = ap.parse_args(argv)
    from imulog.process.alignment import AlignmentParams
    from imulog.steps.align_pose import compute_pose_alignment, pose_body, pose_streams
    from imulog.steps.align_pose_search import ImuInput, pair_imus_with_bodies, search_pose_setup

    params = AlignmentParams()
    imus, bodies = joined_setup(args.imus, args.duration)
    # warm-up (imports, caches) outside both timings
    first_imu, first_body = next(iter(imus.values())), next(iter(bodies.values()))
    compute_pose_alignment(
        "w", first_imu.t_ns, first_imu.gyr, "/poses/w", first_body.t_ns, first_body.position,
        first_body.orientation, params,
    )  # fmt: skip

    t0 = time.perf_counter()
    candidates: dict[str, dict] = {}
    streams_before: dict[str, list] = {}
    for n, s in imus.items():
        candidates[n] = {}
        for b, p in bodies.items():
            try:
                made, rec = compute_pose_alignment(n, s.t_ns, s.gyr, b, p.t_ns, p.position, p.orientation, params)
                candidates[n][b] = rec
                streams_before[(n, b)] = made
            except ValueError as exc:
                candidates[n][b] = str(exc)
    pairs_before, why_before = pair_imus_with_bodies(candidates, params.search.min_vector_match)
    before_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    found = {b: pose_body(b, p.t_ns, p.position, p.orientation, params) for b, p in bodies.items()}
    data = {n: ImuInput(s.t_ns, s.gyr) for n, s in imus.items()}
    pairs, why, search = search_pose_setup(data, found, params)
    streams_after = {
        n: pose_streams(n, found[b], search.candidates[n][b], imus[n].t_ns, imus[n].gyr) for n, b in pairs.items()
    }
    after_s = time.perf_counter() - t0

    same_pairs = pairs == pairs_before and set(why) == set(why_before)
    same_records = all(search.candidates[n][b] == candidates[n][b] for n, b in pairs.items())
    same_streams = all(
        all(
            np.array_equal(a.t_ns, c.t_ns)
            and all(
                np.array_equal(getattr(a, k), getattr(c, k), equal_nan=True)
                for k in ("values", "position", "orientation")
                if getattr(a, k, None) is not None
            )
            for a, c in zip(streams_after[n], streams_before[(n, b)], strict=True)
        )
        for n, b in pairs.items()
    )
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"{len(imus)} IMUs x {len(bodies)} bodies, {args.duration:g} s; {len(pairs)} paired, unpaired: {sorted(why)}")
    print(f"before: {len(imus) * len(bodies)} full alignments, {before_s:.2f} s wall")
    print(
        f"after:  {search.aligned} full alignments ({search.summary()['pairs_scored']} coarse scores), "
        f"{after_s:.2f} s wall ({before_s / after_s:.1f}x)"
    )
    print(f"same pairs: {same_pairs}, same records: {same_records}, same streams: {same_streams}")
    return 0 if same_pairs and same_records and same_streams else 1


if __name__ == "__main__":
    raise SystemExit(main())
