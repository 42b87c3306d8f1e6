"""Long wearable recordings: decode speed and peak memory of the Axivity and ActiGraph readers.

Builds a long .cwa (the real AX6 sample's blocks repeated with shifted RTC time stamps and fixed checksums) and a
long .gt3x (the real GT9X Link log.bin records repeated with shifted seconds and fixed checksums) in a temporary
folder, then decodes each (a) chunk by chunk, dropping every chunk (what a streaming writer sees) and (b) whole.
Peak memory is the growth of the process's peak RSS while decoding, measured in a fresh subprocess per case.

    .venv/bin/python benchmarks/bench_wearables.py [--hours 6]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "devices"


def _pack_rtc(epoch_s: np.ndarray) -> np.ndarray:
    t = np.asarray(epoch_s, dtype="datetime64[s]")
    years = t.astype("datetime64[Y]").astype(np.int64) + 1970
    months = t.astype("datetime64[M]").astype(np.int64) % 12 + 1
    days = (t - t.astype("datetime64[M]")).astype("timedelta64[D]").astype(np.int64) + 1
    secs = (t - t.astype("datetime64[D]")).astype(np.int64)
    h, m, s = secs // 3600, secs // 60 % 60, secs % 60
    return ((years - 2000) << 26 | months << 22 | days << 17 | h << 12 | m << 6 | s).astype(np.uint32)


def make_cwa(out: Path, hours: float) -> int:
    from imulog.converters.axivity import BLOCK_DTYPE, HEADER_BYTES, rtc_to_epoch_s

    data = (DATA / "axivity_cwa" / "ax6_sample.cwa").read_bytes()
    head, blocks = data[:HEADER_BYTES], np.frombuffer(data[HEADER_BYTES:], dtype=BLOCK_DTYPE).copy()
    secs = rtc_to_epoch_s(blocks["rtc"])
    span = int(secs[-1] - secs[0]) + 1
    copies = max(1, int(hours * 3600 // span))
    with open(out, "wb") as f:
        f.write(head)
        for k in range(copies):
            b = blocks.copy()
            b["rtc"] = _pack_rtc(secs + k * span)
            b["sequence"] = np.arange(len(b)) + k * len(b)
            b["checksum"] = 0
            words = b.view("<u2").reshape(len(b), 256).sum(axis=1, dtype=np.uint64)
            b["checksum"] = ((-words.astype(np.int64)) & 0xFFFF).astype(np.uint16)
            f.write(b.tobytes())
    return copies * len(blocks) * 40


def make_gt3x(out: Path, hours: float) -> int:
    import struct

    with zipfile.ZipFile(DATA / "actigraph_gt3x" / "example.gt3x") as z:
        log, info = z.read("log.bin"), z.read("info.txt")
    recs, pos = [], 0
    while pos < len(log):
        typ, sec, size = struct.unpack_from("<BIH", log, pos + 1)
        recs.append((typ, sec, log[pos + 8 : pos + 8 + size]))
        pos += 9 + size
    data_recs = [r for r in recs if r[0] in (0x1A, 0x19, 0x02, 0x0D)]
    setup = [r for r in recs if r[0] not in (0x1A, 0x19, 0x02, 0x0D, 0x03)]
    span = max(r[1] for r in data_recs) - min(r[1] for r in data_recs) + 1
    copies = max(1, int(hours * 3600 // span))

    def record(typ: int, sec: int, payload: bytes) -> bytes:
        head = struct.pack("<BBIH", 0x1E, typ, sec, len(payload))
        x = np.bitwise_xor.reduce(np.frombuffer(head + payload, dtype=np.uint8))
        return head + payload + bytes([int(~x) & 0xFF])

    samples = 0
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as z, z.open("log.bin", "w", force_zip64=True) as f:
        for typ, sec, payload in setup:
            f.write(record(typ, sec, payload))
        for k in range(copies):
            f.write(b"".join(record(t, s + k * span, p) for t, s, p in data_recs))
            samples += sum(len(p) // 6 for t, _, p in data_recs if t == 0x1A)
    with zipfile.ZipFile(out, "a") as z:
        z.writestr("info.txt", info)
    return samples


def _measure(kind: str, path: str, mode: str) -> dict:
    code = f"""
import json, resource, time
from pathlib import Path
from imulog.converters.{kind} import iter_chunks, {"read_cwa" if kind == "axivity" else "read_gt3x"} as read_all
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
n = 0
if "{mode}" == "chunks":
    for c in iter_chunks(Path("{path}")):
        n += len(c.imus[0])
else:
    rec = read_all(Path("{path}"))
    n = len(rec.imus[0])
dt = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps(dict(seconds=dt, samples=n, peak_growth_mb=(peak - base) / 1024)))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(out.stdout)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=6.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cwa, gt3x = Path(tmp) / "long.cwa", Path(tmp) / "long.gt3x"
        n_cwa = make_cwa(cwa, args.hours)
        n_gt3x = make_gt3x(gt3x, args.hours)
        for kind, path, n in (("axivity", cwa, n_cwa), ("actigraph", gt3x, n_gt3x)):
            size = path.stat().st_size / 2**20
            for mode in ("chunks", "whole"):
                r = _measure(kind, str(path), mode)
                print(
                    f"{kind:9s} {size:6.1f} MB {mode:6s}: {r['samples']:>9d} samples ({n} recorded, the rest NaN in the pauses "
                    f"between copies) in "
                    f"{r['seconds']:.2f} s = {r['samples'] / r['seconds'] / 1e6:.2f} M samples/s, "
                    f"peak memory growth {r['peak_growth_mb']:.0f} MB"
                )


if __name__ == "__main__":
    main()
