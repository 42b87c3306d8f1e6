"""Import + first call of imulog's compiled kernels from a warm numba cache: keyed stamps against numba's own.

    .venv/bin/python benchmarks/bench_numba_cache.py [--runs 5]

Each run is a fresh subprocess that imports imulog, then every module holding a ``cache=True`` kernel, and makes a
first call into the kinematics solver (the docs' constrained example), the Madgwick filter, the quaternion kernels
and the codec kernels (a small trial written and read back); it reports its wall time and its own user+sys CPU
(``resource.getrusage``; the machine is shared, compare CPU) and the number of kernels numba compiled (cache
misses over every kernel). Two modes, in the same process's loop, alternating: ``keyed``, imulog's default
(:mod:`imulog.numba_cache`: stamps over every module a kernel imports, files in ``__pycache__/numba-keyed``), and
``numba``, numba's own per-file stamps in ``__pycache__`` (``imulog.numba_cache.uninstall()`` before the kernel
modules load: the code before the change). One warm-up run per mode first; a warm cache must compile nothing.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile

_CHILD = r"""
import json, pathlib, re, resource, sys, time
t0 = time.perf_counter()
import imulog
if sys.argv[1] == "numba":
    import imulog.numba_cache
    imulog.numba_cache.uninstall()
import importlib
import numpy as np
root = pathlib.Path(imulog.__file__).parent
modules = []
for f in sorted(root.rglob("*.py")):
    if re.search(r"^\s*@.*\bcache=True", f.read_text(), re.M):
        modules.append(importlib.import_module("imulog." + ".".join(f.relative_to(root).with_suffix("").parts)))
t_import = time.perf_counter() - t0

from imulog.process.kinematics import ArmModel, Workspace, WorkspaceBox, forward_kinematics, solve_sequence
from imulog.process.madgwick import madgwick_imu
from imulog.process.quaternion_kernels import multiply_rows, rotate_rows
from imulog.archive import TrialReader, write_trial
from imulog.model import ImuStream, Recording

model = ArmModel(upper_arm_length_m=0.30, forearm_length_m=0.27, carrying_angle_deg=15)
fk = forward_kinematics(np.radians([[60, 45, 10, 80, 70], [62, 46, 10, 82, 71]]), model)
boxes = Workspace(elbow=WorkspaceBox((-0.1, 0.0, -0.3), (0.3, 0.3, 0.0)),
                  wrist=WorkspaceBox((-0.2, 0.1, -0.5), (0.3, 0.6, 0.1)))
solve_sequence(fk.r_upper_arm, fk.r_forearm, model, constrained=True, workspace=boxes)
n = 500
acc = np.tile([0.0, 0.0, 9.81], (n, 1)); gyr = np.zeros((n, 3))
q = madgwick_imu(gyr, acc, 0.01)
out4 = np.empty((n, 4)); out3 = np.empty((n, 3))
multiply_rows(q, q, out4); rotate_rows(q, acc, out3)
rec = Recording(imus=[ImuStream(name="wrist", t_ns=np.arange(n, dtype=np.int64) * 10_000_000, acc=acc, gyr=gyr)])
path = pathlib.Path(sys.argv[2]) / "t.mcap"
write_trial(path, rec, attach_sources=False, overwrite=True)
with TrialReader(path) as trial:
    trial.read("/imu/wrist")
wall = time.perf_counter() - t0
ru = resource.getrusage(resource.RUSAGE_SELF)
misses = 0
for m in modules:
    for v in vars(m).values():
        stats = getattr(v, "stats", None)
        if getattr(v, "__module__", None) == m.__name__ and hasattr(stats, "cache_misses"):
            misses += sum(stats.cache_misses.values())
print(json.dumps({"import_s": t_import, "wall_s": wall, "cpu_s": ru.ru_utime + ru.ru_stime, "compiled": misses,
                  "modules": len(modules)}))
"""


def run(mode: str, tmp: str) -> dict:
    """One fresh subprocess in ``mode`` (``keyed`` or ``numba``): its figures."""
    out = subprocess.run([sys.executable, "-c", _CHILD, mode, tmp], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    modes = ("numba", "keyed")
    with tempfile.TemporaryDirectory() as tmp:
        for mode in modes:
            warm = run(mode, tmp)
            print(f"{mode:6s} warm-up: compiled {warm['compiled']} kernels, {warm['cpu_s']:.2f} s CPU")
        res: dict[str, list[dict]] = {m: [] for m in modes}
        for _ in range(args.runs):
            for mode in modes:
                res[mode].append(run(mode, tmp))
    med = {m: {k: statistics.median(r[k] for r in res[m]) for k in ("import_s", "wall_s", "cpu_s")} for m in modes}
    for m in modes:
        compiled = sum(r["compiled"] for r in res[m])
        print(
            f"{m:6s} import+first call, median of {args.runs}: wall {med[m]['wall_s']:.3f} s (imports "
            f"{med[m]['import_s']:.3f} s), CPU {med[m]['cpu_s']:.3f} s; kernels compiled in all runs: {compiled}"
        )
    print(
        f"keyed / numba: CPU {med['keyed']['cpu_s'] / med['numba']['cpu_s']:.2f}x, wall "
        f"{med['keyed']['wall_s'] / med['numba']['wall_s']:.2f}x ({res['keyed'][0]['modules']} kernel modules)"
    )


if __name__ == "__main__":
    main()
