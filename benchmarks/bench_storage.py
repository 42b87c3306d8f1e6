"""Size per hour of data: imulog's archive against the device's own file and against a fair peer (issue 28).

    python benchmarks/bench_storage.py                  # 1 day of home AX6 .cwa and a 1-hour IMU text trial
    python benchmarks/bench_storage.py --days 7         # the week of issue 28 (minutes on 2 shared cores)
    python benchmarks/bench_storage.py --days 7 --minutes-imu 0 --steps   # the week converted, then processed
    python benchmarks/bench_storage.py --days 0 --minutes-imu 0 --devices --demo   # real samples, the demo

Cases (generated in a temporary folder):

* home: ``imulog simulate home --days N`` (a 100 Hz Axivity AX6 .cwa, the device's own file), converted with
  ``imulog convert --attach-original never`` (the original recorded by size and SHA-256, not attached);
* ``--steps``: the converted home recording then goes through ``imulog process orientation``, ``phases``,
  ``metrics`` and ``epochs`` (each its own process), with the archive's size after each step against the .cwa
  (issue 28: at most 2.5x after all four) and each step's wall and CPU time (user + sys of the child: the machine
  is shared, so wall time depends on the load);
* IMU text: the 1-hour 9-axis 100 Hz text file of ``bench_convert.py`` (``%.6g`` values), converted with
  ``--no-attach``;
* ``--devices``: the shared real samples of the integer sources (ActiGraph ``.gt3x``, GENEActiv ``.bin``,
  integer C3D), each converted with ``--no-attach`` (short files: the viewer twins weigh in);
* ``--demo``: ``imulog demo --no-view``, the whole processed trial and its attached originals (50.6 MB before
  issue 28's second part).

The peer is what a user of the `mcap` library would write for the same arrays: every canonical channel of the
converted trial read back and written as 1-s blocks of float64 arrays with explicit times (imulog's
schema_version-1 layout, ``codec.encode(stream, compact=False)``), zstd chunks of the same target size, in the
same process. Ratios: the archive over the device file and over the peer. Targets (issue 28): the week at most
1.3x its .cwa; the 1-hour IMU text trial at most 1.1x the peer. The machine's load average is printed.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_archive import load_average
from bench_convert import write_imu

from imulog.archive import TrialReader, codec
from imulog.archive._builder import CHUNK_TARGET_BYTES
from imulog.archive.twins import is_twin


def imulog_cli(*args: str) -> tuple[float, float]:
    """Run ``imulog ARGS`` in a child process; -> (wall s, CPU s: the child's user + sys)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "imulog", *args], check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


STEPS = ("orientation", "phases", "metrics", "epochs")


def steps(cwa: Path, trial: Path) -> None:
    """Each processing step of a home recording in turn, with the archive's size after it against the .cwa."""
    src = cwa.stat().st_size
    before = trial.stat().st_size
    for step in STEPS:
        wall, cpu = imulog_cli("process", step, str(trial))
        size = trial.stat().st_size
        print(
            f"  after {step}: {size / 1e6:.1f} MB (+{(size - before) / 1e6:.1f} MB) = {size / src:.2f}x the .cwa; "
            f"wall {wall:.0f} s, CPU {cpu:.0f} s (user + sys), load average {load_average()}",
            flush=True,
        )
        before = size


def peer_size(trial: Path, out: Path) -> int:
    """Bytes of the peer's file: the trial's canonical channels as float64 1-s blocks with the mcap library."""
    from mcap.writer import CompressionType, Writer

    with TrialReader(trial) as tr, open(out, "wb") as f:
        w = Writer(f, chunk_size=CHUNK_TARGET_BYTES, compression=CompressionType.ZSTD)
        w.start(library="peer")
        schemas: dict[str, int] = {}
        for ch in tr.channels:
            if is_twin(ch.topic, ch.metadata) or ch.schema_name not in codec.BLOCK_SCHEMAS:
                continue
            if ch.schema_name not in schemas:
                data = codec.file_descriptor_set(ch.schema_name)
                schemas[ch.schema_name] = w.register_schema(ch.schema_name, "protobuf", data)
            cid = None
            seq = 0
            for piece in tr.iter_blocks(ch.topic):  # bounded memory: one chunk of the channel at a time
                _, meta, times, payloads = codec.encode(piece, compact=False)
                if cid is None:
                    cid = w.register_channel(ch.topic, "protobuf", schemas[ch.schema_name], metadata=meta)
                for t, payload in zip(times, payloads, strict=True):
                    w.add_message(cid, t, payload, t, sequence=seq)
                    seq += 1
        w.finish()
    return out.stat().st_size


def report(name: str, hours: float, source: Path, trial: Path, peer: int) -> None:
    mb = 1e6
    src, arc = source.stat().st_size, trial.stat().st_size
    print(
        f"{name}: {hours:g} h; source file {src / mb:.1f} MB ({src / mb / hours:.2f} MB/h); imulog "
        f"{arc / mb:.1f} MB ({arc / mb / hours:.2f} MB/h) = {arc / src:.2f}x the source; peer (float64 1-s blocks, "
        f"mcap library) {peer / mb:.1f} MB ({peer / mb / hours:.2f} MB/h); imulog/peer {arc / peer:.2f}x",
        flush=True,
    )


SHARED = Path(__file__).resolve().parent.parent / ".." / "shared" / "data"
SAMPLES = [
    "devices/actigraph_gt3x/example.gt3x",
    "devices/geneactiv_bin/GENEActiv_testfile.bin",
    "devices/c3d_samples/pc_int.c3d",
    "devices/c3d_samples/MACsample.c3d",
]


def devices(d: Path) -> None:
    """The shared integer-source samples converted without their original."""
    for rel in SAMPLES:
        src = SHARED / rel
        if not src.exists():
            print(f"{rel}: not available")
            continue
        trial = d / f"{src.stem}.mcap"
        imulog_cli("convert", str(src), "-o", str(trial), "--no-attach")
        size, peer, n = trial.stat().st_size, peer_size(trial, d / f"{src.stem}_peer.mcap"), src.stat().st_size
        print(
            f"{src.name}: source {n / 1e3:.0f} kB; imulog {size / 1e3:.0f} kB = {size / n:.2f}x the source; "
            f"peer {peer / 1e3:.0f} kB; imulog/peer {size / peer:.2f}x"
        )


def demo(d: Path) -> None:
    """``imulog demo --no-view``: the processed trial and its attachments."""
    out = d / "demo"
    subprocess.run(
        [sys.executable, "-m", "imulog", "demo", "-o", str(out), "--no-view", "--no-open"],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    trial = out / "trial.mcap"
    with TrialReader(trial) as tr:
        atts = tr.attachment_infos()
    originals = sum((out / "raw" / a["name"]).stat().st_size for a in atts if (out / "raw" / a["name"]).exists())
    stored = sum(a["bytes"] for a in atts)
    size = trial.stat().st_size
    print(
        f"demo trial: {size / 1e6:.1f} MB = {size / 50.6e6:.2f}x the 50.6 MB before; attached originals "
        f"{originals / 1e6:.1f} MB stored as {stored / 1e6:.1f} MB"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=1.0, help="home recording length in days (default 1; 0: skip)")
    ap.add_argument("--minutes-imu", type=float, default=60.0, help="IMU text trial length (default 60)")
    ap.add_argument("--devices", action="store_true", help="also the shared .gt3x, GENEActiv and C3D samples")
    ap.add_argument("--demo", action="store_true", help="also the demo trial (imulog demo --no-view)")
    ap.add_argument("--steps", action="store_true", help="then orientation, phases, metrics, epochs (sizes after each)")
    ap.add_argument("--cwa", default=None, help="an existing `imulog simulate home` .cwa instead of simulating --days")
    ap.add_argument("--dir", default=None, help="where to write the files (default: system temp)")
    a = ap.parse_args(argv)
    print(f"load average {load_average()}")
    with tempfile.TemporaryDirectory(dir=a.dir) as tmp:
        d = Path(tmp)
        if a.devices:
            devices(d)
        if a.demo:
            demo(d)
        if a.minutes_imu > 0:
            text = d / "imu_1h.csv"
            write_imu(text, a.minutes_imu)
            trial = d / "imu.mcap"
            imulog_cli("convert", str(text), "-o", str(trial), "--no-attach")
            report("IMU text 100 Hz 9-axis", a.minutes_imu / 60, text, trial, peer_size(trial, d / "imu_peer.mcap"))
        if a.days <= 0:
            return 0
        if a.cwa:
            cwa = Path(a.cwa)
        else:
            imulog_cli("simulate", "home", "-o", str(d), "--days", str(a.days))
            cwa = d / "home_s00_t00.cwa"
        home = d / "home.mcap"
        wall, cpu = imulog_cli("convert", str(cwa), "-o", str(home), "--attach-original", "never")
        print(f"  convert: wall {wall:.0f} s, CPU {cpu:.0f} s (user + sys)", flush=True)
        report("home AX6 .cwa 100 Hz", a.days * 24, cwa, home, peer_size(home, d / "home_peer.mcap"))
        (d / "home_peer.mcap").unlink()
        if a.steps:
            steps(cwa, home)
    return 0


if __name__ == "__main__":
    sys.exit(main())
