"""Viewer twins are low-passed before decimation (imulog.archive.twin_filter): no aliasing, seamless pieces."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.archive import TrialReader, write_trial
from imulog.archive.streaming import write_trial_streaming
from imulog.archive.timeline import IDENTITY
from imulog.archive.twin_filter import PieceFilter, lowpass_at, lowpassed, margin, taps
from imulog.archive.twins import decimation, imu_twin
from imulog.model import ImuStream, Recording, take_samples


def twin_axes(twin) -> tuple[np.ndarray, np.ndarray]:
    """(gyr, acc) (K, 3) of a ``sensor_msgs/msg/Imu`` twin's CDR rows (37 float64 at the end of each row)."""
    f = np.ascontiguousarray(twin.rows[:, -37 * 8 :]).view("<f8")
    return f[:, 13:16], f[:, 25:28]


def above(x: np.ndarray, rate_hz: float, cut_hz: float) -> np.ndarray:
    """The part of (N, C) ``x`` above ``cut_hz`` (FFT brick wall, mean removed)."""
    spec = np.fft.rfft(x - x.mean(axis=0), axis=0)
    spec[np.fft.rfftfreq(len(x), 1 / rate_hz) <= cut_hz] = 0
    return np.fft.irfft(spec, n=len(x), axis=0)


@pytest.fixture(scope="module")
def gaitmap_foot(shared_data):
    from imulog.converters.registry import convert_files

    rec = convert_files([shared_data / "gaitmap_foot" / "imu_sample.csv"])
    return rec.imus[0]


def test_gaitmap_foot_twin_holds_nothing_above_its_nyquist(gaitmap_foot):
    """The real 204.8 Hz foot IMU: above the twin's Nyquist, the twin holds >= 40 dB less than the raw signal."""
    imu = gaitmap_foot
    t = imu.t_ns
    rate = 1e9 / np.median(np.diff(t))
    keep = decimation(t)
    k = int(keep[1] - keep[0])
    nyquist = rate / k / 2
    assert rate == pytest.approx(204.8, rel=1e-3) and k == 9 and nyquist == pytest.approx(11.38, abs=0.01)
    hi_acc, hi_gyr = above(imu.acc, rate, nyquist), above(imu.gyr, rate, nyquist)
    share = (hi_acc**2).sum() / ((imu.acc - imu.acc.mean(axis=0)) ** 2).sum()
    assert share > 0.4  # about half the foot's acceleration power lies above the twin's Nyquist (48 % measured)
    # the twin is linear in its input: the twin of the above-Nyquist part is what that part puts into the twin
    gyr_hi, acc_hi = twin_axes(imu_twin(ImuStream("foot", t, acc=hi_acc, gyr=hi_gyr), IDENTITY))
    for raw_hi, in_twin in ((hi_acc, acc_hi), (hi_gyr, gyr_hi)):
        db = 10 * np.log10((in_twin**2).mean() / (raw_hi**2).mean())
        print(f"above-Nyquist content in the twin: {db:.1f} dB")
        assert db <= -40, db
        assert 10 * np.log10((raw_hi[keep] ** 2).mean() / (raw_hi**2).mean()) > -1  # every k-th sample: aliased
    # ... while what is below 0.8x its Nyquist stays as it is (within 1 %)
    lo = imu.acc - above(imu.acc, rate, 0.8 * nyquist)
    _, acc_lo = twin_axes(imu_twin(ImuStream("foot", t, acc=lo, gyr=np.zeros_like(lo)), IDENTITY))
    inner = slice(margin(k) // k + 1, -(margin(k) // k) - 1)  # away from the recording's two ends
    err = np.sqrt(((acc_lo - lo[keep])[inner] ** 2).mean() / ((lo - lo.mean(axis=0)) ** 2).mean())
    assert err < 0.01, err


def test_the_archive_twin_is_the_filtered_signal(gaitmap_foot, tmp_path):
    path = write_trial(tmp_path / "foot.mcap", Recording(imus=[gaitmap_foot]))
    with TrialReader(path) as trial:
        twin_topic = next(c.topic for c in trial.channels if c.metadata.get("twin_of") == gaitmap_foot.topic)
        rows = np.array([np.frombuffer(bytes(m), np.uint8) for m in trial.messages(twin_topic)])
    f = np.ascontiguousarray(rows[:, -37 * 8 :]).view("<f8")
    keep = decimation(gaitmap_foot.t_ns)
    np.testing.assert_array_equal(f[:, 25:28], lowpass_at(gaitmap_foot.acc, keep, 9, gaitmap_foot.t_ns))


def test_kernel_is_flat_then_60_db_down():
    for k in (2, 5, 9, 40):
        h = taps(k)
        assert len(h) % 2 == 1 and np.allclose(h, h[::-1]) and h.sum() == pytest.approx(1.0)
        f = np.fft.rfftfreq(1 << 16)
        gain = np.abs(np.fft.rfft(h, 1 << 16))
        nyq = 0.5 / k
        assert np.abs(gain[f <= 0.8 * nyq] - 1).max() < 2e-3
        assert 20 * np.log10(gain[f >= nyq].max()) < -59


def _stream(n: int, seed: int = 0) -> ImuStream:
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.int64) * 10_000_000
    t[n // 2 :] += 2_000_000_000  # a 2 s gap: the filter does not reach across it
    acc = rng.normal(size=(n, 3))
    acc[100:103, 1] = np.nan
    return ImuStream("wrist", t, acc=acc, gyr=rng.normal(size=(n, 3)))


def test_pieces_filter_like_the_whole():
    s = _stream(3000)
    k = 4
    whole = lowpassed(s, np.arange(0, len(s.t_ns), k), k)
    pf = PieceFilter(k)
    cuts = [0, 7, 50, 51, 400, 1490, 1600, 2999, 3000]  # pieces shorter and longer than the kernel's margin
    parts = [pf.push(take_samples(s, np.arange(a, b))) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    parts.append(pf.flush())
    parts = [p for p in parts if p is not None]
    np.testing.assert_array_equal(np.concatenate([p.t_ns for p in parts]), whole.t_ns)
    for name in ("acc", "gyr"):
        np.testing.assert_allclose(np.concatenate([getattr(p, name) for p in parts]), getattr(whole, name), atol=1e-12)
    assert np.isnan(whole.acc[25, 1]) and np.isfinite(whole.acc[24, 1])  # sample 100 is NaN, 96 is not
    # the gap: the last kept sample before it only sees its own side
    alone = lowpassed(take_samples(s, np.arange(0, 1500)), np.arange(0, 1500, k), k)
    np.testing.assert_allclose(whole.gyr[: len(alone.gyr)], alone.gyr, atol=1e-12)


def test_streamed_trial_twin_equals_the_whole(tmp_path):
    s = _stream(4000, seed=3)
    whole = write_trial(tmp_path / "whole.mcap", Recording(imus=[s]))
    cuts = [0, 333, 1000, 1001, 2500, 4000]
    pieces = [Recording(imus=[take_samples(s, np.arange(a, b))]) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    streamed = write_trial_streaming(tmp_path / "streamed.mcap", iter(pieces))
    topic = "/derived/viewer/imu/wrist"
    with TrialReader(whole) as a, TrialReader(streamed) as b:
        ma, mb = [bytes(m) for m in a.messages(topic)], [bytes(m) for m in b.messages(topic)]
    assert len(ma) == 1000 and len(mb) == 1000
    ra, rb = (np.array([np.frombuffer(m, np.uint8) for m in ms]) for ms in (ma, mb))
    np.testing.assert_array_equal(ra[:, : -37 * 8], rb[:, : -37 * 8])  # stamps and frame names
    fa, fb = (np.ascontiguousarray(r[:, -37 * 8 :]).view("<f8") for r in (ra, rb))
    np.testing.assert_allclose(fb, fa, rtol=0, atol=1e-12)  # the same sums (BLAS may order them differently)


def test_long_recordings_get_an_epoch_rate_overview_short_trials_keep_25_hz():
    from imulog.archive.twins import OVERVIEW_AFTER_S, OVERVIEW_EPOCH_S, TWIN_RATE_HZ

    rate = 100.0
    short = (np.arange(int(3600 * rate)) * 1e9 / rate).astype(np.int64)  # 1 h
    keep = decimation(short)
    assert np.median(np.diff(short[keep])) == pytest.approx(1e9 / TWIN_RATE_HZ)
    long = (np.arange(int((OVERVIEW_AFTER_S + 600) * rate)) * 1e9 / rate).astype(np.int64)  # just over 3 h
    keep = decimation(long)
    assert np.median(np.diff(long[keep])) == pytest.approx(OVERVIEW_EPOCH_S * 1e9)
