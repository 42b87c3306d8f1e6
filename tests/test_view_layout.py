"""The default layout keeps the centimetre methods readable: drifting methods get their own plot and start hidden."""

from __future__ import annotations

import numpy as np
from rerun.chunk import RrdReader

from imulog.view import build_blueprint, from_recording, show
from imulog.view import layout as L
from imulog.view.sample import SampleTrialParams, sample_recording


def test_large_error_rule():
    assert L.large_error_topics({"zupt": 2.0, "optimized": 0.8, "ddi": 240.0}) == {"ddi"}
    assert L.large_error_topics({"zupt": 2.5, "optimized": 0.9}) == set()  # all centimetre methods stay
    assert L.large_error_topics({"ddi": 240.0}) == set()  # nothing to compare with: keep what there is
    assert L.large_error_topics({"a": 1.0, "b": 9.0}) == set()  # 9x but under the 10 cm floor


def _trial_with_ddi(tmp_path):
    rec = sample_recording(SampleTrialParams(duration_s=20.0, methods=("zupt", "optimized", "ddi")))
    ddi = next(s for s in rec.signals if s.topic == "/derived/trajectory/ddi")
    t_s = (ddi.t_ns - ddi.t_ns[0]) / 1e9
    ddi.values[:, 0] += 0.5 * 0.05 * t_s**2  # 5 cm/s^2 of uncorrected bias: metres by the end
    out = tmp_path / "ddi.rrd"
    result = show([from_recording(rec, "ddi")], sink="save", save_paths=[out])
    return out, result.logged[0][0]


def test_drifting_method_hidden_in_3d_and_plotted_apart(tmp_path):
    out, logged = _trial_with_ddi(tmp_path)
    errors = {e.topic: e.scale for e in logged.by_role("error")}
    assert errors["/derived/trajectory/ddi"] > 100 > 10 > errors["/derived/trajectory/optimized"]
    hidden = L.large_error_topics(errors)
    assert hidden == {"/derived/trajectory/ddi"}

    blueprint = build_blueprint(logged)
    blueprint_file = tmp_path / "bp.rbl"
    blueprint.save("imulog", blueprint_file)  # serialisable by rerun itself
    assert blueprint_file.stat().st_size > 0

    # the legend lists every path with its error and says DDI starts hidden
    legend = next(c for c in RrdReader(out).stream().to_chunks() if c.entity_path == L.legend_entity())
    text = legend.to_record_batch().column("TextDocument:text").to_pylist()[0][0]
    ddi_row = next(line for line in text.splitlines() if "trajectory/ddi" in line)
    opt_row = next(line for line in text.splitlines() if "trajectory/optimized" in line)
    assert ddi_row.endswith("| hidden |") and opt_row.endswith("| shown |")
    assert float(opt_row.split("|")[3]) < 10 < float(ddi_row.split("|")[3])


def test_readable_axis_covers_centimetre_methods_only(tmp_path):
    from imulog.view import blueprint as B

    _, logged = _trial_with_ddi(tmp_path)
    hidden = B.large_error_topics_of([logged])
    readable = [e.scale for e in logged.by_role("error") if e.topic not in hidden]
    top = max(readable)
    assert 0 < top < 10
    # what the plot of the readable methods spans (1.25 x their 95th percentile) stays far below DDI's error
    ddi = next(e.scale for e in logged.by_role("error") if e.topic in hidden)
    assert 1.25 * top < ddi / 10
    assert np.isfinite(top)


def test_numbered_phase_labels_and_colours():
    from imulog.view.streams import (
        FORCED,
        FORCED_COLOR,
        LOW_CONFIDENCE_COLOR,
        REP_COLORS,
        numbered_phase_labels,
        phase_color,
    )

    labs = np.array(["reach", "lift" + FORCED, "reach", "return_hand"], dtype=object)
    tasks = np.array([3, 3, 4, -1])
    rep = np.array(["rep 3", "rep 3", "rep 4 (confidence 0.20)", ""], dtype=object)
    numbered, colours = numbered_phase_labels(labs, tasks, rep)
    assert numbered.tolist() == ["reach 3", "lift 3" + FORCED, "reach 4", "return_hand"]
    assert colours["reach 3"] == colours["reach 4"] == L.PHASE_COLORS["reach"]
    assert colours["lift 3" + FORCED] == FORCED_COLOR
    assert colours["return_hand"] == L.PHASE_COLORS["return_hand"]
    assert colours["rep 3"] == REP_COLORS[1] and colours["rep 4 (confidence 0.20)"] == LOW_CONFIDENCE_COLOR
    assert phase_color("lift 12") == L.PHASE_COLORS["lift"] and phase_color("unknown 2") == FORCED_COLOR
