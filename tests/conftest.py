"""Shared test fixtures (the real recordings in ../shared/data, temporary trial folders) and the pytest-xdist
scheduler of ``.ci/run``."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest
from procs import kill_started  # noqa: F401  (autouse: the processes a test started die with it, tests/procs.py)

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("IMULOG_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Folder of real public recordings (see ../shared/data/README.md); CI has it beside the clone."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"real recordings not found at {SHARED_DATA}; set IMULOG_SHARED_DATA")
    return SHARED_DATA


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO_ROOT


@pytest.fixture(scope="session")
def processed_r2g(tmp_path_factory) -> Path:
    """recordings/sim's R2G trial converted and processed (orientation, align, phases); do not modify it.

    Tests that change a trial copy it first (``shutil.copy``).
    """
    from click.testing import CliRunner

    from imulog.cli import cli
    from imulog.steps.align import run_align
    from imulog.steps.orientation import run_orientation
    from imulog.steps.phases import run_phases

    sim = REPO_ROOT / "recordings" / "sim"
    out = tmp_path_factory.mktemp("processed_r2g") / "r2g.mcap"
    args = [
        "convert",
        str(sim / "r2g_s00_t00_imu.csv"),
        str(sim / "r2g_s00_t00_vicon.csv"),
        "--meta-file",
        str(sim / "r2g_s00_t00_meta.json"),
        "-o",
        str(out),
    ]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    run_orientation(out)
    run_align(out)
    run_phases(out)
    return out


#: test files whose tests are independent and long (each docs page runs in its own folder, ~10-170 s): under
#: pytest-xdist they are scheduled test by test; every other file goes to one worker whole (its module fixtures
#: are built once, its tests run in file order, as in one process)
PER_TEST_FILES = frozenset({"tests/test_docs.py"})

if importlib.util.find_spec("xdist") is not None:  # the hook exists only with pytest-xdist (the dev extra)

    def pytest_xdist_make_scheduler(config, log):
        """``--dist loadfile`` (``.ci/run``): whole files to the workers, except :data:`PER_TEST_FILES`. (Marks
        for ``--dist loadgroup`` cannot say this: with pytest 9.2 it ignores them, pytest-xdist issue 1386.)"""
        if config.getvalue("dist") != "loadfile":
            return None
        from xdist.scheduler import LoadScopeScheduling

        class FilesAndPages(LoadScopeScheduling):
            """Scopes go out one at a time as a worker runs low; the single tests of :data:`PER_TEST_FILES` (the
            longest units) first, so that no worker is left with one at the end while the other idles."""

            def _split_scope(self, nodeid: str) -> str:
                path = nodeid.split("::", 1)[0]
                return nodeid if path in PER_TEST_FILES else path

            def _assign_work_unit(self, node) -> None:
                if not getattr(self, "_ordered", False):
                    first = [s for s in self.workqueue if "::" in s]
                    for scope in reversed(first):
                        self.workqueue.move_to_end(scope, last=False)
                    self._ordered = True
                super()._assign_work_unit(node)

        return FilesAndPages(config, log)
