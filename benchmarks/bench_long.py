"""Week-long wrist recordings: peak memory and time of every command at 1 and 7 days (issues 17 and 24).

    python benchmarks/bench_long.py                    # 1 and 7 days at 100 Hz (a 774 MB .cwa; ~10 min)
    python benchmarks/bench_long.py --days 0.25 1      # quicker
    python benchmarks/bench_long.py --warm-days 0      # no warm-up: the first length measures numba's compilation
    python benchmarks/bench_long.py --trials day.mcap week.mcap --commands phases   # copies of processed trials
    python benchmarks/bench_long.py --orientation-peer 1     # windowed orientation vs VQF offline, a day, in-process
    python benchmarks/bench_long.py --dynamos 12500 25000 50000   # DynAMoS merge/split time vs movements

For each length: ``imulog simulate home --days D`` writes an Axivity AX6 .cwa (accelerometer + gyroscope,
100 Hz), then ``imulog convert``, ``imulog process orientation``, ``imulog process phases``, ``imulog process
metrics``, ``imulog process trajectory``, ``imulog info``, ``imulog view --save``, ``imulog export`` (the
wrist's samples to Parquet), ``imulog process epochs`` and ``imulog process calibrate`` (a calibration file the
script writes) run as separate processes (``--trials``: on copies of
trials already converted, one per length, for the commands named by ``--commands``); the peak resident memory of each (``ru_maxrss`` of the child),
its wall time and its CPU time (user + system of the child, every thread) are printed, with the ratio of the
longest to the shortest length. The machine's load average
is printed too: times are only comparable within one run.

Kinematics needs two IMUs: the same simulated days are written a second time as a two-IMU trial (the wrist's
samples as ``upper_arm`` and, axes permuted, as ``forearm``, streamed into one archive), whose orientation
(both IMUs), heading and kinematics are measured as ``orientation2``, ``heading`` and ``kinematics``.

``align`` and ``evaluate`` need an optical reference: the same days are written a third time with a marker
cluster that turns with the wrist for the first hour (a lab session before the week at home), and the steps
they need first (for evaluate: align, orientation, phases, trajectory) run unmeasured, their time printed as
``setup``; ``align`` runs on the trial before its orientation, ``align_oriented`` after it (the append then
rewrites the orientation's viewer twins on the new axis, block by block: :mod:`imulog.archive.twin_blocks`).
Every command runs under a cap on its private memory (``--limit-gb``, default 6 GB) so that one that does not
fit fails (reported, the others still run) instead of taking the shared machine's memory.

Before the measured lengths every command runs once, unmeasured, on a short simulated recording (``--warm-days``,
default 0.05 d: 72 minutes, more than one window of every step): numba compiles the kernels a command's code
has not cached yet (``__pycache__/numba-keyed``, keyed on the sources) in the process of the command, and the
compiler's memory stays resident: ``imulog process kinematics`` on the two-IMU quarter day peaked at 614 and
637 MB with an empty cache and at 484 MB with a warm one (docs/long_recordings.md). Without the warm-up the
first length measured that compilation and the others did not (``--warm-days 0``: the cold-cache figures).

Targets: peak RSS at most 1 GB for every command; growth from 1 to 7 days at most 10 % (issue 17) / 15 %
(issue 24, every step including trajectory and kinematics). The final table (``long_table.py``) gives per
command the peak RSS, CPU and wall time at each length, the growth from the shortest to the longest and PASS/FAIL
against 1 GB and 1.15x (a command that failed or was not run fails); ``--summary FILE`` writes it with the
commit, the times and the load averages (JSON for ``.json``, else a Markdown table the docs can quote):

    python benchmarks/bench_long.py --days 1 7 --commands evaluate --summary evaluate.md
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from long_table import format_table, run_info, summary, table_rows, write_summary

COMMANDS = [
    ("convert", ["convert", "{cwa}", "-o", "{mcap}"]),
    # --force: on copies of processed trials (--trials) a step already up to date would do nothing
    ("orientation", ["process", "orientation", "{mcap}", "--force"]),
    ("phases", ["process", "phases", "{mcap}", "--force"]),
    ("metrics", ["process", "metrics", "{mcap}", "--force"]),
    ("trajectory", ["process", "trajectory", "{mcap}", "--force"]),
    ("info", ["info", "{mcap}"]),
    ("view", ["view", "{mcap}", "--save", "{rrd}"]),
    # one long topic to Parquet, block by block (default options; the gyroscope and accelerometer of the day/week)
    ("export", ["export", "{mcap}", "--topic", "{imu_topic}", "-o", "{parquet}", "--overwrite"]),
    # the wrist with a marker cluster (written by reference_trial from the same .cwa)
    ("align", ["process", "align", "{ref}", "--force"]),
    # align on a trial whose orientation exists: the append rewrites the orientation's viewer twins (block by block)
    ("align_oriented", ["process", "align", "{ref}", "--force"]),
    ("evaluate", ["evaluate", "{ref}", "--force"]),
    # the wrist trial's remaining steps (after the others: orientation would read a calibrated channel)
    ("epochs", ["process", "epochs", "{mcap}", "--force"]),
    ("calibrate", ["process", "calibrate", "{mcap}", "--calibration", "{cal}", "--force"]),
    # the two-IMU trial (written by two_imu_trial from the same .cwa)
    (
        "orientation2",
        ["process", "orientation", "{arm}", "--imu", "upper_arm", "--force"],
        ["process", "orientation", "{arm}", "--imu", "forearm", "--force"],
    ),
    ("heading", ["process", "heading", "{arm}", "--force"]),
    # the slowest on a week: last
    ("kinematics", ["process", "kinematics", "{arm}", "--upper-arm", "upper_arm", "--forearm", "forearm", "--force"]),
]
#: steps a measured command needs first, run (unmeasured, time printed) unless up to date: no --force
SETUP = {
    "heading": [
        ["process", "orientation", "{arm}", "--imu", "upper_arm"],
        ["process", "orientation", "{arm}", "--imu", "forearm"],
    ],
    "align_oriented": [["process", "orientation", "{ref}"]],
    "evaluate": [
        ["process", "align", "{ref}"],
        ["process", "orientation", "{ref}"],
        ["process", "phases", "{ref}"],
        ["process", "trajectory", "{ref}"],
    ],
}
TWO_IMU = ("orientation2", "kinematics", "heading")
#: the unmeasured warm-up recording (days): longer than one window of every step (kinematics: half-hour cores,
#: orientation: one-hour cores), so that the windowed paths' kernels are compiled too
WARM_DAYS = 0.05
REFERENCE = ("align", "align_oriented", "evaluate")


def two_imu_trial(cwa: Path, out: Path) -> None:
    """A two-IMU archive of the recording in ``cwa``, written piece by piece (bounded memory): ``upper_arm`` its
    samples, ``forearm`` the same with the axes permuted (so the two orientations differ)."""
    from dataclasses import replace

    from imulog.converters import axivity

    from imulog.archive.streaming import write_trial_streaming

    def pieces():
        for rec in axivity.iter_chunks(cwa):
            imu = rec.imus[0]
            arm = replace(imu, name="upper_arm", meta=dict(imu.meta))
            fore = replace(
                imu, name="forearm", acc=imu.acc[:, [1, 2, 0]], gyr=imu.gyr[:, [1, 2, 0]], meta=dict(imu.meta)
            )
            yield replace(rec, imus=[arm, fore], signals=[])

    write_trial_streaming(out, pieces())


CLUSTER_M = np.array([[0.0, 0.0, 0.0], [0.06, 0.0, 0.0], [0.0, 0.06, 0.0]])  # markers O, X, Y in the sensor frame
WRIST_M = np.array([0.3, 0.2, 1.0])  # where the (only rotating) wrist sits in the room, m


LAB_S = 3600.0  # the marker cluster records the first hour: a lab session with Vicon before the week at home


def reference_trial(cwa: Path, out: Path, noise_m: float = 2e-4, lab_s: float = LAB_S) -> None:
    """An archive of the wrist in ``cwa`` with a rigid marker cluster (O, X, Y, 6 cm apart) that turns with it
    for the first ``lab_s`` seconds (a lab session, as a study would record one; nobody wears a Vicon cluster
    for a week), written piece by piece: what ``align`` and ``evaluate`` need. The home model only rotates the
    wrist, so O stays put and X, Y follow VQF's orientation of the samples (state carried from piece to piece),
    on the IMU's time stamps, with ``noise_m`` of marker noise, to 0.1 mm."""
    from dataclasses import replace

    from imulog.converters import axivity
    from vqf import VQF

    from imulog.archive.streaming import write_trial_streaming
    from imulog.model import MarkerStream
    from imulog.process.quaternion import rotate

    rng = np.random.default_rng(0)
    state: dict = {}

    def pieces():
        for rec in axivity.iter_chunks(cwa):
            imu = rec.imus[0]
            wrist = replace(imu, name="wrist", meta=dict(imu.meta))
            if "vqf" not in state:
                state["vqf"] = VQF(float(np.median(np.diff(imu.t_ns[:1000]))) * 1e-9)
                state["end"] = int(imu.t_ns[0]) + int(lab_s * 1e9)
            keep = imu.t_ns < state["end"]
            if not keep.any():
                yield replace(rec, imus=[wrist], signals=[])
                continue
            gyr, acc = np.ascontiguousarray(imu.gyr[keep]), np.ascontiguousarray(imu.acc[keep])
            q = state["vqf"].updateBatch(gyr, acc)["quat6D"]
            pos = WRIST_M + np.stack([rotate(q, np.broadcast_to(c, (len(q), 3))) for c in CLUSTER_M], axis=1)
            pos = np.round(pos + rng.normal(0.0, noise_m, pos.shape), 4)  # 0.1 mm, as a Vicon export in mm
            markers = MarkerStream("vicon", imu.t_ns[keep], ["O", "X", "Y"], pos)
            yield replace(rec, imus=[wrist], markers=[markers], signals=[])

    write_trial_streaming(out, pieces())


def calibration_file(out: Path) -> None:
    """A calibration JSON (``imulog calibrate``'s format) with small biases and a near-identity matrix."""
    from imulog.process.calibration import AxisCalibration, Calibration

    acc = AxisCalibration(np.array([0.02, -0.01, 0.03]), np.eye(3) * 1.01)
    gyr = AxisCalibration(np.array([0.001, -0.002, 0.0005]), np.eye(3))
    out.write_text(json.dumps(Calibration(acc=acc, gyr=gyr).to_dict()))


#: runs the measured command from a small process: a child's ``ru_maxrss`` starts at the RSS of the process that
#: forked it (Linux copies the page tables at fork and keeps their high-water mark through exec), and the benchmark
#: itself holds up to 400 MB after writing a trial. Arguments: the file for "maxrss_kB utime_s stime_s", the cap on
#: private memory in GB (RLIMIT_DATA: heap and anonymous maps, not the mapped trial; 0: none), the command.
LAUNCHER = """
import os, resource, sys
out, cap, args = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
if cap:
    resource.setrlimit(resource.RLIMIT_DATA, (int(cap * 2**30),) * 2)
_, status, u = os.wait4(os.posix_spawn(args[0], args, os.environ), 0)
with open(out, "w") as f:
    f.write(f"{u.ru_maxrss} {u.ru_utime} {u.ru_stime}")
code = os.waitstatus_to_exitcode(status)
sys.exit(code if code >= 0 else 128 - code)
"""


def _interrupt(signum: int, frame: object) -> None:
    """SIGTERM: stop as Ctrl-C does (the running command killed, the table printed with what was measured)."""
    raise KeyboardInterrupt


class CommandFailed(Exception):
    """A measured command exited non-zero: its last line of error output."""


def run(args: list[str], limit_gb: float | None = None) -> tuple[float, float, float]:
    """(wall seconds, peak RSS MB, CPU seconds: user + system) of one command, spawned by :data:`LAUNCHER` under
    a cap on its private memory (``limit_gb``) so that one that would take the shared machine's memory fails."""
    fd, usage_file = tempfile.mkstemp(suffix=".rusage")
    os.close(fd)
    t0 = time.perf_counter()
    launch = [sys.executable, "-S", "-c", LAUNCHER, usage_file, str(limit_gb or 0), *args]
    proc = subprocess.Popen(launch, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    try:
        _, err_bytes = proc.communicate()
    except KeyboardInterrupt:  # the benchmark stopped (Ctrl-C, SIGTERM): the command with it
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        os.unlink(usage_file)
        raise
    elapsed = time.perf_counter() - t0
    text = Path(usage_file).read_text().split()
    os.unlink(usage_file)
    maxrss_mb, cpu = (int(text[0]) / 1024.0, float(text[1]) + float(text[2])) if text else (0.0, 0.0)
    err = err_bytes.decode(errors="replace")
    if proc.returncode != 0:
        last = [line for line in err.splitlines() if line.strip()][-1:] or [f"exit {proc.returncode}"]
        raise CommandFailed(f"{' '.join(args[2:])}: {last[0][:300]} (peak {maxrss_mb:.0f} MB)")
    return elapsed, maxrss_mb, cpu  # ru_maxrss: kB on Linux


def orientation_peer(days: float, rate: float = 100.0, repeats: int = 1) -> int:
    """The orientation step's windowed computation (imulog.steps.orientation.orientation_windows, default windows)
    against VQF's offline filter (``vqf.offlineVQF``) on the same in-memory samples of a simulated wrist, in this
    process; prints samples/s of each and the ratio (target >= 0.9). The step also gives the gravity-free
    acceleration and static mask and handles gaps; the peer only the quaternions. Both run once on ten minutes
    first, untimed (imports, numba's cache load)."""
    import numpy as np
    from vqf import offlineVQF

    from imulog.process.orientation import OrientationParams
    from imulog.steps.orientation import orientation_windows
    from imulog.steps.windows import WindowParams

    n = int(days * 86400 * rate)
    rng = np.random.default_rng(0)
    k = np.arange(n, dtype=np.float64)
    gyr = np.column_stack([0.5 * np.sin(k / 97.0), 0.4 * np.cos(k / 131.0), 0.3 * np.sin(k / 1700.0)])
    gyr += rng.normal(0.0, 0.01, (n, 3))
    acc = np.column_stack([np.sin(k / 5000.0), np.cos(k / 7000.0), np.full(n, 9.7)]) + rng.normal(0, 0.05, (n, 3))
    t = (k * (1e9 / rate)).astype(np.int64)
    block = 20_000  # about the samples of one 2 MiB ImuBlock chunk

    def blocks():
        for a in range(0, n, block):
            yield t[a : a + block], acc[a : a + block], gyr[a : a + block], None

    plan = WindowParams().plan(n, rate)
    # warm-up on ten minutes, untimed: imports and the compiled kernels' cache load (numba), which the step's
    # command pays once for reading the archive anyway; VQF is a compiled extension with nothing to warm
    warm = min(n, int(600 * rate))
    warm_blocks = iter([(t[:warm], acc[:warm], gyr[:warm], None)])
    for _piece in orientation_windows(warm_blocks, warm, WindowParams().plan(warm, rate), "wrist", OrientationParams()):
        pass
    offlineVQF(gyr[:warm], acc[:warm], None, 1.0 / rate)
    best_step = best_peer = cpu_step = cpu_peer = float("inf")  # wall and CPU (this process, every thread) seconds
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        for _piece in orientation_windows(blocks(), n, plan, "wrist", OrientationParams()):
            pass
        best_step = min(best_step, time.perf_counter() - t0)
        cpu_step = min(cpu_step, time.process_time() - c0)
        t0, c0 = time.perf_counter(), time.process_time()
        offlineVQF(gyr, acc, None, 1.0 / rate)
        best_peer = min(best_peer, time.perf_counter() - t0)
        cpu_peer = min(cpu_peer, time.process_time() - c0)
    ratio = best_peer / best_step
    print(f"{n / 1e6:.2f} M samples ({days:g} d at {rate:g} Hz), {len(plan)} windows; load {os.getloadavg()[0]:.1f}")
    print(f"imulog orientation (windowed): {best_step:.1f} s, {n / best_step / 1e6:.2f} M samples/s")
    print(f"vqf.offlineVQF (whole):        {best_peer:.1f} s, {n / best_peer / 1e6:.2f} M samples/s")
    print(f"CPU: imulog {cpu_step:.1f} s, vqf {cpu_peer:.1f} s, ratio {cpu_peer / cpu_step:.2f}x")
    print(f"speed ratio {ratio:.2f}x: {'meets target' if ratio >= 0.9 else 'MISSES'} (>= 0.9x)")
    return 0 if ratio >= 0.9 else 1


def dynamos_scaling(counts: list[int]) -> int:
    """Time of DynAMoS's merge/split (imulog.process.segmentation.dynamos.postprocess) to convergence on the first
    K of 50,000 synthetic daily-life movements (log-normal durations, median 1.5 s at 100 Hz, rests of 0.5-30 s);
    target: a week's movements (tens of thousands) in well under a minute, about linear in K."""
    import numpy as np

    from imulog.process.segmentation.dynamos import postprocess

    rng = np.random.default_rng(0)
    k = max(counts)
    durs = np.maximum(5, rng.lognormal(np.log(150), 0.7, k).astype(int))
    start = np.cumsum(rng.integers(50, 3000, k) + np.r_[0, durs[:-1]])
    end = start + durs
    n = int(end[-1]) + 10
    norm = np.abs(np.sin(np.arange(n) / 17.0)) + rng.normal(0.0, 0.05, n)
    worst = 0.0
    for count in sorted(counts):
        stats: dict = {}
        t0 = time.perf_counter()
        postprocess(start[:count], end[:count], norm, 0.8, 1.4, 10**9, stats)
        elapsed = time.perf_counter() - t0
        worst = max(worst, elapsed)
        print(f"{count:7d} movements: {elapsed:6.2f} s, {stats['changes']} changes; load {os.getloadavg()[0]:.1f}")
    return 0 if worst < 60.0 else 1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--orientation-peer",
        type=float,
        default=None,
        metavar="DAYS",
        help="only compare the windowed orientation with VQF offline on DAYS of samples, in-process",
    )
    ap.add_argument(
        "--dynamos",
        type=int,
        nargs="+",
        default=None,
        metavar="K",
        help="only time DynAMoS's merge/split on K synthetic movements (several K: scaling)",
    )
    ap.add_argument("--days", type=float, nargs="+", default=[1.0, 7.0], help="recording lengths, days")
    ap.add_argument("--dir", default=None, help="scratch folder (needs ~3 GB per simulated week)")
    ap.add_argument("--trials", nargs="+", default=None, help="converted trials, one per --days value (copied)")
    ap.add_argument(
        "--warm-days",
        type=float,
        default=WARM_DAYS,
        metavar="DAYS",
        help="first run every command unmeasured on DAYS of simulated samples (numba's cache warm for every "
        f"measured length; default {WARM_DAYS:g}); 0: no warm-up (the first length then measures the compilation)",
    )
    ap.add_argument("--commands", nargs="+", default=[c[0] for c in COMMANDS], choices=[c[0] for c in COMMANDS])
    ap.add_argument(
        "--limit-gb",
        type=float,
        default=6.0,
        help="cap each command's private memory (RLIMIT_DATA) so one that does not fit fails instead of taking the "
        "shared machine's memory; 0: no cap",
    )
    ap.add_argument(
        "--summary",
        type=Path,
        default=None,
        metavar="FILE",
        help="also write the final table with the commit, times and load averages: JSON for .json, else Markdown",
    )
    args = ap.parse_args(argv)
    if args.dynamos:
        return dynamos_scaling(args.dynamos)
    if args.orientation_peer is not None:
        return orientation_peer(args.orientation_peer)
    if args.trials and len(args.trials) != len(args.days):
        ap.error(f"--trials needs one trial per --days value ({len(args.days)})")
    commands = [(c[0], c[1:]) for c in COMMANDS if c[0] in args.commands and not (args.trials and c[0] == "convert")]
    names = {name for name, _ in commands}
    imulog = [sys.executable, "-m", "imulog"]
    results: dict[float, dict[str, tuple[float, float, float] | str]] = {}
    start, loads = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), [os.getloadavg()[0]]
    measured = run_info(Path(__file__).resolve().parents[1])  # the commit at the start (a run can take hours)
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        interrupted = False
        previous = signal.signal(signal.SIGTERM, _interrupt)
        try:
            lengths = [None, *args.days] if args.warm_days > 0 else list(args.days)
            for i, length in enumerate(lengths):
                warm = length is None  # the warm-up: every command once, its figures printed, not tabled
                days = args.warm_days if warm else length
                label = f"warm-up {days:g} d" if warm else f"{days:g} d"
                given = args.trials[i - (len(lengths) - len(args.days))] if args.trials and not warm else None
                folder = Path(tmp) / ("warm" if warm else f"d{days:g}")
                folder.mkdir()
                paths = {
                    "cwa": folder / "home_s00_t00.cwa",
                    "mcap": folder / "home.mcap",
                    "rrd": folder / "home.rrd",
                    "arm": folder / "arm.mcap",
                    "ref": folder / "ref.mcap",
                    "cal": folder / "cal.json",
                    "parquet": folder / "wrist.parquet",
                }
                if given:
                    shutil.copy(given, paths["mcap"])
                if not given or names & {*TWO_IMU, *REFERENCE}:
                    subprocess.run(
                        [*imulog, "simulate", "home", "-o", str(folder), "--days", str(days)],
                        check=True,
                        stdout=subprocess.DEVNULL,
                        stderr=subprocess.DEVNULL,
                    )
                measured_here: dict[str, tuple[float, float, float] | str] = {}
                if not warm:
                    results[days] = measured_here
                calibration_file(paths["cal"])
                for name, templates in commands:
                    # each trial written when a command first needs it (unmeasured)
                    uses = {
                        k
                        for t in [*templates, *SETUP.get(name, [])]
                        for a in t
                        for k in ("mcap", "arm", "ref")
                        if a == f"{{{k}}}"
                    }
                    # the wrist's steps without convert asked (convert itself is measured writing it)
                    if "mcap" in uses and name != "convert" and not paths["mcap"].exists():
                        subprocess.run([*imulog, "convert", str(paths["cwa"]), "-o", str(paths["mcap"])], check=True)
                    if "arm" in uses and not paths["arm"].exists():
                        two_imu_trial(paths["cwa"], paths["arm"])
                    if "ref" in uses and not paths["ref"].exists():
                        reference_trial(paths["cwa"], paths["ref"])
                    if any("{imu_topic}" in a for t in templates for a in t):
                        from imulog.archive import TrialReader

                        with TrialReader(paths["mcap"]) as trial:  # the device's IMU channel (/imu/ax6_4321)
                            fields = {"imu_topic": next(t for t in trial.topics() if t.startswith("/imu/"))}
                    else:
                        fields = {}
                    try:
                        for setup in SETUP.get(name, []):
                            wall, mb, cpu = run([*imulog, *[a.format(**paths) for a in setup]], args.limit_gb)
                            print(
                                f"{label}   setup {' '.join(setup[:2])}: {wall:.1f} s wall, {cpu:.1f} s CPU, {mb:.0f} MB"
                            )
                        runs = [
                            run([*imulog, *[a.format(**paths, **fields) for a in template]], args.limit_gb)
                            for template in templates
                        ]
                    except CommandFailed as exc:
                        measured_here[name] = str(exc)
                        loads.append(os.getloadavg()[0])
                        print(f"{label} {name}: FAILED {exc}; load {os.getloadavg()[0]:.1f}", flush=True)
                        continue
                    measured_here[name] = (sum(r[0] for r in runs), max(r[1] for r in runs), sum(r[2] for r in runs))
                    wall, mb, cpu = measured_here[name]
                    loads.append(os.getloadavg()[0])
                    print(
                        f"{label} {name}: {wall:.1f} s wall, {cpu:.1f} s CPU, {mb:.0f} MB, load {os.getloadavg()[0]:.1f}",
                        flush=True,
                    )
                sizes = {k: p.stat().st_size / 1e6 for k, p in paths.items() if p.exists()}
                print(f"{label}: " + ", ".join(f"{k} {v:.0f} MB" for k, v in sizes.items()), flush=True)
                for p in paths.values():
                    p.unlink(missing_ok=True)
        except KeyboardInterrupt:  # what was measured so far still makes the table; the rest is "not run"
            interrupted = True
            print(f"interrupted; load {os.getloadavg()[0]:.1f}", flush=True)
        finally:
            signal.signal(signal.SIGTERM, previous)
    one, five, _ = os.getloadavg()
    print(
        f"load average {one:.1f} (1 min), {five:.1f} (5 min) on {os.cpu_count()} cores; "
        f"self peak {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB"
    )
    meta = {
        **measured,
        "argv": " ".join(["python benchmarks/bench_long.py", *(argv if argv is not None else sys.argv[1:])]),
        "start": start,
        "end": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load": f"{min(loads):.1f}-{max(loads):.1f} (1 min, at each command's end)",
        "interrupted": interrupted,
        "warm_days": args.warm_days,
    }
    return verdicts(commands, results, args.days, args.summary, meta)


def verdicts(
    commands: list[tuple[str, list]],
    results: dict[float, dict[str, tuple[float, float, float] | str]],
    days: list,
    summary_file: Path | None = None,
    meta: dict | None = None,
) -> int:
    """Print the final table (per command: peak RSS, CPU and wall at each length, the RSS growth from the shortest
    to the longest, PASS/FAIL against 1 GB and 1.15x: :mod:`long_table`), write it to ``summary_file`` (JSON or
    Markdown) if given; 0 when every command passes."""
    rows = table_rows([name for name, _ in commands], results, days)
    print(format_table(rows, days), flush=True)
    if summary_file is not None:
        write_summary(summary_file, summary(rows, days, meta or {}))
        print(f"summary: {summary_file}")
    return 0 if all(r["verdict"] == "PASS" for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
