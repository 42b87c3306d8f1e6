"""``imulog process align``: IMU-to-Vicon time lag, drift and frame rotations."""

from __future__ import annotations

import math
from pathlib import Path

import click


@click.command("align")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--imu", default=None, help="IMU name (channel /imu/NAME); default: the only IMU, else 'wrist'.")
@click.option("--markers", default=None, help="Marker channel /markers/NAME; default: the only one, else 'vicon'.")
@click.option("--window", "window_s", type=float, default=120.0, show_default=True, help="Correlation window, s.")
@click.option(
    "--window-start",
    "window_start_s",
    type=float,
    default=0.0,
    show_default=True,
    help="Window start after the first Vicon frame, s.",
)
@click.option("--max-lag", "max_lag_s", type=float, default=60.0, show_default=True, help="Search range +-, s.")
@click.option(
    "--drift/--no-drift",
    default=False,
    show_default=True,
    help="Also estimate clock drift from a second window at the end of the recording.",
)
@click.option(
    "--cluster",
    type=click.Choice(["oxy", "svd"]),
    default="oxy",
    show_default=True,
    help="Cluster frame: markers O, X, Y (thesis) or an SVD fit of all --cluster-markers.",
)
@click.option("--cluster-markers", default="O,X,Y,A", show_default=True, help="Markers of the SVD fit (>= 3).")
@click.option("--cutoff", "cutoff_hz", type=float, default=6.0, show_default=True, help="Marker low-pass, Hz.")
@click.option(
    "--max-gap",
    "max_gap_s",
    type=float,
    default=0.1,
    show_default=True,
    help="Marker gaps up to this are interpolated; longer stay missing, s.",
)
@click.option(
    "--resample/--no-resample",
    default=True,
    show_default=True,
    help="Write IMU-derived channels on the Vicon clock and rate under /derived/reference/.",
)
@click.option("--force", is_flag=True, help="Recompute even when the same parameters are already recorded.")
def process_align(
    trial: Path,
    imu: str | None,
    markers: str | None,
    window_s: float,
    window_start_s: float,
    max_lag_s: float,
    drift: bool,
    cluster: str,
    cluster_markers: str,
    cutoff_hz: float,
    max_gap_s: float,
    resample: bool,
    force: bool,
) -> None:
    """Align the IMU with the Vicon marker cluster of TRIAL (clock and frames).

    Cross-correlates the angular-velocity norms of the gyroscope and of the cluster (from filtered
    markers) over the first WINDOW seconds to find the clock offset, optionally the drift, then the
    constant IMU-to-cluster rotation (and IMU-global-to-world when the orientation step has run).
    Stores imulog.alignment, /derived/vicon/cluster_pose, /derived/vicon/angular_velocity and the
    resampled /derived/reference/... channels.

    \b
    Examples:
      imulog process align trial.mcap
      imulog process align trial.mcap --window 60 --drift
      imulog process align trial.mcap --cluster svd --cluster-markers O,X,Y,A
    """
    from imulog.archive.errors import ArchiveError
    from imulog.process.alignment import AlignmentParams, FilterParams
    from imulog.steps.align import run_align
    from imulog.steps.common import error_line

    if window_s <= 0 or max_lag_s < 0:
        raise click.ClickException("--window must be positive and --max-lag non-negative")
    params = AlignmentParams(
        window_s=window_s,
        window_start_s=window_start_s,
        max_lag_s=max_lag_s,
        drift=drift,
        filter=FilterParams(cutoff_hz=cutoff_hz, max_gap_s=max_gap_s),
        cluster=cluster,
        markers=tuple(m.strip() for m in cluster_markers.split(",") if m.strip()),
    )
    try:
        with click.progressbar(length=1, label="align") as bar:
            outcome = run_align(trial, imu=imu, markers=markers, params=params, resample=resample, force=force)
            bar.update(1)
        from imulog.archive import TrialReader

        with TrialReader(trial) as reader:
            rec = reader.metadata.get("imulog.alignment", {})
    except (ArchiveError, ValueError, KeyError, OSError) as exc:
        raise click.ClickException(error_line(trial, exc)) from exc
    prefix = "unchanged (same inputs and parameters): " if outcome.skipped else ""
    q = rec.get("rotation_imu_to_cluster") or [1.0, 0.0, 0.0, 0.0]
    angle_deg = math.degrees(2 * math.acos(min(1.0, abs(float(q[0])))))
    click.echo(
        f"{prefix}offset {int(rec.get('offset_ns', 0)) / 1e9:.4f} s, drift {float(rec.get('drift_ppm', 0)):.1f} ppm, "
        f"score {float(rec.get('score', float('nan'))):.3f}, IMU-to-cluster "
        f"[{', '.join(f'{float(v):.5f}' for v in q)}] ({angle_deg:.2f} deg)"
    )
