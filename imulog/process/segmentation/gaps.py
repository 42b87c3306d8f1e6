"""Where the rest next to a phase ends: at the neighbouring phase or at a movement that is no phase (issue 31).

Step 2 of :mod:`~imulog.process.segmentation.hand` looks for its rest window in the gap between a phase and its
neighbour. Before the first phase (after the last) the neighbour was the recording's start (end), so that gap also
held the calibration wave and the still stretch before it (about 47 s on the simulated drinking trials, the wave
at 28-37 s): the search for a still window then ran to the gap's middle, inside the wave, and compared every
window with the quietest of about a thousand, which a 25-sample window at 50 Hz fails on noise alone (ratios of
1-3.5 on a still hand). The window moved up to 6 s further from the reach on 42 of 90 simulated 50-Hz trials, and
the velocity integrated over that stretch took the rest's drift for the hand (two first reaches 1.2 and 1.45 s
early, docs/accuracy.md, twelfth round). A movement that the detector found and that overlaps no phase (the
calibration wave, a fidget) is motion all the same: with ``HandParams.movement_gaps`` the rest next to a phase ends
there. An option, off: on the grid's ``combined`` and ``rotation-early`` trials such a movement right after a phase
is often the phase's own last part, and 22 of 1440 development trials got worse.
Pure numpy; intervals are half-open sample ranges ``[start, end)``.
"""

from __future__ import annotations

import numpy as np


def unphased_movements(
    move_start: np.ndarray, move_end: np.ndarray, start: np.ndarray, end: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The detector's movements ``[move_start, move_end)`` (samples) that overlap none of the phases
    ``[start, end)``, sorted by start: motion outside every phase (the calibration wave, a fidget)."""
    ms = np.asarray(move_start, dtype=np.int64)
    me = np.asarray(move_end, dtype=np.int64)
    s = np.sort(np.asarray(start, dtype=np.int64))
    e = np.sort(np.asarray(end, dtype=np.int64))
    # a movement overlaps a phase when some phase starts before its end and ends after its start; phases do not
    # overlap each other, so the count of phases starting before ``me`` minus those ending by ``ms`` says so
    overlaps = np.searchsorted(s, me, side="left") - np.searchsorted(e, ms, side="right") > 0
    keep = ~overlaps & (me > ms)
    order = np.argsort(ms[keep], kind="stable")
    return ms[keep][order], me[keep][order]


def gap_bounds(
    lo: int, hi: int, onset: int, offset: int, others: tuple[np.ndarray, np.ndarray] | None
) -> tuple[int, int]:
    """The rest before a phase ``[onset, offset)`` starts at ``lo`` (the previous phase's end) and the rest after
    it ends at ``hi`` (the next phase's start), or at the nearest of ``others`` (movements that are no phase,
    :func:`unphased_movements`) between: the end of the last one ending by ``onset``, the start of the first one
    starting at ``offset`` or later. Sample indices."""
    if others is None or len(others[0]) == 0:
        return int(lo), int(hi)
    os_, oe = others
    before = oe[oe <= onset]
    after = os_[os_ >= offset]
    if len(before):
        lo = max(int(lo), int(before.max()))
    if len(after):
        hi = min(int(hi), int(after.min()))
    return int(lo), int(hi)
