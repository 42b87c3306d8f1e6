"""Protocols: each module builds a :class:`~imulog.simulate.motion.MotionPlan` with labelled intervals.

Every protocol module has a frozen ``Params`` dataclass (its parameters with sources) and
``build(params, subject_rng, trial_rng) -> ProtocolResult``.
"""

from __future__ import annotations

import importlib
from types import ModuleType

PROTOCOL_NAMES = ("r2g", "slide", "nhpt", "adl", "continuous")


def get(name: str) -> ModuleType:
    if name not in PROTOCOL_NAMES:
        raise ValueError(f"unknown protocol {name!r}; choose one of {', '.join(PROTOCOL_NAMES)}")
    return importlib.import_module(f"imulog.simulate.protocols.{name}")
