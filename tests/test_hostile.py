"""Hostile and damaged input: every read command stays bounded (512 MB, 30 s), never prints a traceback, and
never computes from, exports or launders damaged data (issue 18).

Commands run in one child process (``imulog.cli`` through click's runner, so Python starts once) whose peak
RSS is measured with ``resource.getrusage``; an address-space limit keeps a runaway bomb from hurting the
machine. Crafted files are built with imulog's own record layer, so each holds exactly one hostile feature.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from imulog.converters import ConversionError, get

from imulog.archive import ArchiveError, TrialReader, append_derived
from imulog.archive import _mcap as m
from imulog.archive._builder import McapBuilder
from imulog.archive.doctor import check_file
from imulog.archive.metadata import encode_record
from imulog.archive.writer import write_stream
from imulog.cli import cli
from imulog.model import ImuStream, SignalStream

RSS_CAP_MB = 512
TIME_CAP_S = 30.0
REPO = Path(__file__).resolve().parents[1]
SIM = REPO / "recordings" / "sim" / "r2g_s00_t00"

CHILD = r"""
import json, resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, (8 << 30, 8 << 30))  # a runaway bomb fails here, not on the machine
from click.testing import CliRunner
from imulog.cli import cli
runner, out = CliRunner(), []
for args in json.loads(sys.argv[1]):
    t = time.perf_counter()
    res = runner.invoke(cli, args)
    exc = res.exception if res.exception is not None and not isinstance(res.exception, SystemExit) else None
    out.append({"args": args, "code": res.exit_code, "s": time.perf_counter() - t, "output": res.output[-2000:],
                "exception": None if exc is None else f"{type(exc).__name__}: {exc}"[:300]})
def peak_rss_mb():
    # VmHWM: the peak of this process's own memory since exec; ru_maxrss would also count the parent's RSS at
    # fork (a test process grown to 1 GB over a whole suite made every child look 1 GB big)
    try:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")) / 1024
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
out.append({"rss_mb": peak_rss_mb()})
print(json.dumps(out))
"""


def run_commands(jobs: list[list[str]], cwd: Path) -> tuple[list[dict], float]:
    """Run imulog commands in one child process; return (one result per job, peak RSS in MB)."""
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, json.dumps(jobs)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=TIME_CAP_S * max(2, len(jobs)),
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    *results, rss = json.loads(proc.stdout.strip().splitlines()[-1])
    return results, rss["rss_mb"]


def assert_clean(result: dict) -> None:
    """No traceback, a one-line error when it fails, within the time cap."""
    what = " ".join(result["args"])
    assert result["exception"] is None, f"{what}: {result['exception']}"
    assert "Traceback" not in result["output"], f"{what}: {result['output'][-500:]}"
    assert result["s"] < TIME_CAP_S, f"{what}: {result['s']:.1f} s"
    if result["code"] != 0:
        errors = [line for line in result["output"].splitlines() if line.startswith("Error:")]
        assert len(errors) == 1 and len(errors[0]) < 1000, f"{what}: {result['output'][-500:]}"


# ---------------------------------------------------------------------------------------------- a real trial


@pytest.fixture(scope="module")
def trial(tmp_path_factory) -> Path:
    """The simulated drinking-task trial of recordings/ converted (3 attachments) with orientation appended."""
    tmp = tmp_path_factory.mktemp("hostile")
    path = tmp / "trial.mcap"
    runner = CliRunner()
    res = runner.invoke(
        cli,
        ["convert", f"{SIM}_imu.csv", f"{SIM}_vicon.csv", "--meta-file", f"{SIM}_meta.json", "-o", str(path)],
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["process", "orientation", str(path), "--backend", "madgwick"])
    assert res.exit_code == 0, res.output
    assert check_file(path).ok
    return path


def _imu_chunk(path: Path) -> m.ChunkIndexRec:
    with TrialReader(path) as tr:
        cid = next(c.id for c in tr.summary.channels.values() if c.topic == "/imu/wrist")
        return next(ci for ci in tr.summary.chunk_indexes if cid in ci.message_index_offsets)


def _chunk_data_range(path: Path, ci: m.ChunkIndexRec) -> tuple[int, int]:
    """Byte range of the compressed data inside the chunk record."""
    head = 9 + 8 * 3 + 4 + 4 + len(ci.compression) + 8
    return ci.chunk_start_offset + head, ci.chunk_start_offset + ci.chunk_length


def test_flipped_bytes_in_the_imu_chunk_are_refused_by_every_read_command(trial, tmp_path):
    """Before issue 18, 36 of 80 such exports exited 0 with wrong values, and orientation computed from them."""
    data = trial.read_bytes()
    lo, hi = _chunk_data_range(trial, _imu_chunk(trial))
    offsets = np.linspace(lo, hi - 1, 24).astype(int)
    jobs = []
    for k, off in enumerate(offsets):
        bad = bytearray(data)
        bad[off] ^= 1 << (k % 8)
        name = f"flip{k}.mcap"
        (tmp_path / name).write_bytes(bad)
        jobs += [
            ["export", name, "--topic", "/imu/wrist", "-o", f"out{k}.parquet"],
            ["process", "orientation", name, "--backend", "madgwick", "--force"],
        ]
        if k % 3 == 0:
            jobs.append(["view", name, "--save", f"view{k}.rrd"])
    results, rss = run_commands(jobs, tmp_path)
    for r in results:
        assert_clean(r)
        assert r["code"] != 0, f"{' '.join(r['args'])} exited 0 on a damaged IMU chunk"
        assert "/imu/wrist" in r["output"] and "damaged" in r["output"] and " s into the file" in r["output"]
    assert not list(tmp_path.glob("out*.parquet")) and not list(tmp_path.glob("view*.rrd"))
    assert rss < RSS_CAP_MB


def _regions(data: bytes) -> list[tuple[str, int]]:
    """(name, offset) of a byte in the middle of every record of the file, plus its magic bytes."""
    s = m.read_summary_from_bytes(data)
    out = [("magic", 3)]
    pos = len(m.MAGIC)
    while pos < len(data) - len(m.MAGIC):
        op, length = m._REC.unpack_from(data, pos)
        section = "summary" if pos >= s.summary_start else "data"
        out.append((f"{section} {m.OP_NAMES.get(op, hex(op))} at {pos}", pos + 9 + length // 2 if length else pos))
        pos += 9 + length
    out.append(("closing magic", len(data) - 3))
    return out


Q = "/derived/orientation/wrist"


def PROCESS(name: str) -> list[str]:  # noqa: N802 - reads like a job constant
    return ["process", "orientation", name, "--backend", "madgwick", "--beta", "0.05"]


def test_flipped_bytes_in_every_region_never_give_wrong_results(trial, tmp_path):
    """Every command either refuses (one line, non-zero) or gives exactly what the intact file gives."""
    data = trial.read_bytes()
    regions = _regions(data)
    assert len(regions) > 30
    jobs = [["export", "intact.mcap", "--topic", "/imu/wrist", "-o", "intact.csv"]]
    shutil.copy(trial, tmp_path / "intact.mcap")
    for k, (_, off) in enumerate(regions):
        bad = bytearray(data)
        bad[off] ^= 0x20
        (tmp_path / f"r{k}.mcap").write_bytes(bad)
        jobs += [["doctor", f"r{k}.mcap"], ["export", f"r{k}.mcap", "--topic", "/imu/wrist", "-o", f"r{k}.csv"]]
        if k % 2:
            jobs.append(["info", f"r{k}.mcap"])
        else:
            jobs.append(["export", f"r{k}.mcap", "--topic", "/derived/orientation/wrist", "-o", f"q{k}.csv"])
        if k % 6 == 0:
            jobs.append(["view", f"r{k}.mcap", "--save", f"r{k}.rrd"])
        if k % 4 == 1:  # recompute orientation with other parameters (the replace path), then read it back
            shutil.copy(tmp_path / f"r{k}.mcap", tmp_path / f"p{k}.mcap")
            jobs += [PROCESS(f"p{k}.mcap"), ["export", f"p{k}.mcap", "--topic", Q, "-o", f"p{k}.csv"]]
    shutil.copy(trial, tmp_path / "p_intact.mcap")
    jobs += [["export", "intact.mcap", "--topic", Q, "-o", "intact_q.csv"], PROCESS("p_intact.mcap")]
    jobs.append(["export", "p_intact.mcap", "--topic", Q, "-o", "p_intact.csv"])
    results, rss = run_commands(jobs, tmp_path)
    *results, _, intact_p, _ = results
    assert intact_p["code"] == 0, intact_p["output"]
    want = {n: (tmp_path / f"{n}.csv").read_bytes() for n in ("intact", "intact_q", "p_intact")}
    processed = set()
    for r in results[1:]:
        assert_clean(r)
        cmd, name = r["args"][0], r["args"][1] if r["args"][0] != "process" else r["args"][2]
        where = regions[int(name[1:].split(".")[0])][0]
        if cmd == "doctor":
            assert r["code"] != 0, f"doctor accepted a flip in the {where}"
        elif cmd == "process" and r["code"] == 0:
            processed.add(name)
        elif cmd == "export" and r["code"] == 0 and (not name.startswith("p") or name in processed):
            out = tmp_path / r["args"][-1]
            key = {"r": "intact", "q": "intact_q", "p": "p_intact"}[out.name[0]]
            assert out.read_bytes() == want[key], f"{' '.join(r['args'])}: a flip in the {where} gave other values"
    assert rss < RSS_CAP_MB


def test_replacing_a_step_never_launders_a_damaged_file(trial, tmp_path):
    """The replace path copied damaged bytes under a fresh CRC: 6 of 79 such files then passed doctor."""
    data = trial.read_bytes()
    s = m.read_summary_from_bytes(data)
    rng = np.random.default_rng(3)
    positions = sorted({int(p) for p in rng.integers(len(m.MAGIC), s.data_end_offset, 20)})
    positions += [p for _, p in _regions(data) if p < s.data_end_offset]
    with TrialReader(trial) as tr:
        t = tr.read("/derived/orientation_static/wrist").t_ns
    laundered = []
    for pos in positions:
        bad = tmp_path / "bad.mcap"
        corrupted = bytearray(data)
        corrupted[pos] ^= 0x04
        bad.write_bytes(corrupted)
        if check_file(bad).ok:
            continue
        stream = SignalStream("/derived/orientation_static/wrist", t, ["static"], ["1"], np.zeros(len(t)))
        try:
            append_derived(bad, [stream], run={"step": "orientation:wrist", "params": {"other": 1}})
        except ArchiveError:
            assert bad.read_bytes() == bytes(corrupted)  # refused: nothing written
            continue
        if check_file(bad).ok:
            laundered.append(pos)
    assert not laundered, f"flips at {laundered[:10]} came out passing doctor after a replace"


# ---------------------------------------------------------------------------------------------- crafted files


def _imu(n: int = 3000) -> ImuStream:
    t = np.arange(n, dtype=np.int64) * 10_000_000
    rng = np.random.default_rng(0)
    return ImuStream("wrist", t, acc=rng.normal(0, 1, (n, 3)) + [0, 0, 9.81], gyr=rng.normal(0, 0.1, (n, 3)))


def craft(
    path: Path,
    *,
    chunk: tuple[str, int, bytes] | None = None,
    duplicate_index: int = 0,
    duplicate_metadata: int = 0,
    records: dict[str, dict[str, str]] | None = None,
    channel_meta: dict[str, str] | None = None,
) -> Path:
    """A trial with one IMU channel and one hostile feature: an extra chunk (compression, declared size, data),
    the first chunk indexed ``duplicate_index`` more times, raw metadata records, or extra channel metadata."""
    with open(path, "wb") as f:
        b = McapBuilder.new(f, "hostile test", "")
        write_stream(b, _imu(), channel_meta)
        cid = max(b.channels)
        if chunk is not None:
            compression, declared, payload = chunk
            start = 40 * 10**9
            offset = b.offset
            rec = m.chunk(start, start, declared, 0, compression, payload)
            b.write(rec)
            b.chunk_indexes.append(
                m.ChunkIndexRec(start, start, offset, len(rec), {cid: offset}, 0, compression, len(payload), declared)
            )
        b.chunk_indexes += [b.chunk_indexes[0]] * duplicate_index
        b.add_metadata("imulog.trial", encode_record({"subject": "S01", "task": "r2g", "repetitions": 2}))
        for name, items in (records or {}).items():
            b.add_metadata(name, items)
        b.metadata_indexes += [b.metadata_indexes[-1]] * duplicate_metadata
        b.finish()
    return path


def _zstd_zeros(total: int) -> bytes:
    import zstandard

    obj = zstandard.ZstdCompressor(level=1).compressobj(size=total)
    block = bytes(16 << 20)
    parts = [obj.compress(block) for _ in range(total // len(block))]
    return b"".join([*parts, obj.flush()])


DEEP = "[" * 50_000 + "]" * 50_000


@pytest.fixture(scope="module")
def crafted(tmp_path_factory) -> dict[str, Path]:
    import lz4.frame

    tmp = tmp_path_factory.mktemp("crafted")
    zeros_256m = lz4.frame.compress(bytes(256 << 20))
    files = {
        "zstd bomb, 1 GiB declared": craft(tmp / "zbomb.mcap", chunk=("zstd", 1 << 30, _zstd_zeros(1 << 30))),
        "zstd ratio bomb, 200 MiB": craft(tmp / "zratio.mcap", chunk=("zstd", 200 << 20, _zstd_zeros(192 << 20))),
        "lz4 chunk declaring 1 KiB, holding 256 MiB": craft(tmp / "lz4lie.mcap", chunk=("lz4", 1024, zeros_256m)),
        "uncompressed chunk declaring 1 TiB": craft(tmp / "huge.mcap", chunk=("", 1 << 40, b"\0" * 64)),
        "100,000 index entries for one chunk": craft(tmp / "dup.mcap", duplicate_index=100_000),
        "100,000 index entries for one 1 MB metadata record": craft(
            tmp / "dupmeta.mcap", records={"imulog.notes": {"text": "x" * 1_000_000}}, duplicate_metadata=100_000
        ),
        "deep JSON in a metadata record": craft(
            tmp / "deepmeta.mcap", records={"imulog.anthropometrics": {"_json": '["arm"]', "arm": DEEP}}
        ),
        "deep JSON in a run record": craft(
            tmp / "deeprun.mcap", records={"imulog.run.1": {"_json": '["params"]', "step": "x", "params": DEEP}}
        ),
        "deep JSON in channel metadata": craft(tmp / "deepchan.mcap", channel_meta={"meta": DEEP}),
        "run outputs a number": craft(
            tmp / "runtype.mcap", records={"imulog.run.1": {"_json": '["outputs"]', "step": "x", "outputs": "5"}}
        ),
        "alignment offset a word": craft(
            tmp / "aligntype.mcap", records={"imulog.alignment": {"offset_ns": "soon", "drift_ppm": "0"}}
        ),
    }
    assert (tmp / "zbomb.mcap").stat().st_size < 200_000 and (tmp / "dup.mcap").stat().st_size < 12_000_000
    return files


def test_crafted_files_stay_bounded_and_give_one_line_errors(crafted, tmp_path):
    jobs = []
    for kind, path in crafted.items():
        jobs += [["info", str(path)], ["doctor", str(path)]]
        jobs.append(["export", str(path), "--topic", "/imu/wrist", "-o", str(tmp_path / f"{path.stem}.parquet")])
        if kind.startswith(("zstd", "lz4", "uncompressed", "100,000", "deep JSON in channel")):
            shutil.copy(path, tmp_path / path.name)  # process writes on success: keep the fixture as crafted
            jobs.append(["process", "orientation", path.name, "--backend", "madgwick"])
        if kind.startswith(("zstd bomb", "lz4", "deep JSON in channel")):
            jobs.append(["view", str(path), "--save", str(tmp_path / f"{path.stem}.rrd")])
        if kind.startswith(("deep JSON in a run", "run outputs")):
            jobs.append(["info", "--json", str(path)])
        jobs.append(["salvage", str(path), "-o", str(tmp_path / f"salvaged_{path.name}")])
    jobs.append(["catalog", str(next(iter(crafted.values())).parent), "-o", str(tmp_path / "catalog.parquet"), "-q"])
    results, rss = run_commands(jobs, tmp_path)
    by_file = {str(p): k for k, p in crafted.items()}
    crafted_dir = next(iter(crafted.values())).parent
    *results, catalog = results
    assert_clean(catalog)  # one bad trial must not stop (or crash) the catalog of the others
    for r in results:
        assert_clean(r)
        kind = by_file[next(str(crafted_dir / Path(a).name) for a in r["args"] if a.endswith(".mcap"))]
        if r["args"][0] == "doctor":
            assert r["code"] != 0, f"doctor accepted: {kind}"
        if kind.startswith(("zstd", "lz4", "uncompressed")) and r["args"][0] in ("export", "process", "view"):
            assert r["code"] != 0, f"{r['args'][0]} read the hostile chunk of: {kind}"
        deep_or_typed = ("deep JSON in a metadata", "deep JSON in a run", "run outputs", "alignment")
        if kind.startswith(deep_or_typed) and r["args"][0] == "info":
            assert r["code"] != 0 and ("nested deeper" in r["output"] or "must be" in r["output"]), r["output"]
    assert rss < RSS_CAP_MB, f"peak RSS {rss:.0f} MB"


def test_each_chunk_is_read_once_however_often_it_is_indexed(crafted):
    path = crafted["100,000 index entries for one chunk"]
    with TrialReader(path) as tr:
        assert tr.summary.duplicate_chunk_indexes == 100_000
        assert len(tr.read("/imu/wrist")) == len(_imu())
    assert any("more than once" in p for p in check_file(path).problems)


def test_bounded_decompression_still_reads_honest_lz4_and_zstd_files(tmp_path):
    """Another writer's lz4 and zstd chunks (several channels per chunk) decode through the bounded paths."""
    from mcap.writer import CompressionType, Writer

    for compression in (CompressionType.LZ4, CompressionType.ZSTD):
        path = tmp_path / f"{compression.name}.mcap"
        with open(path, "wb") as f:
            w = Writer(f, chunk_size=4096, compression=compression)
            w.start()
            sid = w.register_schema("S", "jsonschema", b"{}")
            ch = w.register_channel("/a", "json", sid)
            for k in range(500):
                w.add_message(ch, log_time=k, data=b'{"k": %d}' % k, publish_time=k)
            w.finish()
        with TrialReader(path) as tr:
            assert [bytes(p) for p in tr.messages("/a")] == [b'{"k": %d}' % k for k in range(500)]


def test_wrong_crc_after_honest_decompression_is_refused(tmp_path):
    """The uncompressed CRC is checked on every read, not only by doctor."""
    path = craft(tmp_path / "t.mcap")
    data = bytearray(path.read_bytes())
    ci = _imu_chunk(path)
    crc_at = ci.chunk_start_offset + 9 + 24
    data[crc_at] ^= 1  # the stored CRC itself (the data are intact)
    path.write_bytes(bytes(data))
    with TrialReader(path) as tr, pytest.raises(ArchiveError, match=r"/imu/wrist: chunk at byte \d+ .*CRC mismatch"):
        tr.read("/imu/wrist")
    with TrialReader(path) as tr, pytest.raises(ArchiveError, match="CRC mismatch"):
        list(tr.iter_blocks("/imu/wrist"))


# ---------------------------------------------------------------------------------------------- converters

DATA = Path(os.environ.get("IMULOG_SHARED_DATA", REPO.parent / "shared" / "data"))  # as tests/conftest.py
# converter name -> (real sample, how many leading bytes to mutate: text samples are cut to keep parses short)
REAL_SAMPLES = {
    "broad-hdf5": ("broad/02_undisturbed_slow_rotation_B.hdf5", None),
    "c3d": ("c3d/ktk_sample_propulsion_upperlimb.c3d", None),
    "delimited": ("imu_text/fusion_sensor_data.csv", 6000),
    "vicon-csv": ("vicon_nexus/analogs.csv", 20000),
    "gaitmap": ("gaitmap_foot/imu_sample.csv", 6000),
    "xsens": ("devices/xsens_mtmanager/MT2022_ACC_GYRO_ROT_ALL_TAB_NAN_00B42D4B.txt", None),
    "geneactiv": ("devices/geneactiv_bin/GENEActiv_testfile.bin", None),
    "edf": ("devices/edf/trigno_emg.edf", None),
    "nilspod": ("devices/nilspod/NilsPodX-6F13_20210109_162824.bin", None),
    "opensim-trc": ("devices/opensim_trc/markers.trc", 20000),
    "opensim-sto": ("devices/opensim_mot/inverse_kin.mot", 6000),
    "axivity": ("devices/axivity_cwa/ax6_sample.cwa", None),
}  # converter engineers: add one real sample per new converter here


def _cut_text(data: bytes, keep: int | None) -> bytes:
    if keep is None or len(data) <= keep:
        return data
    return data[: data.rfind(b"\n", 0, keep) + 1]


mutation = st.lists(
    st.tuples(st.sampled_from(["flip", "cut", "delete", "huge-cell"]), st.floats(0, 1), st.integers(1, 255)),
    min_size=1,
    max_size=4,
)


def _mutate(data: bytes, ops: list[tuple[str, float, int]]) -> bytes:
    b = bytearray(data)
    for op, where, arg in ops:
        i = min(int(where * len(b)), len(b) - 1)
        if op == "flip":
            b[i] ^= arg
        elif op == "cut":
            del b[i:]
        elif op == "delete":
            del b[i : i + arg]
        else:  # a megabyte-long number in the middle of a cell: must be quoted as a short excerpt at most
            b[i:i] = b"9" * 1_000_000
        if not b:
            b = bytearray(b"\0")
    return bytes(b)


@pytest.mark.parametrize("name", sorted(REAL_SAMPLES))
def test_converters_raise_only_conversion_error_on_mutated_real_samples(name, tmp_path_factory):
    sample, keep = REAL_SAMPLES[name]
    source = DATA / sample
    if not source.is_file():
        pytest.fail(f"real sample {source} not found")
    seed = _cut_text(source.read_bytes(), keep)
    folder = tmp_path_factory.mktemp(name)
    path = folder / source.name
    converter = get(name)

    @settings(max_examples=12, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
    @given(mutation)
    def check(ops):
        path.write_bytes(_mutate(seed, ops))
        try:
            converter.convert(path)
        except ConversionError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 600, str(exc)[:300]

    check()


def test_a_huge_cell_is_quoted_as_an_excerpt(tmp_path):
    path = tmp_path / "imu.csv"
    head = (DATA / "imu_text/fusion_sensor_data.csv").read_bytes().splitlines()[:5]
    cells = head[3].split(b",")
    cells[2] = b"9" * 1_000_000  # a finite-looking number too large for float: inf
    path.write_bytes(b"\n".join([*head[:3], b",".join(cells), *head[4:]]) + b"\n")
    with pytest.raises(ConversionError) as err:
        get("delimited").convert(path)
    assert len(str(err.value)) < 400 and "line 4" in str(err.value)


def test_damaged_broad_hdf5_gives_conversion_error(tmp_path):
    """h5py raised OSError, RuntimeError or KeyError on 66 % of damaged BROAD files."""
    data = (DATA / REAL_SAMPLES["broad-hdf5"][0]).read_bytes()
    path = tmp_path / "b.hdf5"
    rng = np.random.default_rng(1)
    outcomes = {"ok": 0, "error": 0}
    for k in range(30):
        bad = bytearray(data[: int(rng.integers(2048, len(data)))] if k % 2 else data)
        for p in rng.integers(0, 8192, 6):  # superblock, object headers and b-trees live at the start
            bad[int(p)] ^= 0xFF
        path.write_bytes(bytes(bad))
        try:
            get("broad-hdf5").convert(path)
            outcomes["ok"] += 1
        except ConversionError:
            outcomes["error"] += 1
    assert outcomes["error"] >= 15
