"""``imulog process trajectory`` and ``imulog evaluate``: IMU trajectories and their error against Vicon."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import click

from imulog.commands.option_fields import option_fields
from imulog.params import ParamError
from imulog.process.trajectory_accelerometer import ACCELEROMETERS, accelerometer_of, with_accelerometer
from imulog.process.trajectory_opt import METHODS, TrajectoryParams

DEFAULT_METHODS = ",".join(METHODS)
_D = TrajectoryParams()  # the one source of defaults (tests/test_cli_defaults.py)


def _methods(value: str) -> list[str]:
    names = [m.strip() for m in value.split(",") if m.strip()]
    bad = [m for m in names if m not in METHODS]
    if bad or not names:
        raise click.BadParameter(f"unknown method(s) {', '.join(bad) or '(none)'}; choose from {', '.join(METHODS)}")
    return names


@option_fields(
    highpass_hz="HighpassParams.cutoff_hz",
    wavelet_level="WaveletParams.level",
    kalman_alpha="KalmanParams.alpha",
    kalman_q="KalmanParams.process_var_m2ps4",
    sigma_ref="OptimizationParams.sigma_ref_static_m",
    sigma_data="OptimizationParams.sigma_data_mps",
)
@click.command("trajectory")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--imu",
    "imus",
    multiple=True,
    metavar="NAME",
    help="IMU (uses /derived/acc_global/NAME), repeatable; default: every oriented IMU with phases, one run each.",
)
@click.option(
    "--method",
    "methods",
    default=DEFAULT_METHODS,
    show_default=True,
    help="Comma-separated methods: " + ", ".join(METHODS) + ".",
)
@click.option(
    "--highpass-hz",
    type=float,
    default=_D.highpass.cutoff_hz,
    show_default=True,
    help="High-pass cut-off (Bai et al.).",
)
@click.option(
    "--wavelet", default=_D.wavelet.wavelet, show_default=True, help="Wavelet for drift removal (Bai et al.)."
)
@click.option(
    "--wavelet-level",
    type=int,
    default=_D.wavelet.level,
    show_default=True,
    help="Decomposition level (trend: top 2 details + A).",
)
@click.option(
    "--kalman-alpha", type=float, default=_D.kalman.alpha, show_default=True, help="AR(1) coefficient (Doshi)."
)
@click.option(
    "--kalman-q",
    type=float,
    default=_D.kalman.process_var_m2ps4,
    show_default=True,
    help="AR(1) process variance, (m/s^2)^2.",
)
@click.option("--no-smoother", is_flag=True, help="Kalman: forward filter only (no RTS smoother).")
@click.option("--no-zero-velocity", is_flag=True, help="Kalman: no zero-velocity pseudo-measurements.")
@click.option(
    "--sigma-ref",
    type=float,
    default=_D.optimized.sigma_ref_static_m,
    show_default=True,
    help="Optimisation: reference distance while still, m.",
)
@click.option(
    "--sigma-data",
    type=float,
    default=_D.optimized.sigma_data_mps,
    show_default=True,
    help="Optimisation: trust in ZUPT velocity, m/s.",
)
@click.option(
    "--no-return-to-start", is_flag=True, help="Optimisation: drop the return-to-start constraint (default: z only)."
)
@click.option(
    "--accelerometer",
    type=click.Choice(ACCELEROMETERS),
    default=accelerometer_of(_D),
    show_default=True,
    help="recorded: the orientation step's acceleration; rests: the accelerometer's bias and sensitivity from the "
    "trial's own rests, the orientation filter re-run on it and the twelfth round's options with it (an option, "
    "docs/trajectory.md; one window, at most 30 min).",
)
@click.option("--force", is_flag=True, help="Recompute even when the same parameters are already recorded.")
def process_trajectory(
    trial: Path,
    imus: tuple[str, ...],
    methods: str,
    highpass_hz: float,
    wavelet: str,
    wavelet_level: int,
    kalman_alpha: float,
    kalman_q: float,
    no_smoother: bool,
    no_zero_velocity: bool,
    sigma_ref: float,
    sigma_data: float,
    no_return_to_start: bool,
    accelerometer: str,
    force: bool,
) -> None:
    """Reconstruct the wrist trajectory with one or more methods; one /derived/trajectory/METHOD each.

    Needs the orientation step (/derived/acc_global), the phases step (/derived/static, /derived/phases)
    and, for the reference clock and the Vicon world frame, the align step. Each repetition is written as
    the displacement from its start (m). Velocity resets happen only at true rests (the still-gyroscope
    samples the accelerometer confirms); every method checks its own assumptions (rests, bias range,
    de-drift, motion removed by filtering) and a failure is printed in one line and kept in the channel's
    metadata. The baseline /derived/trajectory_baseline/dedrift (linear velocity de-drift between each
    window's ends) is written with every run for `imulog evaluate`.

    Every oriented IMU with phases is reconstructed when no --imu is given, one run each, with one summary
    table; in a trial with several IMUs each gets its own channels, /derived/trajectory/METHOD/IMU, and its
    own record (imulog.trajectory for the primary IMU, imulog.trajectory.IMU for the others).

    \b
    Methods:
      ddi        direct double integration (trapezoidal, window mean removed; R2G thesis)
      zupt       zero-velocity update with linear velocity de-drift (Bai et al. 2023)
      highpass   double integration, then 0.3 Hz zero-phase high-pass (Bai et al.)
      wavelet    double integration, then db6 level-9 trend (D8, D9, A9) removed (Bai et al.)
      kalman     AR(1) acceleration Kalman filter + zero-velocity updates + RTS smoother (Doshi ch. 6)
      zupt_bias  ZUPT after compensating the rotating accelerometer bias (needs /derived/orientation)
      optimized  R2G thesis optimisation: symmetry + smoothness + min-jerk reference, return to start

    \b
    Examples:
      imulog process orientation trial.mcap && imulog process align trial.mcap
      imulog process phases trial.mcap
      imulog process trajectory trial.mcap --method ddi,zupt,optimized
      imulog process trajectory feet.mcap --imu left_foot --method zupt
      imulog process trajectory trial.mcap --accelerometer rests
      imulog evaluate trial.mcap
    """
    from imulog.commands.imus import run_per_imu
    from imulog.steps.trajectory import run_trajectory

    chosen = _methods(methods)
    base = _D
    try:
        params = _params(
            base,
            highpass_hz,
            wavelet,
            wavelet_level,
            kalman_alpha,
            kalman_q,
            no_smoother,
            no_zero_velocity,
            sigma_ref,
            sigma_data,
            no_return_to_start,
        )
        params = with_accelerometer(params, accelerometer)
    except ParamError:  # a refused value: imulog.cli names the option
        raise
    except ValueError as exc:
        raise click.ClickException(f"{trial}: {exc}") from None
    names = _trajectory_imus(trial, imus, chosen)

    def one(name: str):
        outcome = run_trajectory(trial, imu=name, methods=chosen, params=params, force=force)
        if outcome.skipped:
            text = f"{trial}: trajectories up to date (run {outcome.run}); use --force to recompute"
            return outcome, "up to date", text
        lines = [f"{trial}: wrote {', '.join(outcome.topics)} (run {outcome.run})"]
        record = _record(trial, name)
        lines += [f"{trial}: {line}" for line in outcome_lines(record)]
        for warning in record.get("input_warnings") or []:  # given anthropometrics the IMU disagrees with
            who = f"{name}: " if len(names) > 1 else ""
            click.echo(f"{trial}: {who}warning: {warning}", err=True)
        short = f"{len(record.get('repetitions') or [])} windows, {', '.join(record.get('methods') or [])}"
        return outcome, short, "\n".join(lines)

    rows = run_per_imu(trial, names, one, what="trajectory")
    if len(names) > 1:  # each IMU's notes and failed assumptions below the table
        for row in rows:
            for line in row.text.splitlines()[1:]:
                click.echo(f"  {row.imu}: {line.removeprefix(f'{trial}: ')}")


def _params(
    base,
    highpass_hz,
    wavelet,
    wavelet_level,
    kalman_alpha,
    kalman_q,
    no_smoother,
    no_zero_velocity,
    sigma_ref,
    sigma_data,
    no_return_to_start,
) -> TrajectoryParams:
    """The command's options over the defaults (a ValueError for values the parameters refuse)."""
    return replace(
        base,
        highpass=replace(base.highpass, cutoff_hz=highpass_hz),
        wavelet=replace(base.wavelet, wavelet=wavelet, level=wavelet_level),
        kalman=replace(
            base.kalman,
            alpha=kalman_alpha,
            process_var_m2ps4=kalman_q,
            smoother=not no_smoother,
            zero_velocity=not no_zero_velocity,
        ),
        optimized=replace(
            base.optimized,
            sigma_ref_static_m=sigma_ref,
            sigma_data_mps=sigma_data,
            return_to_start=False if no_return_to_start else base.optimized.return_to_start,
        ),
    )


def _record(trial: Path, imu: str) -> dict:
    from imulog.archive import TrialReader
    from imulog.steps.trajectory_topics import record_of_imu

    with TrialReader(trial) as reader:
        return record_of_imu(imu, reader.metadata)


def outcome_lines(record: dict) -> list[str]:
    """What ``process trajectory`` says after writing: skipped methods, notes, failed assumptions (issue 32)
    and the flagged repetitions (issue 31; docs/accuracy.md)."""
    from imulog.process.repetition_flags import flag_line
    from imulog.steps.trajectory import check_lines

    lines = [f"skipped {method}: {why}" for method, why in (record.get("skipped") or {}).items()]
    lines += [f"note: {note}" for note in record.get("notes") or []]
    lines += check_lines(record)
    flagged = flag_line(record.get("flagged_repetitions") or [], len(record.get("repetitions") or []))
    return lines + ([flagged] if flagged else [])


def _trajectory_imus(trial: Path, imus: tuple[str, ...], methods: list[str]) -> list[str]:
    """The IMUs to reconstruct: those named, else every oriented IMU, without those that lack the phases step's
    zero-velocity mask when a method needs it (a note on stderr; all of them when none has it, so the step's
    own error says what to run)."""
    from imulog.archive import ArchiveError, TrialReader
    from imulog.commands.imus import choose_imus
    from imulog.steps.common import error_line
    from imulog.steps.trajectory import NEEDS_STATIC

    names = choose_imus(
        trial, imus, prefix="/derived/acc_global/", missing_hint="run `imulog process orientation` first"
    )
    if imus or len(names) < 2 or not NEEDS_STATIC.intersection(methods):
        return names
    try:
        with TrialReader(trial) as reader:
            topics = set(reader.topics())
    except (ArchiveError, OSError) as exc:
        raise click.ClickException(error_line(trial, exc)) from None
    ready = [n for n in names if f"/derived/static/{n}" in topics]
    if ready and len(ready) < len(names):
        for n in names:
            if n not in ready:
                click.echo(f"note: left out {n}: no /derived/static/{n} (run `imulog process phases`)", err=True)
        return ready
    return names


@click.command("evaluate")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--method", "methods", default=None, help="Comma-separated methods (default: every trajectory present).")
@click.option(
    "--max-gap",
    type=float,
    default=0.05,
    show_default=True,
    help="Drop samples across reference gaps longer than this, s.",
)
@click.option(
    "--strides/--windows",
    "strides",
    default=None,
    help="Per stride and foot (a walking trial; default when the task or the gyroscope says walking) or over "
    "the trajectory step's windows (default otherwise).",
)
@click.option(
    "--imu",
    "imus",
    multiple=True,
    help="Which IMUs (repeatable; default: every one with what is evaluated: trajectories, strides of a foot, or an "
    "orientation and an alignment on a rigid body's poses).",
)
@click.option(
    "--what",
    type=click.Choice(["auto", "orientation", "trajectory"]),
    default="auto",
    show_default=True,
    help="orientation: the IMU's orientation against the rigid body's poses it is aligned on (BROAD), stored as "
    "imulog.orientation_evaluation; trajectory: the trajectories (or strides) against the optical reference, stored "
    "as imulog.evaluation; auto: the orientation when the trial has poses and no trajectories, else the trajectories.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the evaluation record as JSON.")
@click.option("--force", is_flag=True, help="Recompute even when up to date.")
def evaluate(
    trial: Path,
    methods: str | None,
    max_gap: float,
    strides: bool | None,
    imus: tuple[str, ...],
    what: str,
    as_json: bool,
    force: bool,
) -> None:
    """Compare every /derived/trajectory/* with the Vicon cluster origin; print the Table-3.1 summary.

    Per repetition and axis: mean absolute error (cm), error as % of the Vicon range of motion, RMSE,
    final displacement error and Spearman correlation; the table shows mean±std over repetitions. A second
    table gives the median and 90th percentile per axis, the reference's range of motion, the windows whose
    error exceeds the motion itself, and whether each method beats the dedrift baseline; warnings name the
    methods whose assumptions failed. The result is stored as the imulog.evaluation metadata record.

    A trial with an optical rigid body's poses (/poses/NAME: BROAD, an OptiTrack rigid body) and no
    trajectories, aligned on the poses (imulog process align), has its IMU orientation
    (imulog process orientation) evaluated instead: inclination and heading-free RMSE in degrees, as in the
    BROAD paper, over the /events/movement phases when the trial has them. --what orientation asks for it
    when the trial has trajectories too (--what trajectory for those); the two evaluations are stored apart
    (imulog.orientation_evaluation, imulog.evaluation) and never replace each other.

    A walking trial (task walk/gait in imulog.trial, or a gyroscope repeating at a stride's period) is
    evaluated per stride and per foot instead, like gaitmap: each foot IMU aligned with its cluster
    (imulog process align) gets a ZUPT trajectory between its zero-velocity intervals, compared stride by
    stride with the point of its cluster where the IMU sits: stride length, time, foot clearance and the
    position error per axis (docs/gait.md).

    \b
    Examples:
      imulog evaluate trial.mcap
      imulog evaluate trial.mcap --method zupt,optimized --json > errors.json
      imulog evaluate walk.mcap --strides --imu left_foot
      imulog evaluate broad_trial.mcap                 # orientation vs /poses/optical (BROAD)
      imulog evaluate broad_trial.mcap --what orientation   # the same, also once it has trajectories
    """
    from imulog.archive.errors import ArchiveError
    from imulog.steps.common import error_line
    from imulog.steps.evaluate import run_evaluate

    try:
        _, record = run_evaluate(
            trial,
            methods=_methods(methods) if methods else None,
            max_gap_s=max_gap,
            strides=strides,
            imus=list(imus) or None,
            what=what,
            force=force,
        )
        if record.get("kind") == "strides":
            from imulog.steps.gait_evaluate import stride_table

            if as_json:
                click.echo(json.dumps(record, indent=1, default=float))
                return
            walking = record.get("walking") or {}
            why = walking.get("task") or (
                f"gyroscope period {walking.get('period_s')} s" if walking.get("period_s") else "asked"
            )
            click.echo(f"{trial}: walking ({why}): per stride, against each foot's cluster (mean over strides)")
            click.echo(stride_table(record))
            return
    except (ArchiveError, ValueError, KeyError, OSError) as exc:
        raise click.ClickException(error_line(trial, exc)) from None
    if record.get("kind") in ("orientation", "orientations"):  # against rigid bodies' poses (docs/alignment.md)
        from imulog.steps.evaluate_orientation import orientation_lines

        if as_json:
            click.echo(json.dumps(record, indent=1, default=float))
            return
        several = record["imus"] if record["kind"] == "orientations" else {"": record}
        for rec in several.values():
            if "failed" in rec:
                continue
            click.echo(f"{trial}: {rec['imu']} orientation against {rec['reference']}")
            for line in orientation_lines(rec):
                click.echo(f"  {line}")
        for imu, why in (record.get("skipped") or {}).items():
            click.echo(f"{trial}: {imu}: not evaluated: {why}")
        failed = {imu: rec["failed"] for imu, rec in several.items() if "failed" in rec}
        if failed:
            raise click.ClickException(
                f"{trial}: {len(failed)} of {len(several)} IMUs not evaluated: "
                + "; ".join(f"{imu}: {why.removeprefix(f'{trial}: ')}" for imu, why in failed.items())
            )
        return
    from imulog.archive import TrialReader
    from imulog.steps.common import record_of
    from imulog.steps.trajectory_topics import record_of_imu

    per_imu = record.get("kind") == "imus"
    evaluated = record["imus"] if per_imu else {str(record.get("imu") or "").removeprefix("/imu/"): record}
    out: dict = {}
    with TrialReader(trial) as reader:  # forced phases and flagged repetitions stay visible next to the errors
        for imu, rec in evaluated.items():
            flagged = record_of_imu(imu, reader.metadata).get("flagged_repetitions")
            timing = reader.metadata.get(record_of("imulog.timing", imu, reader.metadata) or "imulog.timing") or {}
            out[imu] = (rec, {} if "failed" in rec else _quality(rec, timing, flagged))
    if as_json:
        docs = {imu: {**rec, "phase_quality": q} if q else rec for imu, (rec, q) in out.items()}
        click.echo(
            json.dumps(
                {"kind": "imus", "imus": docs} if per_imu else next(iter(docs.values())), indent=1, default=float
            )
        )
        return
    for imu, (rec, quality) in out.items():
        if "failed" in rec:
            click.echo(f"{trial}: {imu}: not evaluated: {rec['failed'].removeprefix(f'{trial}: ')}")
            continue
        _echo_evaluation(trial, rec, quality, f"{imu}: " if per_imu else "")
    failed = [imu for imu, (rec, _) in out.items() if "failed" in rec]
    if failed:
        raise click.ClickException(f"{trial}: {len(failed)} of {len(out)} IMUs not evaluated: {', '.join(failed)}")


def _quality(record: dict, timing: dict, flagged) -> dict:
    from imulog.steps.evaluate_quality import phase_quality_summary

    return phase_quality_summary(record, timing, flagged=flagged)


def _echo_evaluation(trial: Path, record: dict, quality: dict, who: str) -> None:
    """One IMU's evaluation: the table, the robust figures, warnings and the phase quality."""
    from imulog.steps.evaluate import robust_from_record, table_from_record, warning_lines
    from imulog.steps.evaluate_quality import format_phase_quality

    click.echo(f"{trial}: {who}errors against {record.get('reference', '?')} (mean±std over repetitions)")
    click.echo(table_from_record(record))
    robust = robust_from_record(record)
    if robust:
        click.echo("robust figures (mean over windows; ROM = the reference's range of motion):")
        click.echo(robust)
    for line in warning_lines(record):
        click.echo(f"{trial}: {who}warning: {line}")
    aligned = record.get("alignment") or {}
    if aligned.get("quality") == "poor":  # flagged by imulog process align (docs/alignment.md)
        click.echo(f"{trial}: {who}warning: poor alignment: {'; '.join(aligned.get('quality_reasons') or [])}")
    if quality:
        click.echo(format_phase_quality(quality))
