"""``imulog process epochs``: ENMO, MAD, ActiGraph counts and wear per epoch, hourly and daily totals."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from imulog.commands.imus import imu_option, step_record
from imulog.steps.epochs import EpochParams

_D = EpochParams()


def format_summary(r: dict[str, Any]) -> str:
    """Human-readable summary of an ``imulog.epochs`` record ``r``."""
    cal = r["calibration"]
    worn = sum(row["wear_h"] for row in r["by_day"])
    recorded = sum(row["recorded_h"] for row in r["by_day"])
    lines = [
        f"{r['imu']}: {r['duration_s'] / 3600:.2f} h at {r['rate_hz']:g} Hz, epochs {', '.join(f'{e:g} s' for e in r['epochs_s'])}",
        "  calibration: "
        + (
            f"offset {cal['offset_g']} g, scale {cal['scale']}, error {cal['error_before_mg']} -> "
            f"{cal['error_after_mg']} mg ({cal['still_epochs']} still epochs)"
            if cal["applied"]
            else f"not applied ({cal['reason']})"
        ),
        f"  worn {worn:.2f} of {recorded:.2f} h; {len(r['nonwear'])} non-wear period(s); "
        f"{r['valid_days']} valid day(s) of {len(r['by_day'])}",
        f"  counts: {r['counts']}",
    ]
    for row in r["by_day"]:
        enmo = "-" if row["enmo_mean_mg"] is None else f"{row['enmo_mean_mg']:.1f}"
        lines.append(
            f"  day {row['start'] or row['start_ns']}: worn {row['wear_h']:.2f} h, ENMO {enmo} mg, counts VM {row['counts_vm_sum']:.0f}"
            + ("" if row["valid"] else "  (not valid)")
        )
    return "\n".join(lines)


@click.command("epochs")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@imu_option()
@click.option(
    "--epoch-s",
    "epochs_s",
    type=float,
    multiple=True,
    default=_D.epochs_s,
    show_default=True,
    help="Epoch length in seconds, repeatable (given ones replace the default).",
)
@click.option("--no-calibrate", is_flag=True, help="Do not fit the auto-calibration to local gravity.")
@click.option(
    "--valid-day-hours", type=float, default=_D.valid_day_hours, show_default=True, help="Worn hours for a valid day."
)
@click.option("--force", is_flag=True, help="Recompute even when up to date.")
@click.option("--json", "as_json", is_flag=True, help="Print the imulog.epochs record as JSON.")
def process_epochs(
    trial: Path,
    imus: tuple[str, ...],
    epochs_s: tuple[float, ...],
    no_calibrate: bool,
    valid_day_hours: float,
    force: bool,
    as_json: bool,
) -> None:
    """Epoch summaries of TRIAL's accelerometer, appended as /derived/epochs/Es/IMU (docs/epochs.md).

    \b
    Per epoch (default 5 s and 60 s): ENMO and MAD in g after auto-calibration to local gravity (van Hees 2014),
    ActiGraph counts per axis and vector magnitude (Brønd 2017), non-wear (van Hees 2013: 60-min windows in
    15-min blocks, SD < 13 mg or range < 50 mg on 2 of 3 axes). The record imulog.epochs holds the calibration,
    the non-wear periods and hourly and daily totals with the valid-day rule (hours worn).

    \b
    Examples:
      imulog process epochs week.mcap
      imulog process epochs week.mcap --epoch-s 30 --valid-day-hours 10 --json
      imulog export week.mcap -t /derived/epochs/60s/ax6_4321 -o epochs.csv
    """
    from dataclasses import replace

    from imulog.commands.imus import choose_imus, run_per_imu
    from imulog.steps.epochs import RECORD, run_epochs

    params = replace(
        _D, epochs_s=tuple(epochs_s) or _D.epochs_s, calibrate=not no_calibrate, valid_day_hours=valid_day_hours
    )
    names = choose_imus(trial, imus, needs=("acc",))
    records: dict[str, dict] = {}

    def one(name: str):
        outcome = run_epochs(trial, imu=name, params=params, force=force)
        record = records[name] = step_record(trial, RECORD, name)
        text = format_summary(record)
        return outcome, text.splitlines()[0], text

    if as_json:  # the record(s) only: one IMU's record, or {imu: record}
        run_per_imu(trial, names, one, what="epochs", echo=False)
        click.echo(json.dumps(records[names[0]] if len(names) == 1 else records, indent=2))
        return
    run_per_imu(trial, names, one, what="epochs")
