"""Long recordings in the viewer: min/max envelopes per bucket, full resolution in a window, small .rrd."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.cli import cli
from imulog.model import ImuStream, Recording
from imulog.view import layout as L
from imulog.view.overview import EnvelopeBuilder, OverviewParams, bucket_envelope, read_trial_overview
from imulog.view.rrd import read_scalars, summarize


def test_envelope_pieces_equal_one_pass():
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.integers(1, 30, 5000)).astype(np.int64)
    v = rng.normal(size=(5000, 3))
    v[rng.random((5000, 3)) < 0.05] = np.nan
    whole = EnvelopeBuilder(1000)
    whole.add(t, v)
    pieces = EnvelopeBuilder(1000)
    for a, b in zip([0, 7, 1234, 1235, 4000], [7, 1234, 1235, 4000, 5000], strict=True):
        pieces.add(t[a:b], v[a:b])
    t1, v1 = whole.rows()
    t2, v2 = pieces.rows()
    np.testing.assert_array_equal(t1, t2)
    np.testing.assert_array_equal(v1, v2)
    # each bucket's rows are its true extremes, at its first and last sample
    ids = t // 1000
    for k, bucket in enumerate(np.unique(ids)[:50]):
        inside = ids == bucket
        assert t1[2 * k] == t[inside][0] and t1[2 * k + 1] == t[inside][-1]
        np.testing.assert_array_equal(v1[2 * k], np.nanmin(v[inside], axis=0))
        np.testing.assert_array_equal(v1[2 * k + 1], np.nanmax(v[inside], axis=0))


def test_bucket_envelope_empty_and_single():
    ids, first, last, lo, hi = bucket_envelope(np.zeros(0, np.int64), np.zeros((0, 2)), 10)
    assert len(ids) == 0 and lo.shape == (0, 2)
    ids, first, last, lo, hi = bucket_envelope(np.array([5]), np.array([[1.0, 2.0]]), 10)
    assert first[0] == last[0] == 5 and (lo == hi).all()


@pytest.fixture(scope="module")
def long_trial(tmp_path_factory):
    """3 h of 9-axis IMU at 20 Hz with one burst of movement an hour in."""
    from imulog.archive import write_trial

    rate, hours = 20.0, 3.0
    n = int(rate * 3600 * hours)
    t = np.arange(n, dtype=np.int64) * int(1e9 / rate)
    rng = np.random.default_rng(1)
    gyr = rng.normal(0, 0.01, (n, 3))
    burst = (t >= 3600e9) & (t < 3610e9)
    gyr[burst, 0] += 3.0 * np.sin(np.linspace(0, 20 * np.pi, burst.sum()))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 0.05, (n, 3))
    imu = ImuStream("wrist", t, acc=acc, gyr=gyr, mag=rng.normal(20, 1, (n, 3)))
    path = tmp_path_factory.mktemp("long") / "long.mcap"
    write_trial(path, Recording(imus=[imu]))
    return path, imu


def test_long_trial_opens_on_an_overview(long_trial):
    path, imu = long_trial
    data, reduced = read_trial_overview(path, OverviewParams(buckets=2000))
    assert reduced
    (env,) = data.streams
    assert len(env) <= 2 * 2000 + 2 < len(imu) / 50
    # the burst's peak survives the reduction (a plain decimation would likely miss it)
    assert np.nanmax(env.gyr[:, 0]) == pytest.approx(np.max(imu.gyr[:, 0]))
    assert np.nanmin(env.gyr[:, 0]) == pytest.approx(np.min(imu.gyr[:, 0]))


def test_window_is_full_resolution(long_trial):
    path, imu = long_trial
    data, reduced = read_trial_overview(path, OverviewParams(buckets=500, start_s=3600.0, end_s=3620.0))
    assert reduced
    (env,) = data.streams
    inside = (imu.t_ns >= 3600e9) & (imu.t_ns < 3620e9)
    window = (env.t_ns >= 3600e9) & (env.t_ns < 3620e9)
    np.testing.assert_array_equal(env.t_ns[window], imu.t_ns[inside])
    np.testing.assert_array_equal(env.gyr[window], imu.gyr[inside])
    assert np.all(np.diff(env.t_ns) >= 0)


def test_short_trial_unchanged(tmp_path):
    from imulog.archive import write_trial

    t = np.arange(2000, dtype=np.int64) * 10_000_000
    imu = ImuStream("wrist", t, acc=np.tile([0.0, 0.0, 9.81], (2000, 1)), gyr=np.zeros((2000, 3)))
    path = write_trial(tmp_path / "short.mcap", Recording(imus=[imu]))
    data, reduced = read_trial_overview(path)
    assert not reduced and len(data.streams[0]) == 2000


def test_cli_long_trial_small_rrd(long_trial, tmp_path):
    path, imu = long_trial
    out = tmp_path / "long.rrd"
    result = CliRunner().invoke(cli, ["view", str(path), "--save", str(out), "--start", "3600", "--end", "3610"])
    assert result.exit_code == 0, result.output
    assert "min/max overview" in result.output and "full resolution from 3600 s" in result.output
    t, gyr = read_scalars(out, L.imu_entity("wrist", "gyr"))
    assert len(t) < len(imu) / 10
    assert np.max(gyr[:, 0]) == pytest.approx(np.max(imu.gyr[:, 0]))
    full = tmp_path / "full.rrd"
    result = CliRunner().invoke(cli, ["view", str(path), "--save", str(full), "--full-resolution"])
    assert result.exit_code == 0, result.output
    assert summarize(full)[L.imu_entity("wrist", "gyr")].rows == len(imu)
    assert out.stat().st_size < full.stat().st_size / 5
    bad = CliRunner().invoke(cli, ["view", str(path), "--start", "10", "--end", "5"])
    assert bad.exit_code != 0 and "--end" in bad.output


def test_interval_share_exact():
    from imulog.view.overview import interval_share

    edges = np.array([0, 10, 20, 30, 40], np.int64)
    # [5, 15) covers half of buckets 0 and 1; [20, 40) all of 2 and 3; [22, 24) overlaps it (clipped to 1)
    share = interval_share(np.array([5, 20, 22]), np.array([15, 40, 24]), edges)
    np.testing.assert_allclose(share, [0.5, 0.5, 1.0, 1.0])
    rng = np.random.default_rng(3)  # against a brute-force sum over disjoint random intervals
    cuts = np.sort(rng.choice(np.arange(1, 100_000), 400, replace=False)).reshape(-1, 2)
    edges = np.arange(0, 100_001, 1000)
    brute = [
        np.clip(np.minimum(cuts[:, 1], b) - np.maximum(cuts[:, 0], a), 0, None).sum() / (b - a)
        for a, b in zip(edges[:-1], edges[1:], strict=True)
    ]
    np.testing.assert_allclose(interval_share(cuts[:, 0], cuts[:, 1], edges), brute, atol=1e-12)
    with pytest.raises(ValueError, match="starts but"):
        interval_share(np.array([1, 2]), np.array([3]), edges)


def test_thousands_of_movements_become_a_share_and_window_lanes(tmp_path):
    """A long recording's movement lane is its share per bucket, with the movements kept only in the window."""
    from imulog.archive import write_trial
    from imulog.model import Intervals
    from imulog.view.session import show

    rate, hours = 10.0, 3.0
    n = int(rate * 3600 * hours)
    t = np.arange(n, dtype=np.int64) * int(1e9 / rate)
    imu = ImuStream("wrist", t, acc=np.tile([0.0, 0.0, 9.81], (n, 1)), gyr=np.zeros((n, 3)))
    starts = np.arange(5000, dtype=np.int64) * 2_000_000_000 + 1_000_000_000  # a 0.5 s movement every 2 s
    movements = Intervals("/derived/movements/wrist", starts, starts + 500_000_000, ["movement"] * 5000)
    path = write_trial(tmp_path / "home.mcap", Recording(imus=[imu], events=[movements]))
    params = OverviewParams(buckets=1000, start_s=3600.0, end_s=3660.0)
    data, reduced = read_trial_overview(path, params)
    assert reduced
    kept = next(s for s in data.streams if isinstance(s, Intervals))
    share = next(s for s in data.streams if s.topic == "/derived/movements/wrist/share")
    inside = (movements.end_ns >= 3600e9) & (movements.start_ns < 3660e9)
    np.testing.assert_array_equal(kept.start_ns, movements.start_ns[inside])
    assert 30 <= len(kept) <= 31 < params.max_intervals
    # each bucket (a row at its start) holds the % of it the movements cover: 25 % on average while they last
    width = int(np.diff(share.t_ns)[0])
    brute = [
        100
        * np.clip(np.minimum(movements.end_ns, a + width) - np.maximum(movements.start_ns, a), 0, None).sum()
        / width
        for a in share.t_ns[:200]
    ]
    np.testing.assert_allclose(share.values[:200, 0], brute, atol=1e-9)
    assert np.mean(share.values[share.t_ns < 9_900e9, 0]) == pytest.approx(25.0, abs=0.2)
    assert np.all(share.values[share.t_ns > 10_010e9, 0] == 0.0)
    out = tmp_path / "home.rrd"
    logged = show([data], sink="save", save_paths=[out]).logged[0][0]
    assert [e.path for e in logged.by_role("interval_share")] == ["/derived/movements/wrist/share"]
    summary = summarize(out)
    assert summary["/derived/movements/wrist"].rows <= 2 * len(kept)
    assert summary["/derived/movements/wrist/share"].rows == len(share)
