"""Rigid-body setups pair IMUs with bodies without aligning every pair (``imulog process align`` on ``/poses/*``).

Before, each IMU was aligned in full against every body to pair them (11 x 11 bodies: 121 alignments); now the
bodies are ranked per IMU by the coarse correlation of the angular-velocity norms and only each IMU's best
``refine`` get the full alignment (every body for an IMU left without one). Setup: the simulated 3-IMU rigid-body
setups of seeds 0 and 1 joined (``benchmarks/bench_pose_setup.py``): 6 IMUs, 6 bodies, one station clock; the two
trunks barely turn and no body aligns them. The wall time is in the benchmark, not here."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.model import Recording
from imulog.process import alignment as al

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from bench_pose_setup import joined_setup  # noqa: E402

PAIRED = ["s0_upper_arm", "s0_forearm", "s1_upper_arm", "s1_forearm"]


@pytest.fixture(scope="module")
def six():
    return joined_setup(6, 30.0)


def test_six_bodies_pair_each_imu_with_its_own_after_fewer_full_alignments(six, tmp_path, monkeypatch):
    imus, bodies = six
    path = write_trial(
        tmp_path / "six.mcap", Recording(imus=list(imus.values()), poses=list(bodies.values())), attach_sources=False
    )
    calls = []
    align = al.align

    def counted(*args, **kwargs):
        calls.append(1)
        return align(*args, **kwargs)

    monkeypatch.setattr(al, "align", counted)
    result = CliRunner().invoke(cli, ["process", "align", str(path)])
    assert result.exit_code == 0, result.output
    with TrialReader(path) as t:
        meta = t.metadata
    for n in PAIRED:
        assert meta[f"imulog.alignment.{n}"]["reference"] == f"/poses/{n}_body"
    assert set(meta["imulog.alignment"]["unpaired"]) == {"s0_trunk", "s1_trunk"}
    # 4 bodies per IMU (SearchParams.refine), all 6 for the two trunks left without one: 4 x 4 + 2 x 6 = 28 (36
    # before, more with the wide lag search of the pairs that fail)
    assert 28 <= len(calls) < 36, len(calls)
    assert meta["imulog.alignment"]["search"] == {"pairs_scored": 36, "pairs_aligned": 28}


def test_the_ranked_search_gives_the_pairs_and_records_of_the_exhaustive_one(six):
    """``refine`` 1 (one body per IMU, then every body for an IMU left without one) against ``refine`` 6 (every
    pair, as before): the same pairs, the same records."""
    from imulog.steps.align_pose import pose_body
    from imulog.steps.align_pose_search import ImuInput, search_pose_setup

    imus, bodies = six
    params = al.AlignmentParams()
    found = {b: pose_body(b, p.t_ns, p.position, p.orientation, params) for b, p in bodies.items()}
    data = {n: ImuInput(s.t_ns, s.gyr) for n, s in imus.items()}
    out = {}
    for refine in (1, 6):
        p = dataclasses.replace(params, search=dataclasses.replace(params.search, refine=refine))
        out[refine] = search_pose_setup(data, found, p)
    (pairs1, why1, s1), (pairs6, why6, s6) = out[1], out[6]
    assert pairs1 == pairs6 == {n: f"/poses/{n}_body" for n in PAIRED}
    assert set(why1) == set(why6) == {"s0_trunk", "s1_trunk"}
    assert all(s1.candidates[n][b] == s6.candidates[n][b] for n, b in pairs1.items())
    assert s1.aligned == 4 + 2 * 6 and s6.aligned == 36
