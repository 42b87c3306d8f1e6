"""``imulog process heading``: one heading frame for the IMUs of a trial."""

from __future__ import annotations

import json
from pathlib import Path

import click


def _pose(value: str | None) -> tuple[float, float] | None:
    if not value:
        return None
    try:
        a, b = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter("give START,END in seconds, e.g. 0.5,2.5") from None
    if b <= a:
        raise click.BadParameter("END must be after START")
    return a, b


@click.command("heading")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--imu", "imus", multiple=True, help="IMU (repeatable); default: every oriented IMU.")
@click.option(
    "--static-pose",
    default=None,
    help="START,END (s from the start) of a pose in which every sensor's x axis faces the same way "
    "(used when neither the magnetometers nor the optical clusters relate the headings).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the imulog.heading record as JSON.")
@click.option("--force", is_flag=True, help="Recompute even when up to date.")
def process_heading(trial: Path, imus: tuple[str, ...], static_pose: str | None, as_json: bool, force: bool) -> None:
    """Relate the headings of the oriented IMUs of TRIAL: one global frame for all.

    Each orientation is z-up, its heading magnetic north (9D) or arbitrary (6D). The common frame comes from
    the magnetometers when their field is steady and the same for every IMU, else from the optical clusters
    (run `imulog process align` after `imulog process orientation`), else from a declared static pose; when
    none applies the record says the headings do not relate, and exports that combine IMUs warn. Stores
    imulog.heading: the source, and per IMU the correction from its global frame to the common one.

    \b
    Examples:
      imulog process heading trial.mcap
      imulog process heading trial.mcap --static-pose 0.5,2.5
    """
    from imulog.archive.errors import ArchiveError
    from imulog.steps.common import error_line
    from imulog.steps.heading import run_heading

    try:
        outcome, rec = run_heading(trial, imus=list(imus) or None, static_s=_pose(static_pose), force=force)
    except (ArchiveError, ValueError, KeyError, OSError) as exc:
        raise click.ClickException(error_line(trial, exc)) from None
    if as_json:
        click.echo(json.dumps(rec, indent=1, default=float))
        return
    prefix = "unchanged (same inputs and parameters): " if outcome.skipped else ""
    names = ", ".join(rec.get("imus") or {})
    if rec.get("source") == "none":
        click.echo(f"{trial}: {prefix}no common heading for {names}: each IMU keeps its own")
    else:
        click.echo(f"{trial}: {prefix}one heading frame for {names}: {rec.get('source')} ({rec.get('frame')})")
    for why in rec.get("rejected") or []:
        click.echo(f"  not used: {why}")
    if rec.get("note"):
        click.echo(f"  {rec['note']}")
