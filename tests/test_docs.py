"""Every ```bash and ```python block of README.md and docs/*.md runs, as a reader of a fresh clone runs it.

Each page runs in its own temporary folder laid out like a clone: ``recordings/`` copied, ``benchmarks/``,
``schemas/`` and ``docs/`` linked, ``../shared/data`` reachable, the venv's ``imulog`` and ``python``
first on PATH, and, unless the page makes its own, ``trial.mcap``: recordings/sim's R2G trial converted
(what ``imulog convert recordings/sim/... -o trial.mcap`` makes) and processed by orientation, align,
phases and trajectory, since most pages start from it. ``imulog view ... --web`` gets
``--serve-seconds 1`` and free ports. A page's blocks run in order in one process: python blocks share
one namespace, bash blocks run with ``set -e``. Pages run two at a time (CI has two cores): on two threads
in one pytest process, or one page per worker under pytest-xdist (``.ci/run`` uses ``-n 2``).

A block is skipped only when the line before its fence is ``<!-- no-run: reason -->`` (servers, the
test suite itself, benchmarks of minutes); docs/cli.md lists the conventions.

Run one page by hand: ``python tests/test_docs.py docs/export.md`` (prints each block as it runs).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import procs
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("IMULOG_SHARED_DATA", REPO.parent / "shared" / "data"))
PAGES = ["README.md", *sorted(str(p.relative_to(REPO)) for p in (REPO / "docs").glob("*.md"))]
RUN_LANGS = ("bash", "python")
_FENCE = re.compile(r"^(\s*)```(\S*)\s*$")
_NO_RUN = re.compile(r"^\s*<!--\s*no-run:\s*(.+?)\s*-->\s*$")
PAGE_TIMEOUT_S = 480  # a hung block fails; converters.md alone takes 80-170 s on the 2-core machine, more under load


@dataclass
class Block:
    lang: str
    code: str
    line: int  # 1-based line of the opening fence
    skip: str | None = None


def blocks_of(text: str) -> list[Block]:
    """The fenced code blocks of a Markdown page (every language), with their no-run reason if marked."""
    lines = text.splitlines()
    out: list[Block] = []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, lang = m.group(1), m.group(2).lower()
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith("```"):
            j += 1
        prev = next((lines[k] for k in range(i - 1, -1, -1) if lines[k].strip()), "")
        marker = _NO_RUN.match(prev)
        body = [ln[len(indent) :] if ln.startswith(indent) else ln for ln in lines[i + 1 : j]]
        out.append(Block(lang, "\n".join(body) + "\n", i + 1, marker.group(1) if marker else None))
        i = j + 1
    return out


def runnable(page: str) -> list[Block]:
    return [b for b in blocks_of((REPO / page).read_text()) if b.lang in RUN_LANGS]


RUN_PAGES = [p for p in PAGES if any(not b.skip for b in runnable(p))]


def makes_own_trial(page: str) -> bool:
    """Whether the page's blocks write ``trial.mcap`` themselves (then the workspace has none)."""
    return any(re.search(r"-o\s+trial\.mcap\b|write_trial\(\s*[\"']trial\.mcap", b.code) for b in runnable(page))


def bounded_servers(code: str) -> str:
    """``imulog view ... --web`` stops after a second, on free ports (the servers start, then stop)."""
    out = []
    for line in code.splitlines():
        cmd, hash_, comment = line.partition(" #")
        if re.search(r"\bimulog view\b.*--web\b", cmd):
            cmd = cmd.rstrip() + " --serve-seconds 1 --port 0 --grpc-port 0"
        out.append(cmd + hash_ + comment)
    return "\n".join(out) + "\n"


def make_workspace(root: Path, trial: Path | None) -> Path:
    """A folder laid out like a fresh clone, with ``../shared/data`` beside it."""
    clone = root / "clone"
    clone.mkdir(parents=True)
    shutil.copytree(REPO / "recordings", clone / "recordings")
    # the package itself comes from the editable install; no pyproject.toml here and only links to the
    # venv's programs, so a stray `pip install -e .` in a block fails instead of touching the real venv
    for name in ("benchmarks", "schemas", "docs", "tests"):
        if (REPO / name).exists():
            (clone / name).symlink_to(REPO / name)
    venv_bin = clone / ".venv" / "bin"  # `.venv/bin/imulog` as after the README's setup; no pip, no site-packages
    venv_bin.mkdir(parents=True)
    for tool in ("python", "python3", "imulog", "rerun", "pytest", "ruff"):
        real = Path(sys.executable).parent / tool
        if real.exists():  # a wrapper, not a link: a linked python would not find the venv's packages
            (venv_bin / tool).write_text(f'#!/bin/sh\nexec "{real}" "$@"\n')
            (venv_bin / tool).chmod(0o755)
    (root / "shared").mkdir()
    (root / "shared" / "data").symlink_to(SHARED)
    if trial is not None:
        shutil.copy(trial, clone / "trial.mcap")
    return clone


def page_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "PYTHONPATH")}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (what the page costs on a quiet machine)."""
    import resource

    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def run_page(page: str, workdir: Path, verbose: bool = False) -> list[str]:
    """Run a page's blocks in ``workdir`` (in this process); return one message per failing block."""
    os.chdir(workdir)
    namespace: dict[str, object] = {"__name__": "__main__"}
    failures: list[str] = []
    for block in runnable(page):
        where = f"{page}:{block.line} ({block.lang})"
        if block.skip:
            if verbose:
                print(f"--- {where}: skipped: {block.skip}", flush=True)
            continue
        t0 = time.perf_counter()
        cpu0 = _cpu_s()
        if block.lang == "python":
            try:
                exec(compile(block.code, where, "exec"), namespace)  # noqa: S102 - the docs' own code
                error = None
            except BaseException:  # noqa: BLE001 - report any failure of the block
                error = traceback.format_exc(limit=3).strip().splitlines()[-1]
        else:
            proc = procs.run(  # the block's background jobs (`imulog replay ... &`) end with it
                ["bash", "-e", "-o", "pipefail", "-c", bounded_servers(block.code)],
                cwd=workdir,
                capture_output=True,
                text=True,
                timeout=PAGE_TIMEOUT_S,
            )
            error = None
            if proc.returncode != 0:
                tail = (proc.stderr.strip() or proc.stdout.strip()).splitlines()[-3:]
                error = f"exit {proc.returncode}: " + " | ".join(tail)
        if verbose:
            wall, cpu = time.perf_counter() - t0, _cpu_s() - cpu0
            print(f"--- {where}: {'ok' if error is None else 'FAILED'} ({wall:.1f} s, cpu {cpu:.1f} s)", flush=True)
        if error is not None:
            failures.append(f"{where}: {error}")
    return failures


def make_docs_trial(out: Path) -> Path:
    """recordings/sim's trial converted and processed (orientation, align, phases, trajectory)."""
    from imulog.steps.align import run_align
    from imulog.steps.orientation import run_orientation
    from imulog.steps.phases import run_phases
    from imulog.steps.trajectory import run_trajectory

    sim = REPO / "recordings" / "sim"
    imulog = str(Path(sys.executable).parent / "imulog")
    inputs = [str(sim / "r2g_s00_t00_imu.csv"), str(sim / "r2g_s00_t00_vicon.csv")]
    meta = ["--meta-file", str(sim / "r2g_s00_t00_meta.json")]
    subprocess.run([imulog, "convert", *inputs, *meta, "-o", str(out)], check=True, capture_output=True, env=page_env())
    run_orientation(out)
    run_align(out)
    run_phases(out)
    run_trajectory(out)
    return out


@pytest.fixture(scope="session")
def page_runs(tmp_path_factory):
    """page -> its finished process. In one pytest process every page starts at once on two threads (CI has two
    cores); on a pytest-xdist worker (``.ci/run``: the workers already fill the cores) a page runs when its test
    asks for it, so each page test is scheduled like any other test and no worker starts every page."""
    from concurrent.futures import ThreadPoolExecutor

    trial = make_docs_trial(tmp_path_factory.mktemp("docs_trial") / "trial.mcap")

    def run(page: str) -> subprocess.CompletedProcess:
        root = tmp_path_factory.mktemp("docs_" + re.sub(r"\W", "_", page))
        workdir = make_workspace(root, None if makes_own_trial(page) else trial)
        cmd = [sys.executable, __file__, page, "--workdir", str(workdir)]
        return procs.run(cmd, capture_output=True, text=True, env=page_env(), timeout=PAGE_TIMEOUT_S, cwd=workdir)

    if os.environ.get("PYTEST_XDIST_WORKER"):
        yield run
        return
    pool = ThreadPoolExecutor(max_workers=2)
    futures = {page: pool.submit(run, page) for page in RUN_PAGES}
    yield lambda page: futures[page].result()
    pool.shutdown(wait=True, cancel_futures=True)


def test_blocks_are_found_and_markers_have_reasons():
    text = "x\n<!-- no-run: starts a server -->\n```bash\nimulog view t.mcap --web\n```\n```python\nprint(1)\n```\n"
    blocks = blocks_of(text)
    assert [(b.lang, b.skip, b.line) for b in blocks] == [("bash", "starts a server", 3), ("python", None, 6)]
    assert sum(len(runnable(p)) for p in PAGES) > 20


def test_docs_have_no_paths_of_a_development_machine():
    bad = re.compile(r"(/work/|/home/|/root/|/tmp/|/opt/|/usr/local/|\S+/\.venv/bin|/venv/bin)")
    found = []
    for page in PAGES:
        for n, line in enumerate((REPO / page).read_text().splitlines(), 1):
            if bad.search(line):
                found.append(f"{page}:{n}: {line.strip()[:100]}")
    assert not found, "machine paths in the docs:\n" + "\n".join(found)


@pytest.mark.parametrize("page", RUN_PAGES)
def test_page_blocks_run(page, page_runs):
    proc = page_runs(page)
    failures = [ln[len("FAIL ") :] for ln in proc.stdout.splitlines() if ln.startswith("FAIL ")]
    assert proc.returncode == 0 and not failures, "\n".join(failures) or proc.stderr[-2000:]


def main(argv: list[str]) -> int:
    import argparse

    ap = argparse.ArgumentParser(description="run the code blocks of one docs page")
    ap.add_argument("page")
    ap.add_argument("--workdir", type=Path, default=None, help="run there (default: a fresh temporary clone)")
    args = ap.parse_args(argv)
    env = page_env()
    os.environ.clear()
    os.environ.update(env)
    page = str(Path(args.page).resolve().relative_to(REPO)) if Path(args.page).is_absolute() else args.page
    if args.workdir is None:
        import tempfile

        root = Path(tempfile.mkdtemp(prefix="imulog-docs-"))
        trial = make_docs_trial(root / "trial.mcap")
        args.workdir = make_workspace(root / "ws", None if makes_own_trial(page) else trial)
        print(f"working folder: {args.workdir}")
    failures = run_page(page, args.workdir, verbose=True)
    for f in failures:
        print(f"FAIL {f}", flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
