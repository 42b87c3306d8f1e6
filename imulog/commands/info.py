"""``imulog info``: a trial's channels, rates, gaps, metadata, derived runs and step summaries, for reading."""

from __future__ import annotations

import json
import os
from typing import Any

import click

from imulog.archive import ArchiveError, TrialReader
from imulog.commands.archive import open_trial


def rerun_command(step: str) -> str:
    """The command that reruns a recorded step (``orientation:wrist`` -> ``imulog process orientation``)."""
    from imulog.cli import PROCESS_COMMANDS, TOP_LEVEL_COMMANDS

    base = step.split(":", 1)[0]
    if base in PROCESS_COMMANDS:
        return f"imulog process {base}"
    if base in TOP_LEVEL_COMMANDS:
        return f"imulog {base}"
    return f"the step {step!r}"


def trial_summary(trial: TrialReader) -> dict[str, Any]:
    """Everything ``imulog info`` shows, as a JSON-able dict (summary and metadata only: no channel or
    attachment data is read)."""
    stale = trial.stale_channels()
    stored = trial.summary.stored_bytes_by_channel()
    channels = []
    for c in trial.channels:
        md = c.metadata
        if c.message_count == 0:  # nothing stored (salvaged, interrupted): the recorded statistics do not hold
            channels.append(
                {
                    "topic": c.topic,
                    "schema": c.schema_name,
                    "kind": c.kind,
                    "derived": c.derived,
                    "messages": 0,
                    "samples": 0,
                    "rate_hz": None,
                    "start_ns": None,
                    "end_ns": None,
                    "duration_s": None,
                    "time_gaps": None,
                    "nan_samples": None,
                    "units": md.get("units", ""),
                    "frame_id": md.get("frame_id", ""),
                    "stored_bytes": 0,
                    "out_of_date": None,
                    "metadata": md,
                }
            )
            continue
        channels.append(
            {
                "topic": c.topic,
                "schema": c.schema_name,
                "kind": c.kind,
                "derived": c.derived,
                "messages": c.message_count,
                "samples": c.sample_count,
                "rate_hz": c.rate_hz,
                "mean_rate_hz": mean_rate_hz(c.sample_count, c.duration_s) if c.rate_hz else None,
                "declared_rate_hz": declared_rate_hz(c.topic, trial.metadata, md),
                "start_ns": c.start_ns,
                "end_ns": c.end_ns,
                "duration_s": c.duration_s,
                "time_gaps": int(md["time_gaps"]) if "time_gaps" in md else None,
                "nan_samples": int(md["nan_samples"]) if "nan_samples" in md else None,
                "units": md.get("units", ""),
                "frame_id": md.get("frame_id", ""),
                "stored_bytes": stored.get(c.channel_id, 0),
                "out_of_date": (
                    {**stale[c.topic], "rerun": rerun_command(stale[c.topic]["step"])} if c.topic in stale else None
                ),
                "metadata": md,
            }
        )
    runs = trial.runs()
    # runs are listed on their own; the closing statistics of streamed channels (imulog.channel_stats[.N]) are
    # already merged into those channels' metadata above, and the records of replaced channels are history
    metadata = {k: v for k, v in trial.metadata.items() if not k.startswith(("imulog.run.", "imulog.channel_stats"))}
    atts = trial.attachment_infos()  # sizes from the index, hashes from imulog.raw: nothing re-read
    return {
        "path": str(trial.path),
        "bytes": trial.summary.file_size,
        "channels": channels,
        "metadata": metadata,
        "attachments": atts,
        "runs": {str(k): v for k, v in runs.items()},
        "out_of_date": sorted(stale),
        "out_of_date_steps": {step: {**v, "rerun": rerun_command(step)} for step, v in trial.stale_steps().items()},
    }


def _fmt_units(units: str) -> str:
    """A short form of a channel's units: ``V x38`` for many equal units, else the list, cut at 40 chars; a unit
    the source did not state (an XDF stream without ``<unit>``) shows as ``?``."""
    try:
        values = json.loads(units)
    except ValueError:
        return units
    if not isinstance(values, list):
        return str(values)
    values = [str(v).strip() or "?" for v in values]
    if len(values) > 1 and len(set(values)) == 1:
        return f"{values[0]} x{len(values)}"
    text = ",".join(str(v) for v in values)
    return text if len(text) <= 40 else text[:37] + "..."


def _fmt_rate(rate: float | None) -> str:
    return "-" if not rate else f"{rate:.6g}"


#: the declared rate is shown beside the measured one when they differ by more than this (relative)
DECLARED_RATE_TOLERANCE = 0.01


def mean_rate_hz(samples: int | None, duration_s: float | None) -> float | None:
    """The channel's average rate, (samples - 1) / duration (Hz): what the recording holds per second, unlike the
    median sample step, which quantised time stamps bias (a .cwa's 1/97.56 s step in a 98.41 Hz recording)."""
    if not samples or samples < 2 or not duration_s or duration_s <= 0:
        return None
    return (samples - 1) / duration_s


def declared_rate_hz(topic: str, metadata: dict, channel_meta: dict | None = None) -> float | None:
    """The rate declared for ``/imu/NAME``, ``/markers/NAME`` or ``/poses/NAME`` (Hz): the stream's own
    ``declared_rate_hz``, else its ``rate_hz`` (the converter's ``meta``, kept in the channel's metadata), else the
    same keys of its ``imulog.device.NAME`` record (a device's record may hold its fastest channel's rate: a
    Delsys sensor's EMG 1259 Hz beside its IMU's 148 Hz); None without one."""
    kind, _, name = topic.lstrip("/").partition("/")
    if kind not in ("imu", "markers", "poses") or not name or "/" in name:
        return None
    try:
        stream = json.loads((channel_meta or {}).get("meta") or "{}")
    except ValueError:
        stream = {}
    device = metadata.get(f"imulog.device.{name}")
    for record in (stream, device):
        if not isinstance(record, dict):
            continue
        for key in ("declared_rate_hz", "rate_hz"):
            try:
                value = float(record.get(key))
            except (TypeError, ValueError):
                continue
            if value > 0:
                return value
    return None


def shown_rate(channel: dict) -> str:
    """The rate column: the average rate ((samples - 1) / duration) of a channel without time gaps, else the
    median step's (the gaps' lengths are not in the summary); the declared rate beside it in parentheses when the
    two differ by more than :data:`DECLARED_RATE_TOLERANCE`."""
    gapless = not channel.get("time_gaps")
    rate = channel.get("mean_rate_hz") if gapless and channel.get("mean_rate_hz") else channel.get("rate_hz")
    text = _fmt_rate(rate)
    declared = channel.get("declared_rate_hz")
    if rate and declared and abs(rate - declared) > DECLARED_RATE_TOLERANCE * declared:
        text += f" (declared {declared:.6g})"
    return text


def _echo_periods(metrics: dict) -> None:
    """Daily-life summaries of long recordings (``imulog.metrics`` by_day, else by_hour) as a small table."""
    key = "by_day" if isinstance(metrics.get("by_day"), list) else "by_hour"
    rows = metrics.get(key)
    if not isinstance(rows, list) or not rows:
        return
    click.echo(f"daily life ({'per day' if key == 'by_day' else 'per hour'}, from imulog.metrics):")
    click.echo("  start                      valid_h  arm_use_%  activities  distance_area")
    for r in rows[:48]:
        if not isinstance(r, dict):
            continue
        use = r.get("arm_use_percent")
        click.echo(
            f"  {str(r.get('start') or r.get('start_ns')):<26} {float(r.get('valid_s') or 0) / 3600:7.2f}  "
            f"{'-' if use is None else f'{float(use):9.2f}'}  {r.get('activity_count', ''):>10}  "
            f"{float(r.get('distance_weighted_area') or 0):13.1f}"
        )
    if len(rows) > 48:
        click.echo(f"  ... {len(rows) - 48} more (info --json lists all)")


def _echo_flags(metadata: dict) -> None:
    """One line per IMU: the repetitions to distrust and why (issue 31), from the trajectory step when it ran (it
    adds drift to event correction's reasons), else from the phases step. A setup's other IMUs have their records
    as ``imulog.timing.IMU`` / ``imulog.trajectory.IMU``; the IMU is named only when there are several."""
    from imulog.process.repetition_flags import flag_line, trial_flags

    lines = []
    for imu, timing, trajectory in _per_imu_records(metadata, "imulog.timing", "imulog.trajectory"):
        found = trial_flags(timing, trajectory)
        line = flag_line(*found) if found else ""
        if line:
            lines.append((imu, line))
    for imu, line in lines:
        click.echo(f"repetitions ({imu}): {line}" if len(lines) > 1 and imu else f"repetitions: {line}")


def _per_imu_records(metadata: dict, *bases: str) -> list[tuple[str, dict, dict]]:
    """``(imu, record of bases[0], record of bases[1], ...)`` for the unsuffixed records (the primary IMU's,
    named by their ``imu`` key) and every ``BASE.IMU`` record of another IMU; missing records are ``{}``."""
    others = sorted({key[len(base) + 1 :] for key in metadata for base in bases if key.startswith(base + ".")})
    primary = next((str(metadata[b].get("imu") or "") for b in bases if isinstance(metadata.get(b), dict)), "")
    rows = [(primary.removeprefix("/imu/"), *(metadata.get(b) or {} for b in bases))]
    rows += [(imu, *(metadata.get(f"{b}.{imu}") or {} for b in bases)) for imu in others]
    return rows


def _echo_phase_quality(timing: dict) -> None:
    """One line on what event correction did to the phases (imulog.timing, issue 19): forced phases are
    visible as forced."""
    quality = timing.get("repetition_quality") or []
    if not quality:
        return
    total = {k: sum(int(q.get(k) or 0) for q in quality) for k in ("merged", "dropped", "split", "missing")}
    corrected = sum(1 for q in quality if any(int(q.get(k) or 0) for k in total))
    low = timing.get("low_confidence_repetitions") or []
    click.echo(
        f"phases: {timing.get('n_phases', 0)} in {len(quality)} repetitions from {timing.get('n_movements', 0)} "
        f"movements; event correction changed {corrected} (merged {total['merged']}, dropped {total['dropped']}, "
        f"split {total['split']}, missing {total['missing']})"
    )
    low_text = ", ".join(map(str, low[:20])) + (f" +{len(low) - 20} more" if len(low) > 20 else "")
    click.echo(
        f"  {timing.get('n_forced_phases', 0)} forced phases; confidence mean {timing.get('mean_confidence')}, "
        f"low in repetitions {low_text or '-'}"
    )


def _echo_alignment(metadata: dict) -> None:
    """The IMU-to-Vicon alignment: offset and drift with uncertainty, markers, windows, quality flag; with several
    IMUs aligned (together or one at a time), one line per IMU from its own record."""
    from imulog.archive.alignment_records import alignments_from_metadata
    from imulog.steps.align_summary import alignment_summary, setup_lines, setup_summary

    record = dict(metadata.get("imulog.alignment") or {})
    per_imu = alignments_from_metadata(metadata, failed=True)
    if len(per_imu) > 1:  # each IMU's own record, current whichever way it was aligned
        record["setup"] = setup_summary(per_imu)
    if not record:
        return
    if record.get("setup"):  # several IMUs aligned: one line per IMU, then the clocks
        aligned = [r for r in per_imu.values() if "offset_ns" in r] or [record]
        refs = sorted({str(r["reference"]) for r in aligned if r.get("reference")})  # (a recording's clock: none)
        n = len(record["setup"])
        count = f"{len(aligned)} of {n}" if per_imu and len(aligned) < n else str(n)
        click.echo(f"alignment ({count} IMUs on {', '.join(refs)}):")
        for line in setup_lines(record):
            click.echo(f"  {line}")
        return
    lines = alignment_summary(record)
    if lines:
        click.echo(f"alignment ({record.get('imu', '?')} on {record.get('reference', '?')}): {lines[0]}")
        for line in lines[1:]:
            click.echo(f"  {line}")


def _echo_heading(record: dict, channels: list[dict[str, Any]]) -> None:
    """Whether the oriented IMUs share one heading frame (``imulog process heading``); with several
    orientations and no record, that their headings are not related yet."""
    oriented = [c["topic"].rsplit("/", 1)[1] for c in channels if c["topic"].startswith("/derived/orientation/")]
    if not record:
        if len(oriented) > 1:
            click.echo(
                f"heading: not related between {', '.join(oriented)} (no imulog.heading record: "
                "run `imulog process heading`)"
            )
        return
    names = ", ".join(record.get("imus") or {})
    left = [n for n in oriented if n not in (record.get("imus") or {})]
    if left:
        click.echo(f"heading: {', '.join(left)} oriented but not in imulog.heading (run `imulog process heading`)")
    if record.get("source") == "none":
        click.echo(f"heading: not related between {names}: " + "; ".join(record.get("rejected") or []))
    else:
        click.echo(f"heading: one frame for {names}: {record.get('source')} ({record.get('frame')})")


def gyro_correction_lines(entries: Any) -> list[str]:
    """What ``--backend vqf_gyrocal`` recorded in a run (``gyro_correction``), for reading: per run of samples (and
    window core) whether ``M`` was fitted, ``M`` itself (true rate = ``M @ (gyr - bias)``), the sensitivity error
    of each axis and the largest cross-axis term (``M - I``, %), and the bias it turns about (deg/s)."""
    import numpy as np

    lines = []
    for e in entries if isinstance(entries, list) else []:
        if not isinstance(e, dict):
            continue
        where = "samples {}-{}".format(*e["samples"]) if len(e.get("samples") or []) == 2 else "the run"
        if len(e.get("core") or []) == 2:
            where += " (core {}-{})".format(*e["core"])
        try:
            m = np.asarray(e["matrix"], dtype=np.float64).reshape(3, 3)
            bias = np.degrees(np.asarray(e["bias_rad_s"], dtype=np.float64).reshape(3))
        except (KeyError, TypeError, ValueError):
            lines.append(f"gyro correction over {where}: {json.dumps(e)}")
            continue
        fitted = "fitted" if e.get("fitted") else "not fitted (shorter than the fit needs): M is the identity"
        lines.append(f"gyro correction over {where}: {fitted}")
        rows = "; ".join(" ".join(f"{v:+.5f}" for v in row) for row in m)
        lines.append(f"  M = [{rows}] (true rate = M (gyr - bias))")
        scale = ", ".join(f"{a} {(m[i, i] - 1) * 100:+.2f} %" for i, a in enumerate("xyz"))
        cross = np.abs(m - np.diag(np.diag(m))).max() * 100
        lines.append(
            f"  sensitivity {scale}; largest cross-axis term {cross:.2f} %; bias "
            + ", ".join(f"{v:+.3f}" for v in bias)
            + " deg/s"
        )
    return lines


def _echo_wrapped(text: str, width: int | None) -> None:
    """``text`` on lines of at most ``width`` characters (continuations indented); as is when None."""
    import textwrap

    click.echo(text if width is None else textwrap.fill(text, width, subsequent_indent="    "))


def _cut(text: str, width: int | None) -> str:
    return text if width is None or len(text) <= width else text[: width - 3] + "..."


def _channel_row(c: dict[str, Any]) -> tuple[str, ...]:
    """One row of the channels table; a channel without samples (salvaged, interrupted) shows only that."""
    salvaged = str(c["metadata"].get("salvaged", ""))
    topic = (
        c["topic"]
        + (" [out of date]" if c["out_of_date"] else "")
        + (" [assumptions failed]" if c["metadata"].get("assumptions") == "failed" else "")
    )
    if salvaged:
        topic += f" [{salvaged.split(':', 1)[0]}]"
    if not c["samples"]:
        return (topic + " [empty]", c["schema"], "-", "0", "-", "-", f"{c['stored_bytes'] / 1e6:.2f}", "-")
    gaps = f"{c['time_gaps'] if c['time_gaps'] is not None else '-'}/{c['nan_samples'] if c['nan_samples'] is not None else '-'}"
    dur = "-" if c["duration_s"] is None else f"{c['duration_s']:.3f}"
    return (
        topic,
        c["schema"],
        shown_rate(c),
        str(c["samples"]),
        dur,
        gaps,
        f"{c['stored_bytes'] / 1e6:.2f}",
        _fmt_units(c["units"]),
    )


@click.command()
@click.argument("file", type=click.Path(exists=True))
@click.option("-v", "--verbose", is_flag=True, help="also every run's parameters, the viewer twins, full metadata")
@click.option("--json", "as_json", is_flag=True, help="print one JSON document (for scripts)")
def info(file: str, verbose: bool, as_json: bool) -> None:
    """Show a trial's channels, metadata, attachments and derived runs (compact; -v for everything).

    For every channel: schema, rate (Hz: samples per second, (samples - 1) / duration, or with time gaps
    1 / the median sample step; the device's declared rate beside it when they differ by more than 1 %),
    sample count, duration, gaps (time gaps longer than 1.5 sample periods / samples with NaN), stored
    (compressed) size, units and frame. A salvaged channel
    says [partial] (chunks were lost) and a channel with no samples [empty] (no rate, duration or
    gaps). Derived channels whose inputs (channels or metadata records such as imulog.alignment)
    changed since they were computed are marked out of date, with the command that recomputes them.
    By default the viewer twins (/derived/viewer/...) are one line, metadata records one line each
    (cut at 110 characters) and runs one line without their parameters; -v lists them all in full.
    Reads only the summary and the metadata records (fast on any trial size).

    \b
    Examples:
      imulog info trial.mcap
      imulog info trial.mcap -v          # every run's parameters, the viewer twins
      imulog info trial.mcap --json | python -c "import json,sys; print(json.load(sys.stdin)['channels'][0])"
      imulog catalog archive/ -o catalog.parquet   # a folder of trials: one row each (docs/batch.md)
    """
    if os.path.isdir(file):  # a study's folder: the catalog is the command for it
        raise click.UsageError(
            f"{file} is a folder; info shows one trial (imulog info {os.path.join(file, 'TRIAL.mcap')}); for "
            f"every trial of a folder, one row each: imulog catalog {file} -o catalog.parquet"
        )
    with open_trial(file) as trial:
        try:
            data = trial_summary(trial)
        except ArchiveError as exc:
            raise click.ClickException(str(exc)) from None
    if as_json:
        click.echo(json.dumps(data, indent=2, default=str))
        return
    width = None if verbose else 110
    click.echo(f"{data['path']}  ({data['bytes'] / 1e6:.2f} MB)")
    click.echo("channels:")
    twins = [c for c in data["channels"] if c["metadata"].get("twin_of") or c["topic"].startswith("/derived/viewer/")]
    shown = data["channels"] if verbose else [c for c in data["channels"] if c not in twins]
    rows = [("topic", "schema", "rate_hz", "samples", "duration_s", "gaps(t/nan)", "MB", "units")]
    rows += [_channel_row(c) for c in shown]
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for r in rows:
        click.echo("  " + "  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip())
    if twins and not verbose:
        mb = sum(c["stored_bytes"] for c in twins) / 1e6
        click.echo(f"  + {len(twins)} viewer twins under /derived/viewer/ ({mb:.2f} MB; -v lists them)")
    from imulog.archive.timeline import TrialAxis

    _echo_wrapped(f"time axis (MCAP log time): {TrialAxis(data['metadata']).describe()}", width)
    click.echo("metadata:")
    for name, values in data["metadata"].items():
        text = ", ".join(f"{k}={v}" if isinstance(v, str) else f"{k}={json.dumps(v)}" for k, v in values.items())
        click.echo(_cut(f"  {name}: {text}", width))
    _echo_periods(data["metadata"].get("imulog.metrics") or {})
    _echo_alignment(data["metadata"])
    _echo_heading(data["metadata"].get("imulog.heading") or {}, data["channels"])
    _echo_phase_quality(data["metadata"].get("imulog.timing") or {})
    _echo_flags(data["metadata"])
    failed = [c for c in data["channels"] if c["metadata"].get("assumptions") == "failed"]
    if failed:  # trajectories whose method does not apply to this recording (issue 32)
        click.echo("assumptions failed:")
        for c in failed:
            click.echo(f"  {c['topic']}: {c['metadata'].get('assumptions_why', '')}")
    if data["attachments"]:
        click.echo("attachments:")
        for a in data["attachments"]:
            digest = (a["sha256"] or "-")[:16]
            click.echo(f"  {a['name']}  {a['media_type']}  {a['bytes']} bytes  sha256 {digest}")
    if data["runs"]:
        click.echo("derived runs:" + ("" if verbose else " (-v: their parameters)"))
        for n, r in data["runs"].items():
            outputs = list(r.get("outputs", {}))
            out = ", ".join(outputs) or "-"
            if not verbose and len(outputs) > 3:
                out = f"{', '.join(outputs[:3])} +{len(outputs) - 3} more"
            params = f" params={json.dumps(r.get('params', {}))}" if verbose else ""
            line = f"  #{n} {r.get('step', '')}: {r.get('algorithm', '')}{params} -> {out} ({r.get('time', '')})"
            click.echo(_cut(line, None if verbose else 160))
            if verbose:
                for extra in gyro_correction_lines(r.get("gyro_correction")):
                    click.echo(f"      {extra}")
    if data["out_of_date"] or data["out_of_date_steps"]:
        click.echo("out of date (inputs changed since they were computed):")
        by_step: dict[str, list[str]] = {}
        for c in data["channels"]:
            if c["out_of_date"]:
                by_step.setdefault(c["out_of_date"]["step"], []).append(c["topic"])
        for step, topics in by_step.items():
            reasons = next(c["out_of_date"]["reasons"] for c in data["channels"] if c["topic"] == topics[0])
            click.echo(f"  {', '.join(topics)}: {'; '.join(reasons)} -> rerun {rerun_command(step)}")
        for step, v in data["out_of_date_steps"].items():
            if step not in by_step:  # steps that wrote only metadata records (evaluate, ...)
                click.echo(f"  step {step} (run #{v['run']}): {'; '.join(v['reasons'])} -> rerun {v['rerun']}")
