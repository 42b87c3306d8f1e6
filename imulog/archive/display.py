"""How a :class:`~imulog.archive.TrialReader` shows itself in a REPL or a notebook, and its pandas time index.

``repr(trial)`` is a few lines (the raw channels with their rates, how many derived channels and runs, the
alignment); ``trial._repr_html_()`` (Jupyter) keeps the full table of channels (schema, rate, samples,
duration), the derived runs and the alignment. Both read only the file's summary and metadata records. ``frame_on_clock``
is what ``TrialReader.read_pandas(topic, clock=...)`` returns: a DataFrame indexed by time on one clock.
"""

from __future__ import annotations

import html
from typing import Any


def _rows(trial) -> list[tuple[str, str, str, str, str]]:
    rows = []
    for c in trial.channels:
        rate = f"{c.rate_hz:.6g}" if c.rate_hz else "-"
        dur = "-" if c.duration_s is None else f"{c.duration_s:.2f}"
        rows.append((c.topic, c.schema_name, rate, str(c.sample_count), dur))
    return rows


def _alignment(trial) -> str:
    rec = trial.metadata.get("imulog.alignment")
    if not rec:
        return "none (imulog process align)"
    offset = rec.get("offset_ns")
    drift = rec.get("drift_ppm")
    parts = [f"{rec.get('imu', '?')} on {rec.get('reference', '?')}"]
    if offset is not None:
        parts.append(f"offset {float(offset) / 1e9:.6f} s")
    if drift is not None:
        parts.append(f"drift {float(drift):.3g} ppm")
    if rec.get("score") is not None:
        parts.append(f"score {float(rec['score']):.3f}")
    return ", ".join(parts)


def _runs(trial) -> list[str]:
    return [f"#{n} {r.get('step', '')}: {r.get('algorithm', '')}" for n, r in trial.runs().items()]


def trial_repr(trial, width: int = 110) -> str:
    """A few lines: file and trial record, raw channels (rate, duration), derived channels and runs, alignment.

    ``trial.channels`` (or ``imulog info``) has the full table; in Jupyter the HTML repr shows it.
    """
    rec = trial.metadata.get("imulog.trial", {})
    who = ", ".join(f"{k}={rec[k]}" for k in ("subject", "trial", "task", "start_time") if k in rec)
    lines = [f"<TrialReader {trial.path}{' (' + who + ')' if who else ''}>"]
    chans = [c for c in trial.channels if not (c.metadata.get("twin_of") or c.topic.startswith("/derived/viewer/"))]
    raw = [c for c in chans if not c.derived]
    derived = [c for c in chans if c.derived]

    def short(c) -> str:
        rate = f" {c.rate_hz:.6g} Hz" if c.rate_hz else ""
        dur = f" {c.duration_s:.1f} s" if c.duration_s else ""
        return f"{c.topic}{rate}{dur}" if c.sample_count else f"{c.topic} (empty)"

    def joined(label: str, items: list[str]) -> str:
        text = f"  {label}: " + (", ".join(items) or "none")
        return text if len(text) <= width else text[: width - 3] + "..."

    lines.append(joined(f"raw ({len(raw)})", [short(c) for c in raw]))
    groups = sorted({c.topic.split("/")[2] for c in derived if c.topic.count("/") >= 2})
    runs = trial.runs()
    lines.append(joined(f"derived ({len(derived)} channels, {len(runs)} runs)", groups))
    lines.append("  alignment: " + _alignment(trial))
    return "\n".join(lines)


def trial_html(trial) -> str:
    """HTML summary for Jupyter (``_repr_html_``)."""
    esc = html.escape
    rec = trial.metadata.get("imulog.trial", {})
    head = "".join(f"<th>{esc(h)}</th>" for h in ("topic", "schema", "rate (Hz)", "samples", "duration (s)"))
    body = "".join("<tr>" + "".join(f"<td>{esc(v)}</td>" for v in r) + "</tr>" for r in _rows(trial))
    who = ", ".join(
        f"{esc(str(k))}={esc(str(v))}"
        for k, v in rec.items()
        if k in ("subject", "trial", "task", "start_time", "time_zone")
    )
    runs = "".join(f"<li>{esc(r)}</li>" for r in _runs(trial)) or "<li>none</li>"
    return (
        f"<div class='imulog-trial'><b>{esc(str(trial.path))}</b>{' &mdash; ' + who if who else ''}"
        f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
        f"<p><b>runs</b></p><ul>{runs}</ul><p><b>alignment</b>: {esc(_alignment(trial))}</p></div>"
    )


def frame_on_clock(
    trial, topic: str, clock: str, start_ns: int | None = None, end_ns: int | None = None, imu: str | None = None
) -> Any:
    """``topic`` as a DataFrame indexed by time on ``clock`` (``device`` or ``reference``).

    The index is ``time`` (a tz-aware DatetimeIndex) when the trial records a start time, else ``t``: a
    TimedeltaIndex from the trial's first raw sample. Columns keep their bare names (``acc_x``) plus
    ``t[s]`` and ``t_ns`` (ns on ``clock``); ``df.attrs["units"]`` maps columns to units and
    ``df.attrs["clock"]`` describes the clock. Intervals are indexed by their start.
    """
    import pandas as pd

    from imulog.archive.tables import stream_table
    from imulog.archive.trial_clock import trial_clock

    tc = trial_clock(trial, clock, imu)
    table = stream_table(trial.read(topic, start_ns, end_ns), trial.channel(topic).metadata, topic, tc)
    units = {}
    names = []
    for f in table.schema:
        meta = {k.decode(): v.decode() for k, v in (f.metadata or {}).items()}
        bare = meta.get("name", f.name) if f.name not in ("t[s]", "start[s]", "end[s]", "duration[s]") else f.name
        names.append(bare)
        units[bare] = meta.get("unit", "")
    df = table.rename_columns(names).to_pandas()
    key = "start" if "start_ns" in df.columns else "t"
    if f"{key}_time" in df.columns or "time" in df.columns:
        df = df.set_index("time" if key == "t" else f"{key}_time")
    else:
        df.index = pd.to_timedelta(df[f"{key}_ns"] - tc.origin_ns, unit="ns")
        df.index.name = key
    df.attrs["units"] = units
    df.attrs["clock"] = tc.record()
    df.attrs["topic"] = topic
    return df
