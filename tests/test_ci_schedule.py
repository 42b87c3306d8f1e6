"""The pytest-xdist scheduler of tests/conftest.py (``.ci/run``: ``-n 2 --dist loadfile``): a test file goes to one
worker whole, in file order; the tests of PER_TEST_FILES (the docs pages) go one by one, before any file."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

pytest.importorskip("xdist")

DOCS = "tests/test_docs.py"
COLLECTION = [
    "tests/test_a.py::test_one",
    "tests/test_a.py::test_two",
    "tests/test_a.py::test_three",
    f"{DOCS}::test_blocks_are_found",
    f"{DOCS}::test_page_blocks_run[README.md]",
    f"{DOCS}::test_page_blocks_run[docs/cli.md]",
    "tests/test_b.py::test_one",
    "tests/test_c.py::test_one",
    "tests/test_c.py::test_two",
]


class _Config:
    """What the scheduler reads of pytest's config: ``--dist``, ``--tx`` (``-n 2``), ``--loadscope-reorder``."""

    def __init__(self, dist: str) -> None:
        self.values = {"dist": dist, "tx": ["2*popen"]}
        self.option = SimpleNamespace(loadscopereorder=True)

    def getvalue(self, name: str):
        return self.values[name]


class _Worker:
    """A worker that records the tests it is sent (as pytest-xdist's WorkerController receives them)."""

    def __init__(self, name: str, sent: list[tuple[str, str]]) -> None:
        self.gateway = SimpleNamespace(id=name)
        self.shutting_down = False
        self.sent = sent
        self.pending: list[int] = []

    def send_runtest_some(self, indexes: list[int]) -> None:
        self.pending.extend(indexes)
        self.sent.extend((self.gateway.id, COLLECTION[i]) for i in indexes)

    def shutdown(self) -> None:
        self.shutting_down = True


def _make_scheduler(request, dist: str):
    plugin = next(p for p in request.config.pluginmanager.get_plugins() if hasattr(p, "PER_TEST_FILES"))
    return plugin.pytest_xdist_make_scheduler(config=_Config(dist), log=None)


def _run(sched) -> list[tuple[str, str]]:
    """Schedule COLLECTION on two workers that finish their tests in turn; (worker, test) in the order sent."""
    sent: list[tuple[str, str]] = []
    workers = [_Worker("gw0", sent), _Worker("gw1", sent)]
    for w in workers:
        sched.add_node(w)
    for w in workers:
        sched.add_node_collection(w, COLLECTION)
    sched.schedule()
    while any(w.pending for w in workers):
        for w in workers:
            if w.pending:
                sched.mark_test_complete(w, w.pending.pop(0))
    return sent


def test_files_stay_whole_and_docs_tests_go_one_by_one_first(request):
    sent = _run(_make_scheduler(request, "loadfile"))
    assert sorted(t for _, t in sent) == sorted(COLLECTION)  # every test sent once
    for name in ("tests/test_a.py", "tests/test_c.py"):
        mine = [(w, t) for w, t in sent if t.startswith(name)]
        assert len({w for w, _ in mine}) == 1  # one worker
        assert [t for _, t in mine] == [t for t in COLLECTION if t.startswith(name)]  # in file order
    order = [t.startswith(DOCS) for _, t in sent]
    assert order == sorted(order, reverse=True)  # every docs test before any file's
    assert {w for w, t in sent if t.startswith(DOCS)} == {"gw0", "gw1"}  # the pages spread over both workers


def test_other_distributions_keep_pytest_xdist_defaults(request):
    assert _make_scheduler(request, "load") is None
