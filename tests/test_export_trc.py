"""``imulog export -o markers.trc``: OpenSim's marker file, read back by OpenSim itself (``opensim``'s
``TimeSeriesTableVec3``, its TRC reader) and by imulog's TRC converter. Real data: the Vicon Nexus export of
pyomeca (``../shared/data/vicon_nexus/markers.csv``, Apache-2.0: 51 markers with ``Daphnee:`` prefixes and gaps) and
the OptiTrack Motive take (``devices/optitrack_motive``, BSD-3-Clause: two marker channels, a never-seen marker)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import convert_file

from imulog.archive import TrialReader
from imulog.cli import cli


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def nexus(shared_data, tmp_path_factory):
    path = tmp_path_factory.mktemp("trc") / "nexus.mcap"
    result = run("convert", shared_data / "vicon_nexus" / "markers.csv", "-o", path)
    assert result.exit_code == 0, result.output
    return path


def test_opensim_reads_the_markers_as_the_trial_holds_them(nexus, tmp_path):
    opensim = pytest.importorskip("opensim")
    out = tmp_path / "markers.trc"
    result = run("export", nexus, "-o", out)
    assert result.exit_code == 0, result.output
    assert "(trc, reference clock)" in result.output
    with TrialReader(nexus) as trial:
        (topic,) = [t for t in trial.topics() if t.startswith("/markers/")]
        mk = trial.read(topic)
    table = opensim.TimeSeriesTableVec3(str(out))
    assert list(table.getColumnLabels()) == list(mk.labels)  # the Daphnee: names, as the optical system gave them
    assert table.getTableMetaDataAsString("Units") == "mm" and table.getNumRows() == len(mk.t_ns)
    got = np.array(
        [
            [[v.get(k) for k in range(3)] for v in (table.getRowAtIndex(i)[j] for j in range(len(mk.labels)))]
            for i in range(table.getNumRows())
        ]
    )
    want = np.where(mk.valid[:, :, None], mk.pos * 1000.0, np.nan)
    assert (~mk.valid).any()  # the file has gaps: empty cells, NaN for OpenSim
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_allclose(got[~np.isnan(got)], want[~np.isnan(want)], rtol=0, atol=1e-6)  # 1 nm cells
    times = np.array(table.getIndependentColumn())
    np.testing.assert_allclose(np.diff(times), np.diff(mk.t_ns) / 1e9, atol=1e-6)
    # and imulog's own TRC reader gives the markers back, in m
    back = convert_file(out).markers[0]
    assert back.labels == list(mk.labels)
    np.testing.assert_allclose(np.where(back.valid[:, :, None], back.pos, np.nan), want / 1000.0, atol=1e-9)


def test_a_trial_with_several_marker_channels_names_them(shared_data, tmp_path):
    path = tmp_path / "motive.mcap"
    assert run("convert", shared_data / "devices/optitrack_motive/sample_optitrack_take.csv", "-o", path).exit_code == 0
    refused = run("export", path, "-o", tmp_path / "x.trc")
    assert refused.exit_code == 1 and not (tmp_path / "x.trc").exists()
    assert "several marker channels: choose one with --topic (/markers/motive, /markers/motive_rigid_body_markers)" in (
        refused.output
    )
    wrong = run("export", path, "-o", tmp_path / "x.trc", "-t", "/poses/rigid_body_1")
    assert wrong.exit_code == 1 and "trc takes a marker channel, not /poses/rigid_body_1" in wrong.output
    ok = run("export", path, "-o", tmp_path / "m.trc", "-t", "/markers/motive")
    assert ok.exit_code == 0, ok.output
    back = convert_file(tmp_path / "m.trc").markers[0]
    occluded = back.labels.index("Unlabeled:105")  # never seen in the take: an empty column
    assert not back.valid[:, occluded].any() and back.valid.any()
