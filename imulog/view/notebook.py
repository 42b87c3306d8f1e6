"""A trial inline in a Jupyter notebook, with Rerun's notebook viewer (``pip install 'imulog[notebook]'``).

::

    from imulog.view.notebook import show_trial
    show_trial("trial.mcap")                      # the last expression of a cell: the viewer appears

The trial is read as ``imulog view`` reads it (long recordings as a min/max overview unless a
``start_s``/``end_s`` window is given), logged with the same layout and blueprint into a fresh
recording, and streamed into a ``rerun.notebook.Viewer`` widget. Nothing is served over the network and
no browser is needed to build it: the widget holds the recording's bytes until the notebook shows it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class NotebookTrial:
    """What :func:`show_trial` made: the widget (display it), its recording and what was logged."""

    viewer: Any
    recording: Any
    logged: list = field(default_factory=list)
    reduced: bool = False

    def _repr_mimebundle_(self, **kwargs: Any):  # a cell ending in show_trial(...) shows the viewer
        return self.viewer._repr_mimebundle_(**kwargs)

    def display(self) -> None:
        """Show the viewer now (outside the last line of a cell)."""
        self.viewer.display()


def show_trial(
    path: str | Path,
    *,
    width: int | str = "auto",
    height: int | str = 640,
    start_s: float | None = None,
    end_s: float | None = None,
    full_resolution: bool = False,
    viewer: Any = None,
) -> NotebookTrial:
    """Log the trial at ``path`` into a Rerun notebook viewer (a new one, or ``viewer``) and return it.

    ``start_s``/``end_s``: full resolution in that window (seconds on the viewer's timeline), the rest
    as an overview; ``full_resolution``: every sample of the whole trial.
    """
    try:
        from rerun.notebook import Viewer
    except ImportError as exc:  # pragma: no cover - the notebook extra is missing
        raise ImportError("the notebook viewer needs rerun-notebook: pip install 'imulog[notebook]'") from exc
    from imulog.view.overview import OverviewParams, read_trial_overview
    from imulog.view.session import log_trials, new_recording
    from imulog.view.source import open_trial

    if full_resolution:  # channels read while they are logged: the widget receives the first ones sooner
        data, reduced = open_trial(path), False
    else:
        data, reduced = read_trial_overview(path, OverviewParams(start_s=start_s, end_s=end_s), lazy=True)
    rec = new_recording(data.label)
    if viewer is None:
        viewer = Viewer(width=width, height=height, recording=rec)
    else:
        viewer.add_recording(rec)
    logged = log_trials(rec, [data], overlay=False)
    rec.flush()
    return NotebookTrial(viewer=viewer, recording=rec, logged=logged, reduced=reduced)
