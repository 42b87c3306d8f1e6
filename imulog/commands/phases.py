"""``imulog process phases``: segment movements, R2G phases and zero-velocity intervals."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import click

from imulog.commands.imus import imu_option, step_record
from imulog.commands.option_fields import option_fields
from imulog.process.segmentation.pipeline import METHODS, PROTOCOLS, PhaseParams

_D = PhaseParams()  # the one source of defaults (tests/test_cli_defaults.py); protocol/repetitions: the trial's


def _threshold(value: str) -> float | str:
    if value.lower() == "otsu":
        return "otsu"
    try:
        fraction = float(value)
    except ValueError:
        raise click.BadParameter(f"{value!r} is neither 'otsu' nor a number") from None
    if not 0 < fraction < 1:
        raise click.BadParameter(f"threshold fraction must lie in (0, 1), got {value}")
    return fraction


MAX_ROWS = 40  # phases printed one per line up to this; beyond, the first and last ones and a count
TAIL_ROWS = 10


def format_summary(timing: dict) -> str:
    """Human-readable timing table (one line per phase, the first and last ones beyond :data:`MAX_ROWS`) plus
    per-label mean durations (over every phase)."""
    if timing.get("protocol", "r2g") == "r2g":
        found = (
            f"{timing['n_movements']} movements -> {timing['n_phases']} phases in {timing['n_repetitions']} "
            f"repetitions ({timing['n_corrected_repetitions']} corrected)"
        )
    else:
        found = f"{timing['n_movements']} movements (no task protocol: each movement is a phase)"
    head = (
        f"{timing['imu']}: {found}, method {timing['method']}, {timing['clock']} clock, "
        f"static {100 * timing['static_fraction']:.1f} %"
    )
    if "phases" not in timing or "computed" in timing:  # read window by window: summaries, no row per phase
        return "\n".join([head, *format_long_summary(timing)])
    lines = [head, f"{'rep':>4} {'phase':<14} {'start s':>9} {'end s':>9} {'dur s':>7} {'peak rad/s':>10}"]
    by_label: dict[str, list[float]] = {}
    rows = timing["phases"]
    head_rows = rows if len(rows) <= MAX_ROWS else rows[: MAX_ROWS - TAIL_ROWS]
    for k, row in enumerate(rows):
        by_label.setdefault(row["label"], []).append(row["duration_s"])
        if k < len(head_rows) or k >= len(rows) - TAIL_ROWS:
            if len(rows) > MAX_ROWS and k == len(rows) - TAIL_ROWS:
                lines.append(
                    f"   ... {len(rows) - len(head_rows) - TAIL_ROWS} more phases (all of them: imulog export TRIAL "
                    f"--topic /derived/phases/{timing['imu'].rsplit('/', 1)[-1]} -o phases.csv)"
                )
            lines.append(
                f"{row['repetition']:>4} {row['label']:<14} {row['start_s']:>9.3f} {row['end_s']:>9.3f} "
                f"{row['duration_s']:>7.3f} {row['peak_angular_velocity_rad_s']:>10.3f}"
                + ("  forced" if row.get("forced") else "")
            )
    for label, durations in by_label.items():
        mean = sum(durations) / len(durations)
        lines.append(f"mean {label:<14} duration {mean:.3f} s over {len(durations)}")
    low = timing.get("low_confidence_repetitions") or []
    if timing.get("repetition_quality"):  # what event correction did (issue 19)
        shown = ", ".join(map(str, low[:20])) + (f" +{len(low) - 20} more" if len(low) > 20 else "")
        lines.append(
            f"event correction: {timing.get('n_forced_phases', 0)} forced phases, confidence mean "
            f"{timing.get('mean_confidence')}, below 0.5 in repetitions {shown or '-'}"
        )
    from imulog.process.repetition_flags import flag_line

    flagged = flag_line(timing.get("flagged_repetitions") or [], int(timing.get("n_repetitions") or 0))
    if flagged:  # one line (issue 31): which repetitions' phases to check, and why
        lines.append(f"{flagged}; check them in imulog view (process trajectory adds drift to the reasons)")
    return "\n".join(lines)


def format_long_summary(timing: dict) -> list[str]:
    """Lines for a record computed core by core: durations, their histogram, phases per hour and per day."""
    d = timing.get("phase_durations") or {}
    lines = [f"computed {timing.get('computed', 'core by core')}"]
    if d.get("n"):
        lines.append(
            f"phase durations: median {d['median_s']:.2f} s (10-90 %: {d['p10_s']:.2f}-{d['p90_s']:.2f} s), "
            f"longest {d['max_s']:.1f} s, total {d['total_s'] / 60:.1f} min"
        )
        hist = d.get("histogram") or {}
        edges, counts = hist.get("bin_edges_s") or [], hist.get("counts") or []
        cells = [
            f"{lo:g}-{hi:g} s: {n}" if hi is not None else f">{lo:g} s: {n}"
            for lo, hi, n in zip(edges[:-1], edges[1:], counts, strict=False)
            if n
        ]
        lines.append("durations: " + ", ".join(cells))
    for key, name in (("by_day", "day"), ("by_hour", "hour")):
        rows = timing.get(key) or []
        if rows and (key == "by_day" or len(rows) <= 48):
            per = ", ".join(f"{(r['start'] or str(r['start_s']) + ' s')[:16]}: {r['phases']}" for r in rows)
            lines.append(f"phases per {name}: {per}")
    return lines


def _protocol_from_trial(trial: Path) -> tuple[str, int]:
    """(protocol, repetitions) from the trial's ``imulog.trial`` record (see ``steps.phases.protocol_of``)."""
    from imulog.archive import ArchiveError, TrialReader
    from imulog.steps.phases import protocol_of

    try:
        with TrialReader(trial) as reader:
            record = reader.metadata.get("imulog.trial", {})
    except (ArchiveError, OSError):  # unreadable trial: run_phases reports it with its own message
        record = {}
    try:
        return protocol_of(record)
    except ValueError as exc:
        raise click.ClickException(f"{trial}: {exc}") from None


@option_fields(
    repetitions="RepetitionParams.n_repetitions",
    phases_per_repetition="RepetitionParams.n_phases",
    static_method="PhaseParams.static",
    static_threshold="GyroNormStaticParams.threshold_rad_s",
)
@click.command("phases")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@imu_option()
@click.option("--method", type=click.Choice(METHODS), default=_D.method, show_default=True)
@click.option(
    "--threshold",
    default=str(_D.dynamos.threshold),
    show_default=True,
    help="DynAMoS threshold: 'otsu' or a fraction of the max.",
)
@click.option(
    "--repetitions",
    type=int,
    default=None,
    help="R2G repetitions in the trial (0 = infer). Default: the trial record's 'repetitions', else 25.",
)
@click.option(
    "--protocol",
    type=click.Choice(PROTOCOLS),
    default=None,
    help="r2g: drinking-task phases per repetition; movements: every movement is a phase. "
    "Default: r2g when the trial record's task is r2g, else movements.",
)
@click.option("--phases-per-repetition", type=int, default=_D.repetitions.n_phases, show_default=True)
@click.option("--alpha", type=float, default=_D.dynamos.alpha, show_default=True, help="DynAMoS short-movement factor.")
@click.option("--beta", type=float, default=_D.dynamos.beta, show_default=True, help="DynAMoS long-movement factor.")
@click.option(
    "--cutoff-hz",
    type=float,
    default=_D.dynamos.cutoff_hz,
    show_default=True,
    help="Low-pass cut-off of the gyroscope.",
)
@click.option("--no-refine", is_flag=True, help="Keep the raw DynAMoS threshold crossings as onsets/offsets.")
@click.option(
    "--static",
    "static_method",
    type=click.Choice(["movements", "gyro-norm"]),
    default=_D.static,
    show_default=True,
    help="Zero-velocity mask: complement of the movements, or the gyro-norm baseline detector.",
)
@click.option(
    "--static-threshold",
    type=float,
    default=_D.gyro_norm.threshold_rad_s,
    show_default=True,
    help="gyro-norm threshold, rad/s.",
)
@click.option("--force", is_flag=True, help="Recompute even when the same parameters are already recorded.")
@click.option("--quiet", is_flag=True, help="Print only the one-line summary.")
def process_phases(
    trial: Path,
    imus: tuple[str, ...],
    method: str,
    threshold: str,
    repetitions: int | None,
    protocol: str | None,
    phases_per_repetition: int,
    alpha: float,
    beta: float,
    cutoff_hz: float,
    no_refine: bool,
    static_method: str,
    static_threshold: float,
    force: bool,
    quiet: bool,
) -> None:
    """Segment movements and R2G phases, append them to TRIAL and print the timing table.

    Writes /derived/movements/IMU, /derived/phases/IMU (R2G trials: reach, lift, return_bottle,
    return_hand with task_index = repetition; other tasks: one phase 'movement' per movement),
    /derived/static/IMU (1 = zero velocity) and the metadata record imulog.timing (per phase: start,
    end, duration s, peak angular velocity rad/s; imulog.timing.IMU for IMUs other than the trial's
    primary one). Every IMU is segmented when no --imu is given, one run each, with one summary table.
    Running twice with the same options changes nothing.

    \b
    Examples:
      imulog process phases trial.mcap
      imulog process phases trial.mcap --threshold otsu --repetitions 25
      imulog process phases trial.mcap --method double-threshold --static gyro-norm
      imulog process phases slide.mcap --method template --repetitions 30 --phases-per-repetition 1
      imulog process phases walk.mcap --protocol movements --static gyro-norm
    """
    from imulog.commands.imus import choose_imus, run_per_imu
    from imulog.steps.phases import run_phases

    thr = _threshold(threshold)
    recorded_protocol, recorded_repetitions = _protocol_from_trial(trial)
    protocol = protocol or recorded_protocol
    repetitions = recorded_repetitions if repetitions is None else repetitions
    if alpha <= 0 or beta <= alpha:
        raise click.ClickException(f"need 0 < alpha < beta, got alpha={alpha}, beta={beta}")
    params = replace(
        _D,
        method=method,
        protocol=protocol,
        dynamos=replace(
            _D.dynamos, threshold=thr, alpha=alpha, beta=beta, cutoff_hz=cutoff_hz, refine_boundaries=not no_refine
        ),
        repetitions=replace(_D.repetitions, n_repetitions=repetitions, n_phases=phases_per_repetition),
        static=static_method,
        gyro_norm=replace(_D.gyro_norm, threshold_rad_s=static_threshold),
    )

    def one(name: str):
        outcome = run_phases(trial, imu=name, params=params, force=force)
        timing = step_record(trial, "imulog.timing", name)
        text = format_summary(timing)
        if quiet:
            text = text.splitlines()[0]
        skipped = getattr(outcome, "skipped", False)
        return outcome, text.splitlines()[0], ("(unchanged: same inputs and parameters) " if skipped else "") + text

    run_per_imu(trial, choose_imus(trial, imus, needs=("gyr",)), one, what="phases")
