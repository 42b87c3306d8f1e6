"""Shared numeric helpers (imulog.numeric) against the numpy expressions they stand for."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.numeric import finite_rows, median_int


def test_median_int_is_numpys_median_exactly():
    """By counting where the values span a narrow range (a sampling clock's steps), by numpy's sort elsewhere:
    always ``float(np.median(a))``, odd and even lengths, negative values, int32, one wide outlier (a gap)."""
    rng = np.random.default_rng(0)
    for _ in range(500):
        n = int(rng.integers(1, 2000))
        a = int(rng.integers(-(2**40), 2**40)) + rng.integers(0, int(rng.integers(1, 3000)), n)
        assert median_int(a) == float(np.median(a))
        assert median_int(a.astype(np.int32) if abs(a).max() < 2**31 else a) == float(np.median(a))
    steps = np.diff((np.arange(360_000) * 1e7).astype(np.int64) + rng.integers(0, 15_000, 360_000))
    assert median_int(steps) == float(np.median(steps))
    steps[100] = 600 * 10**9  # a ten-minute gap: too wide to count, numpy's median
    assert median_int(steps) == float(np.median(steps))
    with pytest.warns(RuntimeWarning):  # numpy's warning for an empty array, and its NaN
        assert np.isnan(median_int(np.zeros(0, np.int64)))


def test_finite_rows_is_isfinite_all_over_the_last_axis():
    rng = np.random.default_rng(1)
    for width in (1, 3, 4, 9):
        a = rng.normal(size=(1000, width))
        a[rng.integers(0, 1000, 50), rng.integers(0, width, 50)] = np.nan
        a[7, 0] = np.inf
        assert np.array_equal(finite_rows(a), np.isfinite(a).all(axis=-1))
