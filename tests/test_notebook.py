"""The notebook API: TrialReader's repr and HTML, read_pandas on either clock, a trial in Rerun's notebook viewer."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from imulog.archive import TrialReader
from imulog.process.alignment import device_to_reference


def test_repr_is_a_few_lines_and_the_html_keeps_the_table(processed_r2g):
    with TrialReader(processed_r2g) as trial:
        text = repr(trial)
        page = trial._repr_html_()
        n_runs = len(trial.runs())
        channels = trial.channels
    assert text.startswith(f"<TrialReader {processed_r2g} (subject=S00")
    lines = text.splitlines()
    assert len(lines) == 4 and max(len(line) for line in lines[1:]) <= 110  # was 40 lines (issue 30)
    assert "raw (2): /imu/wrist 114.903 Hz" in text and "/markers/vicon 100 Hz" in text
    derived = [c for c in channels if c.derived and not c.metadata.get("twin_of")]
    assert f"derived ({len(derived)} channels, {n_runs} runs): acc_global, movements, orientation" in text
    assert "alignment: /imu/wrist on /markers/vicon, offset " in text
    # the HTML repr (Jupyter) keeps the full table: one row per channel, viewer twins included, and the runs
    assert page.startswith("<div") and "<table>" in page and page.count("<tr>") == 1 + len(channels)
    assert page.count("<li>") == n_runs and "orientation:wrist" in page
    assert "<TrialReader" not in page  # HTML of its own, not the text repr


def test_read_pandas_on_either_clock(processed_r2g):
    with TrialReader(processed_r2g) as trial:
        plain = trial.read_pandas("/imu/wrist")
        dev = trial.read_pandas("/imu/wrist", clock="device")
        ref = trial.read_pandas("/imu/wrist", clock="reference")
        phases = trial.read_pandas("/derived/phases/wrist", clock="reference")
        alignment = trial.metadata["imulog.alignment"]
        vicon = trial.read_pandas("/markers/vicon", clock="reference")
    assert "t_ns" in plain.columns and isinstance(plain.index, pd.RangeIndex)  # unchanged default
    assert isinstance(ref.index, pd.TimedeltaIndex) and ref.index.name == "t"  # no start_time recorded
    np.testing.assert_array_equal(ref["t_ns"].to_numpy(), device_to_reference(plain["t_ns"].to_numpy(), alignment))
    np.testing.assert_array_equal(dev["t_ns"].to_numpy(), plain["t_ns"].to_numpy())
    np.testing.assert_array_equal(ref["gyr_x"].to_numpy(), plain["gyr_x"].to_numpy())
    assert ref.attrs["units"]["gyr_x"] == "rad/s" and ref.attrs["clock"]["clock"] == "reference"
    assert vicon.index[0] == pd.Timedelta(0)  # the Vicon starts the trial
    # phases and IMU share the index: slicing the IMU by a phase works directly
    first = phases.iloc[0]
    window = ref.loc[phases.index[0] : phases.index[0] + pd.to_timedelta(first["duration[s]"], unit="s")]
    assert 80 < len(window) < 200


def test_show_trial_builds_the_recording_without_a_browser(processed_r2g, tmp_path, monkeypatch):
    rerun_notebook = pytest.importorskip("rerun_notebook")
    sent: list[bytes] = []
    monkeypatch.setattr(rerun_notebook.Viewer, "send_rrd", lambda self, data: sent.append(bytes(data)))
    from imulog.view.notebook import show_trial

    shown = show_trial(processed_r2g)
    topics = {e.topic for e in shown.logged[0].entities}
    assert {"/imu/wrist", "/markers/vicon", "/derived/phases/wrist"} <= topics
    assert sent and all(chunk[:4] == b"RRF2" for chunk in sent)  # Rerun's RRD stream, as the widget gets it
    # about as much data as `imulog view --save` writes for the same trial
    from click.testing import CliRunner

    from imulog.cli import cli

    out = tmp_path / "t.rrd"
    assert CliRunner().invoke(cli, ["view", str(processed_r2g), "--save", str(out)]).exit_code == 0
    assert 0.5 < sum(map(len, sent)) / out.stat().st_size < 2.0
    assert hasattr(shown, "_repr_mimebundle_") and shown.reduced is False
