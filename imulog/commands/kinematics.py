"""``imulog process kinematics``: shoulder and elbow angles from two IMUs (constrained DH model)."""

from __future__ import annotations

from pathlib import Path

import click

from imulog.commands.option_fields import option_fields


def _floats(text: str | None, n: int, option: str) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError as exc:
        raise click.BadParameter(f"expected {n} comma-separated numbers, got {text!r}", param_hint=option) from exc
    if len(values) != n:
        raise click.BadParameter(f"expected {n} comma-separated numbers, got {len(values)}", param_hint=option)
    return values


@option_fields(neutral_window="KinematicsOptions.neutral_window_s", calibration="KinematicsOptions.calibration_mode")
@click.command("kinematics")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--upper-arm",
    default=None,
    help="Upper-arm IMU name (/imu/NAME); default from imulog.kinematics, else the sensor whose name or placement "
    "says upper arm (upper_arm, RightUpperArm, humerus_r, a device record's placement/label).",
)
@click.option(
    "--forearm",
    default=None,
    help="Forearm IMU name; default from imulog.kinematics, else the sensor whose name or placement says forearm "
    "(forearm, lower arm, radius; a wrist sensor when none does), on the upper arm's side.",
)
@click.option(
    "--trunk",
    default=None,
    help="Trunk IMU name (axes on the trunk axes): follow a moving trunk; default from imulog.kinematics "
    "(trunk_imu), else a still trunk. --trunk '' ignores the metadata's trunk IMU.",
)
@click.option(
    "--neutral-pose",
    default=None,
    metavar="DEG,DEG,DEG,DEG,DEG",
    help="Joint angles of the static neutral posture, deg (plane of elevation, elevation, axial rotation, "
    "flexion, pronation); default from imulog.kinematics, else 90,30,0,90,90.",
)
@click.option(
    "--neutral-window",
    default=None,
    metavar="START,END",
    help="Seconds after the first sample during which the posture is held; default from imulog.kinematics, else 0.5,2.5.",
)
@click.option(
    "--calibration",
    type=click.Choice(["heading", "full"]),
    default="heading",
    show_default=True,
    help="Fit only the heading of each IMU's global frame to the trunk (heading) or a full rotation.",
)
@click.option(
    "--markers/--no-markers", default=True, show_default=True, help="Compute the Vicon-cluster reference and errors."
)
@click.option("--max-iterations", type=int, default=50, show_default=True, help="Solver iterations per sample.")
@click.option("--force", is_flag=True, help="Recompute even when the same parameters are already recorded.")
def process_kinematics(
    trial: Path,
    upper_arm: str | None,
    forearm: str | None,
    trunk: str | None,
    neutral_pose: str | None,
    neutral_window: str | None,
    calibration: str,
    markers: bool,
    max_iterations: int,
    force: bool,
) -> None:
    """Shoulder and elbow joint angles of TRIAL from an upper-arm and a forearm IMU.

    Implements Caruso et al. (IEEE Access 2024): an ISB-consistent Denavit-Hartenberg arm (segment
    lengths and carrying angle from imulog.anthropometrics) fitted at every sample to the two IMU
    orientations, without and with constraints (joint limits; elbow and wrist centres inside the
    workspace boxes of imulog.kinematics), warm-started from the previous sample. Uses
    /derived/orientation/IMU when present (run `imulog process orientation` first to choose the
    filter), else VQF offline. Writes /derived/kinematics/joint_angles_{unconstrained,constrained}
    (deg), /derived/kinematics/{elbow,wrist} (poses in the trunk frame, m),
    /derived/kinematics/constraint_active and, with marker clusters, the Vicon reference and
    imulog.kinematics_errors (e_tot, e_out in deg).

    \b
    Examples:
      python -m imulog.simulate.arm arm.mcap --seconds 60      # a simulated two-IMU trial
      imulog process kinematics arm.mcap
      imulog process kinematics arm.mcap --neutral-pose 90,30,0,90,90 --neutral-window 0.5,2.5
      imulog process kinematics trial.mcap --upper-arm ua --forearm fa --no-markers
      imulog convert xsens/ -o arm.mcap --device-name 00B421AF=right_upper_arm --device-name 00B4227B=right_forearm
      imulog process kinematics arm.mcap --no-markers             # the IMUs found by their names
      python -m imulog.simulate.arm sway.mcap --trunk-imu --trunk-sway 15
      imulog process kinematics sway.mcap                      # trunk IMU named in the metadata
      imulog info arm.mcap                                     # shows imulog.kinematics_errors
    """
    from imulog.archive import ArchiveError
    from imulog.process.kinematics.solver import SolverParams
    from imulog.steps.common import error_line
    from imulog.steps.kinematics import KinematicsOptions, run_kinematics

    pose = _floats(neutral_pose, 5, "--neutral-pose")
    window = _floats(neutral_window, 2, "--neutral-window")
    if max_iterations < 1:
        raise click.BadParameter("must be >= 1", param_hint="--max-iterations")
    options = KinematicsOptions(
        upper_arm=upper_arm,
        forearm=forearm,
        trunk=trunk,
        neutral_pose_deg=pose,
        neutral_window_s=window,
        calibration_mode=calibration,
        use_markers=markers,
        solver=SolverParams(max_iterations=max_iterations),
    )
    try:
        outcome = run_kinematics(trial, options=options, force=force)
    except (ArchiveError, ValueError, KeyError, OSError, RuntimeError) as exc:
        raise click.ClickException(error_line(trial, exc)) from None
    if outcome.skipped:
        click.echo(f"unchanged (same inputs and parameters): {', '.join(outcome.topics)}")
        return
    click.echo(f"wrote {', '.join(outcome.topics)} (run {outcome.run})")
    from imulog.archive import TrialReader

    with TrialReader(trial) as t:
        err = t.metadata.get("imulog.kinematics_errors")
        cal = t.metadata.get("imulog.kinematics_calibration", {})
    if cal.get("ms_per_sample"):
        ms = cal["ms_per_sample"]
        click.echo(
            f"solver: {ms.get('unconstrained', float('nan')):.3f} ms/sample unconstrained, "
            f"{ms.get('constrained', float('nan')):.3f} ms/sample constrained; "
            f"constraints active {100 * cal.get('constraint_active_fraction', 0):.1f} % of samples"
        )
    if err:
        click.echo(f"errors vs marker reference (deg), t_out = {100 * (err['t_out_fraction'] or 0):.1f} %:")
        click.echo(f"  {'joint':24s} {'e_tot_un':>9s} {'e_tot_con':>9s} {'e_out_un':>9s} {'e_out_con':>9s}")
        from imulog.process.kinematics.dh import JOINT_NAMES

        for j in JOINT_NAMES:
            vals = [err[k][j] for k in ("e_tot_un_deg", "e_tot_con_deg", "e_out_un_deg", "e_out_con_deg")]
            click.echo(f"  {j:24s} " + " ".join(f"{v:9.2f}" if v is not None else f"{'-':>9s}" for v in vals))
