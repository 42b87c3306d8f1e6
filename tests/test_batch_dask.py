"""imulog batch on a real dask.distributed LocalCluster gives exactly the outputs of the local run."""

from __future__ import annotations

import shutil

import pytest
from click.testing import CliRunner

from imulog.batch import run
from imulog.batch.simulated import simulate_archive
from imulog.batch.verify import check_archive, derived_digests
from imulog.cli import cli

distributed = pytest.importorskip("distributed")

STEPS = "orientation,align,phases,trajectory,metrics,evaluate"
OPTIONS = {"phases": {"repetitions": 3}}


def test_dask_local_cluster_matches_local_run(tmp_path):
    raw = tmp_path / "raw"
    simulate_archive(raw, subjects=2, trials=1, repetitions=3, opening_static_s=5.0)
    local, remote = tmp_path / "local", tmp_path / "dask"
    shutil.copytree(raw, local)
    shutil.copytree(raw, remote)
    (remote / "S02" / "broken.mcap").write_bytes(b"definitely not mcap")
    ref = run(local, STEPS, options=OPTIONS, progress=False)
    assert ref.ok and ref.processed == 2
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        report = run(remote, STEPS, options=OPTIONS, progress=False, dask_scheduler=cluster.scheduler_address)
        assert report.engine == "dask" and report.workers == 1
        assert report.processed == 2 and report.failed == 1  # the broken file is isolated on the cluster too
        assert "broken.mcap" in report.failures()[0].path
        with distributed.Client(cluster) as client:  # an existing Client works as well; nothing left to do
            again = run(remote, STEPS, options=OPTIONS, progress=False, dask_scheduler=client, ledger=None)
        assert again.up_to_date == 2 and again.steps_computed == 0
        cli_run = CliRunner().invoke(
            cli,
            [
                "batch",
                str(remote),
                "--steps",
                STEPS,
                "--repetitions",
                "3",
                "-q",
                "--dask-scheduler",
                cluster.scheduler_address,
                "--no-ledger",
            ],
        )
        assert cli_run.exit_code == 1 and "(dask, 1 worker): 0 processed, 2 up to date" in cli_run.output
        assert "broken.mcap" in cli_run.output
    for f in ref.files:
        twin = str(remote) + f.path[len(str(local)) :]
        digests = derived_digests(f.path)
        assert len(digests) > 10  # derived channels plus result records
        assert derived_digests(twin) == digests
    assert check_archive(f.path for f in report.files if f.status != "failed") == {}
