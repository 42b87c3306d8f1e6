"""Rerun viewer of imulog trials: columnar logging, default blueprint, web viewer.

from imulog.view import open_trial, show
show([open_trial("trial.mcap")], sink="save", save_paths=["trial.rrd"])   # channels read while logged

The names below are imported on first use, so ``import imulog.archive.clocks`` (used by exports) does not
import Rerun.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "build_blueprint": "imulog.view.blueprint",
    "ViewResult": "imulog.view.session",
    "log_trials": "imulog.view.session",
    "new_recording": "imulog.view.session",
    "show": "imulog.view.session",
    "TrialData": "imulog.view.source",
    "from_recording": "imulog.view.source",
    "open_trial": "imulog.view.source",
    "read_trial": "imulog.view.source",
    "Entity": "imulog.view.streams",
    "LoggedTrial": "imulog.view.streams",
    "log_streams": "imulog.view.streams",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'imulog.view' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
