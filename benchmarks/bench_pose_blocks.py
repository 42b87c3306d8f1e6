"""Pose channels: PoseBlock (packed blocks) read against one foxglove.PoseInFrame per sample (the old layout).

    python benchmarks/bench_pose_blocks.py            # 1 M poses (about 30 s on a loaded 2-core machine)

Times are CPU seconds of this process (``time.process_time``: zstd's threads included), so the ratio holds
on a busy machine; the load average is printed.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--old-samples", type=int, default=200_000, help="PoseInFrame messages to decode")
    args = ap.parse_args(argv)
    os.environ["IMULOG_VIEWER_TWINS"] = "0"  # before imulog.archive is imported: time the canonical channel
    from imulog.archive import TrialReader, codec, write_trial
    from imulog.archive._generated.foxglove import PoseInFrame_pb2
    from imulog.model import PoseStream, Recording

    n, m = args.samples, min(args.old_samples, args.samples)
    rng = np.random.default_rng(0)
    t = np.arange(n, dtype=np.int64) * 10_000_000
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    poses = PoseStream("/derived/vicon/cluster_pose", t, rng.normal(size=(n, 3)), q)
    with tempfile.TemporaryDirectory() as tmp:
        path = write_trial(Path(tmp) / "poses.mcap", Recording(poses=[poses]))
        with TrialReader(path) as tr:
            best = float("inf")
            for _ in range(3):
                t0 = time.process_time()
                back = tr.read(poses.topic)
                best = min(best, time.process_time() - t0)
    assert np.array_equal(back.position, poses.position) and np.array_equal(back.orientation, poses.orientation)
    msg = PoseInFrame_pb2.PoseInFrame(frame_id="world")
    payloads = []
    for k in range(m):
        msg.timestamp.seconds, msg.timestamp.nanos = divmod(int(t[k]), 1_000_000_000)
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = poses.position[k]
        msg.pose.orientation.w, msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z = q[k]
        payloads.append(msg.SerializeToString())
    t0 = time.process_time()
    old = codec.decode("foxglove.PoseInFrame", "/x", {}, payloads)
    old_s = time.process_time() - t0
    assert np.array_equal(old.position, poses.position[:m])
    new_rate, old_rate = n / best / 1e6, m / old_s / 1e6
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"PoseBlock read (decompress + decode): {new_rate:.2f} M poses/s CPU ({n} poses)")
    print(f"PoseInFrame decode alone:             {old_rate:.2f} M poses/s CPU ({m} messages)")
    print(f"ratio: {new_rate / old_rate:.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
