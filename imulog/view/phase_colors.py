"""Colours and labels of the phase and repetition lanes in the viewer (pure: arrays in, labels and colours out)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from imulog.view import layout as L

FORCED = " (forced)"  # suffix of a phase label event correction made by cutting a movement
FORCED_COLOR = 0x7F7F7FFF  # forced phases are grey, not their phase's colour
REP_COLORS = (0xD5D9DFFF, 0xAEB5BFFF)  # the repetition lane alternates two greys: repetitions countable
LOW_CONFIDENCE_COLOR = 0xE8B730FF  # a repetition the segmentation is unsure of (confidence < 0.5)
MAX_NUMBERED_REPETITIONS = 1000  # phase lane labels "reach 3" up to this many repetitions, plain "reach" beyond
MAX_LOGGED_PHASES = 20_000  # the phase log lists every phase up to this many


def phase_color(label: str) -> int:
    """RGBA of a phase lane value: ``reach``, ``reach 3`` -> reach's colour; ``... (forced)`` -> grey."""
    if label.endswith(FORCED):
        return FORCED_COLOR
    base, _, number = label.rpartition(" ")
    return L.PHASE_COLORS.get(label, L.PHASE_COLORS.get(base, FORCED_COLOR) if number.isdigit() else FORCED_COLOR)


def known_phase_colors(values: Iterable[Any]) -> dict[str, int]:
    """Colours of the values that are R2G phases or forced phases (other lane values keep Rerun's colours)."""
    present = {str(v) for v in values if v}
    return {v: phase_color(v) for v in present if v in L.PHASE_COLORS or v.endswith(FORCED)}


def numbered_phase_labels(labs: np.ndarray, tasks: np.ndarray, rep: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    """Phase labels with their repetition (``reach 3``, ``lift 3 (forced)``) and the colour of every lane value.

    A zoomed-in state lane then reads on its own; the repetition lane alternates two greys (amber where the
    repetition's confidence is low) so repetitions can be counted when zoomed out.
    """
    out = []
    colors: dict[str, int] = {}
    base_color: dict[str, int] = {}
    for lab, k in zip(labs.tolist(), tasks.tolist(), strict=True):
        lab = str(lab)
        if k < 0:
            value = lab
        elif lab.endswith(FORCED):
            value = f"{lab[: -len(FORCED)]} {k}{FORCED}"
        else:
            value = f"{lab} {k}"
        out.append(value)
        if value:
            if lab not in base_color:
                base_color[lab] = phase_color(lab)
            colors[value] = base_color[lab]
    return np.array(out, dtype=object), colors | repetition_colors(tasks, rep)


def repetition_colors(tasks: np.ndarray, rep: np.ndarray) -> dict[str, int]:
    """Colours of the repetition lane: two alternating greys, amber where a repetition's confidence is low."""
    colors: dict[str, int] = {}
    for r, k in zip(rep.tolist(), tasks.tolist(), strict=True):
        if r:
            unsure = "confidence" in str(r) or "flagged" in str(r)
            colors[str(r)] = LOW_CONFIDENCE_COLOR if unsure else REP_COLORS[int(k) % 2]
    return colors
