"""Rerun viewer of imulog trials: columnar logging, default blueprint, web viewer.

from imulog.view import read_trial, show
show([read_trial("trial.mcap")], sink="save", save_paths=["trial.rrd"])
"""

from imulog.view.blueprint import build_blueprint
from imulog.view.session import ViewResult, log_trials, new_recording, show
from imulog.view.source import TrialData, from_recording, read_trial
from imulog.view.streams import Entity, LoggedTrial, log_streams

__all__ = [
    "Entity",
    "LoggedTrial",
    "TrialData",
    "ViewResult",
    "build_blueprint",
    "from_recording",
    "log_streams",
    "log_trials",
    "new_recording",
    "read_trial",
    "show",
]
