"""``imulog process align``: IMU-to-Vicon time lag, drift and frame rotations."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from imulog.commands.option_fields import option_fields
from imulog.process.alignment import AlignmentParams, FilterParams

_D = AlignmentParams()


@option_fields(cluster_markers="AlignmentParams.markers")
@click.command("align")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--imu",
    "imus",
    multiple=True,
    help="IMU name (channel /imu/NAME), repeatable; default: every IMU of the trial, each paired with its own "
    "rigid marker cluster (on rigid bodies' poses: with its own body). --imu NAME --poses BODY: that IMU on that "
    "body. Every IMU keeps its own record (imulog.alignment.NAME); `imulog info` lists them.",
)
@click.option("--markers", default=None, help="Marker channel /markers/NAME; default: the only one, else 'vicon'.")
@click.option(
    "--poses",
    default=None,
    help="Align on the rigid body's poses /poses/NAME (OptiTrack rigid body, BROAD's optical quaternion) instead of "
    "markers; default when the trial has poses and no markers.",
)
@click.option("--window", "window_s", type=float, default=_D.window_s, show_default=True, help="Lag window length, s.")
@click.option(
    "--window-start",
    "window_start_s",
    type=float,
    default=_D.window_start_s,
    show_default=True,
    help="Windows start this long after the first Vicon frame, s.",
)
@click.option("--max-lag", "max_lag_s", type=float, default=_D.max_lag_s, show_default=True, help="Search range +-, s.")
@click.option(
    "--drift/--no-drift",
    default=_D.drift,
    show_default=True,
    help="Fit clock drift to the lags of the windows across the trial (--no-drift: one offset).",
)
@click.option(
    "--cluster",
    type=click.Choice(["auto", "oxy", "svd"]),
    default=_D.cluster,
    show_default=True,
    help="auto: find the rigid markers that move with the IMU; oxy: markers O, X, Y (thesis); "
    "svd: fit the --cluster-markers.",
)
@click.option(
    "--cluster-markers",
    default=None,
    help="Markers on the IMU (comma-separated, with or without the Subject: prefix); overrides the search. "
    "One marker aligns on its acceleration.",
)
@click.option(
    "--cutoff", "cutoff_hz", type=float, default=_D.filter.cutoff_hz, show_default=True, help="Marker low-pass, Hz."
)
@click.option(
    "--max-gap",
    "max_gap_s",
    type=float,
    default=_D.filter.max_gap_s,
    show_default=True,
    help="Marker gaps up to this are interpolated; longer stay missing, s.",
)
@click.option(
    "--resample/--no-resample",
    default=True,
    show_default=True,
    help="Write IMU-derived channels on the Vicon clock and rate under /derived/reference/.",
)
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print the alignment record as JSON (the IMU aligned; a whole setup: imulog.alignment).",
)
@click.option("--force", is_flag=True, help="Recompute even when the same parameters are already recorded.")
def process_align(
    trial: Path,
    imus: tuple[str, ...],
    markers: str | None,
    poses: str | None,
    window_s: float,
    window_start_s: float,
    max_lag_s: float,
    drift: bool,
    cluster: str,
    cluster_markers: str | None,
    cutoff_hz: float,
    max_gap_s: float,
    resample: bool,
    as_json: bool,
    force: bool,
) -> None:
    """Align the IMUs with the Vicon markers of TRIAL (clock and frames).

    Every IMU of the trial by default: each is paired one to one with its own rigid marker cluster, searched
    among all markers (any naming); markers not rigid with the rest of a cluster are dropped; the IMUs of one
    recording get one clock offset and drift fitted to all of them together, and an IMU without a cluster
    gets that clock and is flagged as having no frame alignment. Per IMU, as below:

    Finds the rigid marker set that moves with the IMU (marker triads ranked by rigidity and by how well
    their angular velocity matches the gyroscope), cross-correlates the angular-velocity norms over
    WINDOW-second windows across the trial and fits the clock offset and drift to their lags, then the
    constant IMU-to-cluster rotation (and IMU-global-to-world when the orientation step has run). With
    no rigid cluster on the IMU, aligns on one marker's acceleration (flagged less certain). Stores
    imulog.alignment, /derived/vicon/cluster_pose, /derived/vicon/angular_velocity and the resampled
    /derived/reference/... channels.

    A trial with an optical rigid body's poses (/poses/NAME: an OptiTrack rigid body, BROAD's optical
    quaternion) and no markers is aligned on the poses: the body's angular velocity comes from its
    orientations (the body frame is the cluster frame). With several IMUs and bodies, every IMU is aligned with
    every body and they are paired one to one by the data (the summed vector match), whatever their names; --imu
    NAME --poses BODY aligns one IMU on the body you name. Poses missing in more than half the samples are
    refused.

    In a trial with several IMUs each IMU's alignment is its own record, imulog.alignment.NAME (with
    /derived/vicon/cluster_pose/NAME), whichever way it was aligned: aligning one IMU never replaces another's.
    imulog.alignment stays the first IMU aligned (or the setup's primary IMU).

    \b
    Examples:
      imulog process align trial.mcap                  # every IMU
      imulog process align trial.mcap --imu left_foot --imu right_foot
      imulog process align trial.mcap --window 60 --no-drift
      imulog process align trial.mcap --cluster-markers Subject:O,Subject:X,Subject:Y
      imulog process align trial.mcap --cluster-markers WRIST        # one marker: its acceleration
      imulog process align broad_trial.mcap                          # BROAD: on /poses/optical
      imulog process align optitrack.mcap          # several IMUs and rigid bodies: paired by the data
      imulog process align trial.mcap --imu forearm --poses forearm_body    # one IMU on the body named
    """
    from imulog.archive.errors import ArchiveError
    from imulog.steps.align import alignment_summary, run_align
    from imulog.steps.common import error_line

    names = tuple(m.strip() for m in (cluster_markers or "").split(",") if m.strip())
    params = AlignmentParams(
        window_s=window_s,
        window_start_s=window_start_s,
        max_lag_s=max_lag_s,
        drift=drift,
        filter=FilterParams(cutoff_hz=cutoff_hz, max_gap_s=max_gap_s),
        cluster="svd" if names and cluster == "auto" and len(names) > 1 else cluster,
        markers=names,
    )
    try:
        from imulog.archive import TrialReader

        with TrialReader(trial) as reader:
            topics = reader.topics()
        n_imus = sum(t.startswith("/imu/") for t in topics)
        from imulog.steps.align_pose import aligns_on_poses

        on_poses = aligns_on_poses(topics, markers, poses)
        if on_poses and names:
            raise click.ClickException(f"{trial}: --cluster-markers names markers; this alignment is on poses")
        if names and len(imus) != 1 and n_imus > 1:
            raise click.ClickException(
                f"{trial}: --cluster-markers names the markers of one IMU: choose it with --imu (the trial has {n_imus})"
            )
        if on_poses and len(imus) != 1 and n_imus > 1:  # several IMUs: each paired with its body by the data
            from imulog.steps.align_pose_setup import run_align_pose_setup

            outcome = run_align_pose_setup(
                trial, imus=list(imus) or None, params=params, resample=resample, force=force
            )
        elif on_poses:
            from imulog.steps.align_pose import run_align_pose

            outcome = run_align_pose(
                trial, imu=imus[0] if imus else None, poses=poses, params=params, resample=resample, force=force
            )
        elif len(imus) > 1 or (not imus and n_imus > 1):
            from imulog.steps.align_setup import run_align_setup

            outcome = run_align_setup(
                trial, imus=list(imus) or None, markers=markers, params=params, resample=resample, force=force
            )
        else:
            outcome = run_align(
                trial, imu=imus[0] if imus else None, markers=markers, params=params, resample=resample, force=force
            )
        heading = None
        if len(imus) != 1 and n_imus > 1:  # oriented IMUs: a common heading frame from the clusters or bodies
            from imulog.steps.heading import refresh_heading

            try:
                heading = refresh_heading(trial)
            except (ValueError, KeyError) as exc:  # the alignment is written; say why the headings do not relate
                click.echo(f"heading: not related ({exc})", err=True)
        with TrialReader(trial) as reader:
            rec = reader.metadata.get("imulog.alignment", {})
            if len(imus) == 1 or n_imus == 1:  # one IMU aligned: its own record, whichever is main
                from imulog.steps.common import alignment_for, imu_names

                one = imus[0] if imus else imu_names(topics)[0]
                rec = alignment_for(reader.metadata, f"/imu/{one}") or rec
    except (ArchiveError, ValueError, KeyError, OSError) as exc:
        raise click.ClickException(error_line(trial, exc)) from exc
    if as_json:
        click.echo(json.dumps(rec, indent=1, default=str))
        return
    prefix = "unchanged (same inputs and parameters): " if outcome.skipped else ""
    if rec.get("setup") and outcome.step == "align" and (len(imus) != 1):
        from imulog.steps.align_summary import setup_lines

        left = [n for n in rec.get("unpaired") or {} if n not in rec["setup"]]  # rigid bodies: IMUs without one
        count = f"{len(rec['setup'])} of {len(rec['setup']) + len(left)}" if left else str(len(rec["setup"]))
        click.echo(f"{trial}: {prefix}{count} IMUs aligned")
        for line in setup_lines(rec):
            click.echo(f"  {line}")
        if heading:
            shared = heading.get("source") != "none"
            click.echo(
                f"  heading: {'one frame, ' + str(heading.get('source')) if shared else 'not shared'} "
                f"({heading.get('frame')})"
            )
        return
    q = rec.get("rotation_imu_to_cluster")
    lines = alignment_summary(rec)
    if q:
        angle_deg = math.degrees(2 * math.acos(min(1.0, abs(float(q[0])))))
        what = "IMU-to-body" if (rec.get("cluster") or {}).get("pose") else "IMU-to-cluster"
        lines.insert(1, f"{what} [{', '.join(f'{float(v):.5f}' for v in q)}] ({angle_deg:.2f} deg)")
    who = f" {str(rec.get('imu', '')).removeprefix('/imu/')}" if n_imus > 1 else ""  # which IMU, among several
    click.echo(f"{trial}:{who} {prefix}{lines[0]}")
    for line in lines[1:]:
        click.echo(f"  {line}")
