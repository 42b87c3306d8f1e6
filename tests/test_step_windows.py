"""The step window contract (imulog.steps.windows): cores tile the recording, margins are clipped, one window
for a short trial, event windows between rests."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.steps.windows import Window, event_windows, owned, plan_windows


def test_short_trial_is_one_window_without_margins():
    (w,) = plan_windows(6000, 100.0, core_s=3600.0, margin_s=60.0)
    assert (w.lo, w.core_lo, w.core_hi, w.hi) == (0, 0, 6000, 6000)


@pytest.mark.parametrize("total", [360_001, 720_000, 1_000_003])
def test_cores_tile_the_recording_and_margins_are_clipped(total):
    ws = plan_windows(total, 100.0, core_s=3600.0, margin_s=60.0)
    assert ws[0].core_lo == 0 and ws[-1].core_hi == total
    for a, b in zip(ws[:-1], ws[1:], strict=True):
        assert a.core_hi == b.core_lo
        assert b.lo == b.core_lo - 6000 and a.hi == min(total, a.core_hi + 6000)
    x = np.arange(total)
    joined = np.concatenate([w.core(x[w.lo : w.hi]) for w in ws])
    np.testing.assert_array_equal(joined, x)


def test_bad_inputs_raise_one_line():
    with pytest.raises(ValueError, match="rate"):
        plan_windows(10, 0.0)
    with pytest.raises(ValueError, match="lo <= core_lo"):
        Window(0, 5, 4, 4, 6)
    with pytest.raises(ValueError, match="rows"):
        plan_windows(10, 1.0)[0].core(np.zeros(3))


def test_event_windows_hold_their_rests_and_split_long_stretches():
    ws = event_windows([(0, 100), (300, 400), (2000, 2100)], 2100, 100.0, max_s=10.0)
    assert [(w.lo, w.move_lo, w.move_hi, w.hi, w.split) for w in ws] == [
        (0, 100, 300, 400, False),
        (300, 400, 1400, 1400, True),
        (1400, 1400, 2000, 2100, True),
    ]
    with pytest.raises(ValueError, match="overlap"):
        event_windows([(0, 100), (50, 200)], 300, 100.0)


def test_items_are_owned_by_the_window_holding_their_start():
    ws = plan_windows(30, 1.0, core_s=10.0, margin_s=2.0)
    got = {w.index: mine for w, mine in owned(ws, ["a", "b", "c", "d"], [25, 0, 9, 10])}
    assert got == {0: ["b", "c"], 1: ["d"], 2: ["a"]}
