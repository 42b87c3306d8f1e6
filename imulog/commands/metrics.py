"""``imulog process metrics``: arm usage, activity counts, distance histogram, timings and smoothness."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from imulog.commands.imus import imu_option, step_record
from imulog.steps.metrics import MetricsParams

_D = MetricsParams()  # the one source of defaults (tests/test_cli_defaults.py)


def format_summary(r: dict[str, Any]) -> str:
    """Human-readable summary of an ``imulog.metrics`` record ``r``."""
    m2_axes = r.get("activity.method2.per_axis", ["?"] * 3)
    m1_axes = r.get("activity.method1.per_axis", ["?"] * 3)
    lines = [
        f"{r['imu']}: {r['duration_s']:.1f} s at {r['rate_hz']:.1f} Hz",
        f"  arm usage (> {r['arm_usage.noise_level_g']:.4g} g):  x {r['arm_usage.x_percent']:.1f} %  "
        f"y {r['arm_usage.y_percent']:.1f} %  z {r['arm_usage.z_percent']:.1f} %  overall "
        f"{r['arm_usage.overall_percent']:.1f} %",
        f"  activities (method 2, m={r['activity.method2.m_samples']}, dead={r['activity.method2.dead_samples']} "
        f"samples, floor {r['activity.method2.noise_floor_g']:.4g} g): {r['activity.method2.count']}  "
        f"(x {m2_axes[0]}, y {m2_axes[1]}, z {m2_axes[2]}), active {r['activity.method2.total_s']:.1f} s",
        f"  activities (method 1, sign changes): {r['activity.method1.count']}  "
        f"(x {m1_axes[0]}, y {m1_axes[1]}, z {m1_axes[2]})",
        f"  distance in {r['distance.window_s']} s windows: median {r['distance.window_median_cm']:.1f} cm, "
        f"max {r['distance.window_max_cm']:.1f} cm, weighted area (> {r['distance.weight_start_cm']} cm) "
        f"{r['distance.weighted_area']:.2f}",
    ]
    labels = list(dict.fromkeys(k.split(".")[1] for k in r if k.startswith("timings.") and k.endswith(".mean_s")))
    for label in labels:
        lines.append(
            f"  {label:<14} n {r[f'timings.{label}.n']:>3}  mean {r[f'timings.{label}.mean_s']:.3f} s  "
            f"sd {r[f'timings.{label}.std_s']:.3f} s"
            + (f"  CV {r[f'timings.{label}.cv']:.2f}" if f"timings.{label}.cv" in r else "")
        )
    if "nhpt.n_pegs" in r:
        lines.append(
            f"  NHPT: {r['nhpt.n_pegs']} pegs, test time {r['nhpt.test_time_s']:.2f} s, "
            f"mean transport {r['nhpt.transport_mean_s']:.2f} s"
        )
    smooth = list(dict.fromkeys(k.split(".")[1] for k in r if k.startswith("smoothness.") and k.endswith(".n")))
    if smooth:
        lines.append(f"  smoothness from {r.get('smoothness.source', '?')}:")
    for label in smooth:
        lines.append(
            f"  {label:<14} peaks {r[f'smoothness.{label}.velocity_peaks_mean']:.2f}  "
            f"NJ {r[f'smoothness.{label}.normalized_jerk_mean']:.1f}  LDLJ {r[f'smoothness.{label}.ldlj_mean']:.2f}  "
            f"SPARC {r[f'smoothness.{label}.sparc_mean']:.3f}"
        )
    return "\n".join(lines)


@click.command("metrics")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@imu_option()
@click.option(
    "--noise-level-g",
    type=float,
    default=_D.noise_level_g,
    show_default=True,
    help="Arm-usage threshold in g, on changes between samples at --arm-usage-rate-hz (Doshi 2011); "
    "with --static: measured unless given.",
)
@click.option(
    "--arm-usage-rate-hz",
    type=float,
    default=_D.arm_usage_rate_hz,
    show_default=True,
    help="Rate the arm-usage threshold applies at (Doshi: 10 Hz); faster recordings are averaged to it first.",
)
@click.option(
    "--noise-floor-g",
    type=float,
    default=_D.noise_floor_g,
    show_default=True,
    help="Activity noise floor in g (Doshi 2011); with --static: measured unless given.",
)
@click.option(
    "--static",
    "static_trial",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="A trial recorded with the sensor at rest: estimate the noise level and floor from it.",
)
@click.option(
    "--noise-statistic",
    type=click.Choice(["peak", "std", "diff_peak", "diff_std"]),
    default="peak",
    show_default=True,
    help="Statistic of the --static recording used as arm-usage noise level (Doshi: peak).",
)
@click.option("--m-s", type=float, default=_D.m_s, show_default=True, help="Moving-average half width, s (m).")
@click.option(
    "--dead-s", type=float, default=_D.dead_s, show_default=True, help="Dead period separating activities, s."
)
@click.option(
    "--min-activity-s",
    type=float,
    default=_D.min_activity_s,
    show_default=True,
    help="Drop activities shorter than this, s (imulog addition; 0 = Doshi).",
)
@click.option("--window-s", type=float, default=_D.window_s, show_default=True, help="Distance-histogram window, s.")
@click.option(
    "--max-distance-cm", type=float, default=_D.max_distance_cm, show_default=True, help="Last histogram bin, cm."
)
@click.option(
    "--weight-start-cm", type=float, default=_D.weight_start_cm, show_default=True, help="Weight-0 distance, cm."
)
@click.option(
    "--acc-unit",
    type=click.Choice(["g", "m/s^2"]),
    default=_D.acc_unit,
    show_default=True,
    help="Integrate distances in g (Doshi App. A.3) or SI units.",
)
@click.option(
    "--trajectory",
    default=_D.trajectory,
    help="Positions for smoothness: METHOD of /derived/trajectory/METHOD or 'vicon'. [default: the most "
    "accurate trajectory present (optimized, zupt_bias, zupt, kalman, ...), else vicon]",
)
@click.option("--force", is_flag=True, help="Recompute even when the same parameters are already recorded.")
@click.option("--json", "as_json", is_flag=True, help="Print the imulog.metrics record as JSON.")
def process_metrics(
    trial: Path,
    imus: tuple[str, ...],
    noise_level_g: float,
    arm_usage_rate_hz: float,
    noise_floor_g: float,
    static_trial: Path | None,
    noise_statistic: str,
    m_s: float,
    dead_s: float,
    min_activity_s: float,
    window_s: float,
    max_distance_cm: float,
    weight_start_cm: float,
    acc_unit: str,
    trajectory: str,
    force: bool,
    as_json: bool,
) -> None:
    """Compute clinical metrics of TRIAL's IMU, append them and print a summary.

    \b
    Metrics (formulas and references in docs/metrics.md):
      arm usage      % of samples whose change from the previous one exceeds the noise level (Doshi 2011 4.2)
      activities     method 1: sign changes about the mean; method 2: moving average of m samples subtracted,
                     noise floor, activities separated by dead periods (Doshi 2011 4.2.4)
      distance       histogram of distance traversed in 5 s windows and its linearly weighted area (Doshi ch. 5)
      timings        per-phase durations (R2G) and peg pick-up/placement times (NHPT) from /derived/phases/IMU
      smoothness     velocity peaks, normalised jerk, LDLJ, SPARC per phase, from a trajectory or Vicon

    Writes /derived/metrics/activity/IMU (Intervals), /derived/metrics/distance/IMU (distance_cm) and the
    metadata record imulog.metrics (imulog.metrics.IMU for IMUs other than the trial's primary one; shown by
    `imulog info --json`). Every IMU when no --imu is given, one run each, one summary table. Same inputs and
    options: no change.

    \b
    Examples:
      imulog process metrics trial.mcap
      imulog process metrics trial.mcap --noise-level-g 0.03 --dead-s 2 --window-s 5
      imulog process metrics trial.mcap --static sensor_at_rest.mcap      # noise from a static recording
      imulog process align r2g.mcap && imulog process phases r2g.mcap && imulog process metrics r2g.mcap
    """
    from dataclasses import replace

    from click.core import ParameterSource

    from imulog.archive.errors import ArchiveError
    from imulog.commands.imus import choose_imus, run_per_imu
    from imulog.steps.common import error_line
    from imulog.steps.metrics import RECORD, run_metrics

    ctx = click.get_current_context()
    given = {n for n in ("noise_level_g", "noise_floor_g") if ctx.get_parameter_source(n) != ParameterSource.DEFAULT}
    try:
        if static_trial is not None:
            level, floor = _noise_from_static(
                static_trial, imus[0] if len(imus) == 1 else None, m_s, noise_statistic, arm_usage_rate_hz
            )
            noise_level_g = noise_level_g if "noise_level_g" in given else level
            noise_floor_g = noise_floor_g if "noise_floor_g" in given else floor
            click.echo(f"noise from {static_trial}: level {level:.4f} g ({noise_statistic}), floor {floor:.4f} g")
        params = replace(
            _D,
            noise_level_g=noise_level_g,
            arm_usage_rate_hz=arm_usage_rate_hz,
            noise_floor_g=noise_floor_g,
            m_s=m_s,
            dead_s=dead_s,
            min_activity_s=min_activity_s,
            window_s=window_s,
            max_distance_cm=max_distance_cm,
            weight_start_cm=weight_start_cm,
            acc_unit=acc_unit,
            trajectory=trajectory,
        )
        params.distance()  # validates the histogram and activity parameters before any I/O
        params.activity(100.0)
    except (ArchiveError, ValueError, KeyError, OSError) as exc:
        raise click.ClickException(error_line(trial, exc)) from exc
    names = choose_imus(trial, imus, needs=("acc",))
    records: dict[str, dict] = {}

    def one(name: str):
        outcome = run_metrics(trial, imu=name, params=params, force=force)
        record = records[name] = step_record(trial, RECORD, name)
        text = format_summary(record)
        skipped = getattr(outcome, "skipped", False)
        usage = next((line.strip() for line in text.splitlines() if line.strip().startswith("arm usage")), "")
        short = text.splitlines()[0].split(": ", 1)[-1] + (f", {usage}" if usage else "")
        return outcome, short, ("(unchanged: same inputs and parameters) " if skipped else "") + text

    if as_json:  # the record(s) only: one IMU's record, or {imu: record}
        run_per_imu(trial, names, one, what="metrics", echo=False)
        click.echo(json.dumps(records[names[0]] if len(names) == 1 else records, indent=2))
        return
    run_per_imu(trial, names, one, what="metrics")


def _noise_from_static(
    path: Path, imu: str | None, m_s: float, statistic: str, arm_usage_rate_hz: float = _D.arm_usage_rate_hz
) -> tuple[float, float]:
    """Arm-usage noise level and activity noise floor (g) of a trial recorded at rest.

    The noise level is measured at the rate the arm-usage threshold applies at (0.1 s window means at 10 Hz),
    the noise floor at the recording's own rate (activity counts work on every sample)."""
    from imulog.archive import TrialReader
    from imulog.process.metrics import (
        ActivityCountParams,
        acc_to_g,
        estimate_noise_floor,
        estimate_noise_level,
        to_reference_rate,
    )
    from imulog.steps.common import nominal_rate_hz, pick_imu

    with TrialReader(path) as reader:
        name = pick_imu(reader.topics(), imu)
        stream = reader.read(f"/imu/{name}")
    if stream.acc is None:
        raise ValueError(f"{path}: /imu/{name} has no accelerometer columns")
    acc_g = acc_to_g(stream.acc)
    slow = acc_g
    if nominal_rate_hz(stream.t_ns) > 1.5 * arm_usage_rate_hz:
        slow = to_reference_rate(acc_g, stream.t_ns, arm_usage_rate_hz)[0]
    level = estimate_noise_level(slow).threshold_g(statistic)  # type: ignore[arg-type]
    floor = estimate_noise_floor(acc_g, ActivityCountParams.for_rate(nominal_rate_hz(stream.t_ns), m_s=m_s))
    return level, floor
