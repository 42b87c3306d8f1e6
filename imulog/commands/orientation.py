"""``imulog process orientation``: sensor orientation and gravity-free global acceleration."""

from __future__ import annotations

from pathlib import Path

import click

from imulog.commands.imus import imu_option
from imulog.commands.option_fields import option_fields
from imulog.process.orientation import OrientationParams

BACKEND_CHOICES = ["vqf_offline", "vqf", "madgwick", "imufusion", "rts", "vqf_gyrocal"]
_D = OrientationParams()  # the one source of defaults (tests/test_cli_defaults.py)


@option_fields(static_threshold="StaticParams.threshold_rad_s", static_min_s="StaticParams.min_duration_s")
@click.command("orientation")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@imu_option()
@click.option(
    "--backend",
    type=click.Choice(BACKEND_CHOICES),
    default=_D.backend,
    show_default=True,
    help="vqf_offline: acausal VQF (most accurate on BROAD); vqf: causal VQF; madgwick: the R2G thesis "
    "setting (AQUA init + Madgwick, numba); imufusion: x-io Fusion (optional package); rts: imulog's "
    "Kalman smoother over the whole trial with rest-based gyroscope bias (6D); vqf_gyrocal: vqf_offline on "
    "the gyroscope self-calibrated over the whole trial (docs/orientation.md says where both stand against "
    "vqf_offline).",
)
@click.option("--beta", type=float, default=_D.beta, show_default=True, help="Madgwick gain, rad/s (madgwick backend).")
@click.option("--mag/--no-mag", "use_mag", default=_D.use_mag, show_default=True, help="Fuse the magnetometer (9D).")
@click.option(
    "--static-threshold",
    type=float,
    default=_D.static.threshold_rad_s,
    show_default=True,
    help="Static if gyro norm < this, rad/s.",
)
@click.option(
    "--static-min-s", type=float, default=_D.static.min_duration_s, show_default=True, help="Shortest static period, s."
)
@click.option(
    "--source",
    type=click.Choice(["auto", "raw", "calibrated"]),
    default="auto",
    show_default=True,
    help="Input: /derived/calibrated/IMU when present (auto), or force raw / calibrated.",
)
@click.option("--force", is_flag=True, help="Recompute even when the same parameters are already recorded.")
def process_orientation(
    trial: Path,
    imus: tuple[str, ...],
    backend: str,
    beta: float,
    use_mag: bool,
    static_threshold: float,
    static_min_s: float,
    source: str,
    force: bool,
) -> None:
    """Estimate the IMU orientation and gravity-free global acceleration; append them to TRIAL.

    Writes /derived/orientation/IMU (qw,qx,qy,qz sensor-to-global, z up), /derived/acc_global/IMU
    (m/s^2, gravity removed) and /derived/orientation_static/IMU (gyro-norm static mask), on the IMU
    clock. Every IMU of the trial is oriented when no --imu is given, one run each, with one summary
    table and one line saying whether they share one heading frame (each 6D global frame has its own
    arbitrary heading: `imulog process heading` relates them). Running twice
    with the same options changes nothing.

    \b
    Examples:
      imulog process orientation trial.mcap                          # VQF offline (default)
      imulog process orientation trial.mcap --backend madgwick --beta 0.03   # the thesis's setting
      imulog process orientation trial.mcap --backend vqf --mag      # causal VQF with magnetometer
      imulog process orientation opals.mcap --imu upper --imu lower  # two of the trial's IMUs
    """
    from dataclasses import replace

    from imulog.commands.imus import choose_imus, run_per_imu
    from imulog.steps.orientation import global_frame, run_orientation

    params = replace(  # a bad value raises imulog.params.ParamError: one line from imulog.cli (the option and unit)
        _D,
        backend=backend,
        beta=beta,
        use_mag=use_mag,
        static=replace(_D.static, threshold_rad_s=static_threshold, min_duration_s=static_min_s),
    )
    frame = global_frame(params)

    def one(name: str):
        outcome = run_orientation(trial, imu=name, params=params, source=source, force=force)
        if outcome.skipped:
            text = f"unchanged (same inputs and parameters): {', '.join(outcome.topics)}"
        else:
            text = f"wrote {', '.join(outcome.topics)} (run {outcome.run})"
        return outcome, f"/derived/orientation/{name}, {params.backend}, global frame {frame}", text

    names = choose_imus(trial, imus, needs=("acc", "gyr"))
    run_per_imu(trial, names, one, what="orientation")
    if len(names) > 1:  # one heading frame for all (the heading step, from what the trial has), or why not
        from imulog.steps.heading import heading_status, refresh_heading

        try:
            refresh_heading(trial)
        except (ValueError, KeyError) as exc:  # the orientations are written; the line says they do not relate
            click.echo(f"heading: not related ({exc})", err=True)
        click.echo(heading_status(trial, names, frame))
