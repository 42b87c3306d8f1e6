"""Can another LSL program on this machine hide a session's streams? (liblsl's shared ports, docs/record.md)

    python benchmarks/lsl_crowd.py                 # 34 outlets of another session, then ours: default vs own ports
    python benchmarks/lsl_crowd.py --crowd 0       # the same without the crowd

A "crowd" process publishes ``--crowd`` outlets in a session of its own on liblsl's default ports (what another
LSL program, or a second test run, does); then a process of ours publishes ``wrist`` and ``vicon`` in another
session, and a resolver of our session looks for them ``--tries`` times: once with our session on the default
ports (16571, 16572-16603) and once with ports of its own (``MulticastPort``/``BasePort``, as tests/lsl_session.py
gives each test process). Prints which of our streams each try saw. On this machine (2026-12-07, pylsl 1.18.6):
with 34 crowd outlets, default ports: only ``vicon`` on every try (``wrist``'s outlet got a random port, outside
the swept range, and the query on port 16571 reaches one outlet's socket only); own ports: both, every try.

Uses the machine's default LSL ports while it runs (up to a minute): not for a machine where others record.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from lsl_session import config_text  # noqa: E402

PUBLISH = """
import sys, time, pylsl
names = sys.argv[1].split(",") if sys.argv[1] else []
outlets = [pylsl.StreamOutlet(pylsl.StreamInfo(n, "IMU", 3, 100, "float32", f"crowd-test:{n}")) for n in names]
print("ready", flush=True)
time.sleep(float(sys.argv[2]))
"""

RESOLVE = """
import pylsl
print(",".join(sorted(i.name() for i in pylsl.resolve_streams(2.0))))
"""


def config(folder: Path, session: str, port: int | None) -> Path:
    """An LSL configuration file (tests/lsl_session.py's): this machine only, ``session``, liblsl's default ports
    or ``port`` and the ports after it."""
    cfg = folder / f"{session}.cfg"
    cfg.write_text(config_text(session, port))
    return cfg


def publish(cfg: Path, names: list[str], seconds: float) -> subprocess.Popen:
    """A process with an outlet per name, in ``cfg``'s session, once its outlets exist."""
    proc = subprocess.Popen(
        [sys.executable, "-c", PUBLISH, ",".join(names), str(seconds)],
        env={**os.environ, "LSLAPICFG": str(cfg)},
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout.readline().strip() == "ready"
    return proc


def seen(cfg: Path) -> str:
    env = {**os.environ, "LSLAPICFG": str(cfg)}
    return subprocess.run([sys.executable, "-c", RESOLVE], env=env, capture_output=True, text=True).stdout.strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--crowd", type=int, default=34, help="outlets of the other session (liblsl's range: 32 ports)")
    ap.add_argument("--tries", type=int, default=3)
    ap.add_argument("--port", type=int, default=24000, help="first port of our own block")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="lsl_crowd_") as tmp:
        folder = Path(tmp)
        tag = f"{os.getpid()}"
        for label, port in (("default ports", None), ("own ports", args.port)):
            crowd = publish(config(folder, f"crowd-{tag}", None), [f"c{k}" for k in range(args.crowd)], 60)
            ours = None
            try:
                cfg = config(folder, f"ours-{tag}-{port}", port)
                ours = publish(cfg, ["wrist", "vicon"], 60)
                time.sleep(1.0)
                tries = [seen(cfg) or "none" for _ in range(args.tries)]
                print(f"{args.crowd} crowd outlets, our session on {label}: saw {'; '.join(tries)}")
            finally:
                for p in (ours, crowd):
                    if p is not None:
                        p.kill()
                        p.wait()


if __name__ == "__main__":
    main()
