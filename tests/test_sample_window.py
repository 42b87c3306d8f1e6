"""SampleWindow: windows of a channel read block by block equal slices of the whole, and dropped blocks stay dropped."""

import numpy as np
import pytest

from imulog.steps.sample_window import SampleWindow


def _blocks(t, x, sizes):
    pos = 0
    for n in sizes:
        yield t[pos : pos + n], None, x[pos : pos + n]
        pos += n


def test_windows_equal_slices_of_the_whole():
    t = np.arange(100, dtype=np.int64)
    x = np.arange(200.0).reshape(100, 2)
    w = SampleWindow(_blocks(t, x, [7, 30, 1, 40, 22]), total=100)
    for lo, hi in [(0, 5), (3, 40), (36, 38), (38, 90), (80, 120)]:  # overlapping, forward, past the end
        got_t, none, got_x = w.get(lo, hi)
        assert none is None
        np.testing.assert_array_equal(got_t, t[lo:hi])
        np.testing.assert_array_equal(got_x, x[lo:hi])
        w.drop_before(lo)
        assert w.start <= lo and all(len(p[0]) for p in w.parts)
    assert w.start == 78  # the blocks ending before 80 were freed: only the last one is kept
    with pytest.raises(RuntimeError, match="dropped"):
        w.get(10, 20)


def test_take_moves_forward():
    t = np.arange(50, dtype=np.int64)
    w = SampleWindow(_blocks(t, t[:, None] * 1.0, [10] * 5), total=50)
    for lo in range(0, 50, 9):
        np.testing.assert_array_equal(w.take(lo, lo + 15)[0], t[lo : lo + 15])
        assert w.start > lo - 10
