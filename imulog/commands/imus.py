"""Every IMU of a trial by default: the ``--imu`` option and the loop the per-IMU commands share.

A per-IMU command (calibrate, orientation, phases, metrics, epochs) runs its step once per IMU, one provenance
run each (``orientation:left_foot``), on every IMU of the trial when ``--imu`` is not given (``--imu NAME`` is
repeatable to choose), and prints one summary table. A trial with one IMU prints what the command always printed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

IMU_HELP = "IMU to process (channel /imu/NAME), repeatable; default: every IMU of the trial, one run each."


def imu_option(help_text: str = IMU_HELP) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``--imu NAME`` (repeatable) into the command's ``imus`` parameter (a tuple, empty when not given)."""
    return click.option("--imu", "imus", multiple=True, metavar="NAME", help=help_text)


def choose_imus(
    trial: Path, imus: Sequence[str], *, prefix: str = "/imu/", missing_hint: str = "", needs: Sequence[str] = ()
) -> list[str]:
    """The IMUs to process: those named (each must have a ``{prefix}NAME`` channel), else every one the trial has.

    ``needs``: the quantities the step reads (``acc``, ``gyr``); by default, IMUs whose channel lacks one (an
    ActiGraph's accelerometer-only stream beside its IMU) are left out with a note on stderr. Raises
    ``click.ClickException`` with one line naming the trial when a name matches no IMU or none is left.
    """
    import json

    from imulog.archive import ArchiveError, TrialReader
    from imulog.steps.common import error_line, imu_names, pick_imu

    try:
        with TrialReader(trial) as reader:
            topics = reader.topics()
            columns = {
                c.topic: json.loads(c.metadata.get("columns") or "null") for c in reader.channels if c.topic in topics
            }
        if imus:
            return [pick_imu(topics, name, prefix=prefix, missing_hint=missing_hint) for name in dict.fromkeys(imus)]
        names = imu_names(topics, prefix)
        if not names:
            pick_imu(topics, None, prefix=prefix, missing_hint=missing_hint)  # raises the step's own message
        lacking = {}
        for name in names:
            have = columns.get(f"/imu/{name}")
            missing = [q for q in needs if isinstance(have, list) and q not in have]
            if missing:
                lacking[name] = missing
        if lacking and len(lacking) < len(names):
            for name, missing in lacking.items():
                click.echo(f"note: left out /imu/{name}: no {', '.join(missing)} (name it with --imu to try)", err=True)
            names = [n for n in names if n not in lacking]
        return names
    except (ArchiveError, ValueError, OSError) as exc:
        raise click.ClickException(error_line(trial, exc)) from None


@dataclass
class ImuRun:
    """What one IMU's step did: ``status`` wrote / unchanged / failed, the run number, a short result."""

    imu: str
    status: str
    run: int | None = None
    result: str = ""
    text: str = ""  # what the command prints for a single IMU


StepCall = Callable[[str], tuple[Any, str, str]]
"""``call(imu) -> (outcome, short result for the table, full text for a single IMU)``; raises on failure."""

ERRORS: tuple[type[BaseException], ...] = (ValueError, KeyError, OSError, RuntimeError)


def run_per_imu(trial: Path, names: Sequence[str], call: StepCall, *, what: str, echo: bool = True) -> list[ImuRun]:
    """Run ``call`` on each IMU of ``names`` and print the result.

    One IMU: its text, or its error as the command's one-line error. Several: one table (imu, status, run,
    result); an IMU that fails is a row with its reason, the others still run, and the command then exits
    non-zero naming how many failed. ``what`` names the step in the table's title; ``echo=False`` prints nothing
    (``--json`` prints the records instead) but still fails the same way.
    """
    from imulog.archive import ArchiveError
    from imulog.steps.common import error_line

    rows: list[ImuRun] = []
    for name in names:
        try:
            outcome, result, text = call(name)
        except (ArchiveError, *ERRORS) as exc:
            if len(names) == 1:
                raise click.ClickException(error_line(trial, exc)) from None
            rows.append(ImuRun(name, "failed", None, str(exc).removeprefix(f"{trial}: ")))
            continue
        skipped = bool(getattr(outcome, "skipped", False))
        rows.append(ImuRun(name, "unchanged" if skipped else "wrote", getattr(outcome, "run", None), result, text))
    if len(names) == 1:
        if echo:
            click.echo(rows[0].text)
        return rows
    if echo:
        click.echo(f"{what}: {len(names)} IMUs of {trial}")
        for line in table_lines(rows):
            click.echo(line)
    failed = [r.imu for r in rows if r.status == "failed"]
    if failed:
        raise click.ClickException(f"{trial}: {len(failed)} of {len(rows)} IMUs failed: {', '.join(failed)}")
    return rows


def step_record(trial: Path, base: str, imu: str) -> dict[str, Any]:
    """The record a per-IMU step wrote for ``imu`` (``base``, or ``base.IMU``: :func:`imulog.steps.common.record_for`)."""
    from imulog.archive import TrialReader
    from imulog.steps.common import record_of

    with TrialReader(trial) as reader:
        name = record_of(base, imu, reader.metadata)
        record = reader.metadata.get(name) if name else None
    if record is None:
        raise KeyError(f"no {base} record for /imu/{imu} after the step")
    return dict(record)


def table_lines(rows: Sequence[ImuRun]) -> list[str]:
    """The summary table: one line per IMU, columns padded to their widest cell."""
    cells = [("imu", "status", "run", "result")] + [
        (r.imu, r.status, "" if r.run is None else str(r.run), r.result) for r in rows
    ]
    widths = [max(len(c[k]) for c in cells) for k in range(3)]
    return ["  " + "  ".join(c[k].ljust(widths[k]) for k in range(3)) + "  " + c[3] for c in cells]
