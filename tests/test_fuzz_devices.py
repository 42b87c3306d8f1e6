"""Every registered converter on a fuzz corpus made from the real samples (issue 26): truncations, bit flips and
huge declared numbers in headers, plus foreign inputs forced on each converter. Each input must convert or fail
with one ConversionError line naming the file and no Python exception type, within the issue's bound
(max(30 s, N / 10 MB/s), 512 MB), measured per input in one child process as tests/test_hostile_devices.py does.

Readers without a shared sample get one from tests/data and a built one (the older Genea .bin: GGIRread's
genea_testfile.bin, tests/genea_build.py).

The corpus is a bounded, seeded sample (a fixed number of mutations per real file, files up to 2 MB), so the test
takes about a minute; ``IMULOG_FUZZ_PER_FILE`` raises the count for a longer local run.
"""

from __future__ import annotations

import json
import lzma
import os
import re
import subprocess
import sys
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest
from genea_build import build_genea
from imulog.converters import ConversionError, available, detect

RSS_CAP_MB = 512
TIME_CAP_S = 30.0
MAX_FILE_BYTES = 2 << 20
PER_FILE = int(os.environ.get("IMULOG_FUZZ_PER_FILE", 6))
REPO = Path(__file__).resolve().parents[1]
SKIP = {".md", ".tsv", ".npz", ".json", ".txt.license", ".pdf", ".png"}
EXCEPTION_NAME = re.compile(r"\b(?!ConversionError)[A-Z][A-Za-z]*(Error|Exception)\b|OverflowError|Traceback")

CHILD = r"""
import json, resource, sys, time, traceback
resource.setrlimit(resource.RLIMIT_AS, (6 << 30, 6 << 30))
from imulog.converters import ConversionError, convert_file

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(key)) / 1024

out = []
for path, fmt in json.loads(sys.argv[1]):
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    t = time.perf_counter()
    result = {"path": path, "fmt": fmt}
    try:
        rec = convert_file(path, fmt)
        result["ok"] = sum(len(s) for s in rec.streams() if hasattr(s, "t_ns"))
    except ConversionError as e:
        result["error"] = str(e)
    except BaseException as e:  # noqa: BLE001 - what the test is looking for
        result["exception"] = "".join(traceback.format_exception(e))[-1500:]
    result["s"] = time.perf_counter() - t
    result["rss_mb"] = status("VmHWM")
    out.append(result)
print(json.dumps(out))
"""


def _samples(shared_data: Path) -> list[Path]:
    files = []
    for p in sorted(shared_data.rglob("*")):
        if not p.is_file() or p.stat().st_size > MAX_FILE_BYTES or p.stat().st_size == 0:
            continue
        if p.suffix.lower() in SKIP or p.name.startswith(("LICENSE", "NOTICE", "README", ".")):
            continue
        files.append(p)
    return files


def _text(data: bytes) -> bool:
    return b"\x00" not in data[:4096]


def _huge_number(data: bytes, rng: np.random.Generator, value: bytes) -> bytes:
    """A number in the first 12 lines replaced by ``value`` (a declared count, rate or time gone huge)."""
    head_end = 0
    for _ in range(12):
        nl = data.find(b"\n", head_end)
        if nl < 0:
            break
        head_end = nl + 1
    numbers = [m.span() for m in re.finditer(rb"\d+(\.\d+)?", data[: head_end or len(data)])]
    if not numbers:
        return data + value
    a, b = numbers[int(rng.integers(len(numbers)))]
    return data[:a] + value + data[b:]


def _mutations(data: bytes, rng: np.random.Generator) -> list[tuple[str, bytes]]:
    n = len(data)
    out = []
    for frac in (0.05, 0.5, 0.93):
        out.append((f"cut{int(frac * 100)}", data[: max(1, int(frac * n))]))
    for k in range(2):
        b = bytearray(data)
        pos = int(rng.integers(min(n, 512))) if k == 0 else int(rng.integers(n))
        b[pos] ^= 1 << int(rng.integers(8))
        out.append((f"flip{k}", bytes(b)))
    if _text(data):
        out.append(("huge", _huge_number(data, rng, b"99999999999999999999")))
        out.append(("e308", _huge_number(data, rng, b"1e308")))
    else:
        for k in range(2):  # a 32-bit word in the header set to its largest value: a length or count gone huge
            b = bytearray(data)
            pos = int(rng.integers(max(1, min(n - 4, 1024))))
            b[pos : pos + 4] = b"\xff\xff\xff\x7f" if k else b"\xff\xff\xff\xff"
            out.append((f"word{k}", bytes(b)))
    return out


def _zip_members(path: Path, rng: np.random.Generator) -> list[tuple[str, bytes]]:
    """For a ZIP container (.gt3x): the members mutated inside an intact ZIP (else only the ZIP CRC is tested)."""
    import io

    with zipfile.ZipFile(path) as z:
        members = {i.filename: z.read(i.filename) for i in z.infolist()}
    out = []
    for name, content in members.items():
        for label, bad in _mutations(content, rng):
            buf = io.BytesIO()
            with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
                for other, c in members.items():
                    z.writestr(other, bad if other == name else c)
            out.append((f"{Path(name).stem}-{label}", buf.getvalue()))
    return out


@pytest.fixture(scope="module")
def corpus(shared_data: Path, tmp_path_factory) -> list[tuple[Path, str]]:
    d = tmp_path_factory.mktemp("fuzz_devices")
    jobs: list[tuple[Path, str]] = []
    built = d / "built"
    built.mkdir()
    real_genea = built / "genea_testfile.bin"  # GGIRread's real file (tests/data): no shared sample of the format
    real_genea.write_bytes(lzma.decompress((REPO / "tests" / "data" / "genea_testfile.bin.xz").read_bytes()))
    sources = _samples(shared_data) + [real_genea, build_genea(built / "genea_built.bin", seconds=30).path]
    for src in sources:
        try:
            fmt = detect(src).name
        except ConversionError:
            continue
        rng = np.random.default_rng(zlib.crc32(src.name.encode()))
        data = src.read_bytes()
        muts = _zip_members(src, rng) if zipfile.is_zipfile(src) and src.suffix == ".gt3x" else _mutations(data, rng)
        chosen = [muts[int(i)] for i in sorted(rng.choice(len(muts), size=min(PER_FILE, len(muts)), replace=False))]
        for label, bad in chosen:
            out = d / f"{src.stem}.{label}{src.suffix}"
            out.write_bytes(bad)
            jobs.append((out, fmt))
    # every registered converter forced on inputs that are not its format
    junk = d / "junk.bin"
    junk.write_bytes(np.random.default_rng(1).bytes(3000))
    csv = d / "numbers.csv"
    csv.write_text("a,b,c\n" + "1e308,inf,-inf\n" * 5 + "nan,1,2\n")
    for name in available():
        jobs += [(junk, name), (csv, name)]
    return jobs


def test_every_converter_on_the_fuzz_corpus_fails_cleanly_and_bounded(corpus):
    payload = json.dumps([[str(p), f] for p, f in corpus])
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, payload],
        capture_output=True,
        text=True,
        timeout=120 + 5 * len(corpus),
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Warning" not in proc.stderr, proc.stderr[-3000:]  # numpy's RuntimeWarning lines are not for users
    results = json.loads(proc.stdout.strip().splitlines()[-1])
    assert len(results) == len(corpus) > 200
    problems = []
    for r in results:
        size = Path(r["path"]).stat().st_size
        where = f"{Path(r['path']).name} as {r['fmt']}"
        if "exception" in r:
            problems.append(f"{where}: {r['exception']}")
            continue
        if r["s"] > max(TIME_CAP_S, size / 10e6) or r["rss_mb"] > RSS_CAP_MB:
            problems.append(f"{where}: {r['s']:.1f} s, {r['rss_mb']:.0f} MB")
        msg = r.get("error")
        if msg is not None and ("\n" in msg or len(msg) > 1000 or EXCEPTION_NAME.search(msg)):
            problems.append(f"{where}: {msg!r}")
    assert not problems, "\n".join(problems[:20])
    failed = sum("error" in r for r in results)
    assert 0 < failed < len(results)  # the corpus holds both readable damage and refused damage
