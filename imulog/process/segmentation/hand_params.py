"""The parameters of the accelerometer's phase-boundary refinement
(:func:`~imulog.process.segmentation.hand.refine_with_accelerometer`), in a module of their own so that ``hand``
stays a module of steps (imulog defaults, units in the names; each step is described in
:mod:`~imulog.process.segmentation.hand`)."""

from __future__ import annotations

from dataclasses import dataclass

from imulog.param_rules import check_rules


@dataclass(frozen=True)
class HandParams:
    """Parameters of :func:`refine_with_accelerometer` (imulog defaults; units in the names).

    enabled: use the accelerometer at all (off: boundaries follow the gyroscope only).
    cutoff_hz: highest low-pass cut-off (Hz) of the accelerometer; target_level_mps2 and min_cutoff_hz lower
        it for a noisy sensor (see :func:`~imulog.process.segmentation.boundaries.adaptive_cutoff_hz`).
    rest_window_s: length (s) of the rest window that gives ``f_rest`` and the noise.
    rest_distance_s: the rest window is centred this far (s) from the phase, or at the gap's middle when the
        gap is shorter than twice this.
    guard_s: the rest window keeps this distance (s) from the neighbouring phases.
    n_sigma: acceleration level = ``n_sigma`` x the rest noise (rms of per-axis robust sd, m/s^2); also the
        speed level of step 8's slower last parts, in sd of the velocity's noise.
    min_level_mps2: lower bound of that level (quantised, nearly noise-free sensors).
    velocity_level_mps: the hand moves where the velocity integrated from the rest exceeds this (m/s).
    quiet_s: the walk stops at the first run this long (s) without motion.
    min_run_s: shorter runs above the level are noise, not motion (s).
    max_shift_s: a boundary walking further than this (s) beyond the gyroscope boundary is not trusted (see
        settled_beyond_shift for a continuation after the walk).
    cruise_velocity_mps: the hand also moves where that velocity exceeds this (m/s) whatever its acceleration
        (overlapping submovements of a slow phase cruise at a few cm/s with next to no acceleration); 0: off.
    continuation_s: a translation resuming within this time (s) after the offset can extend the phase.
    continuation_n_level: ... when its ``|a|`` stays at least this many times the acceleration level for
        ``min_run_s`` (a sub-movement after a pause, not a noise spike).
    bridge_n_level: a phase also continues over a dip in acceleration to the next run of ``|a|`` above this many
        times the level when the speed stays above ``velocity_level_mps`` in between (the hand never stopped;
        overlapping submovements, issue 31); 0: off.
    flank_top_n_level: the acceleration flank leading out of (into) the rest is fitted between the level and
        this many times the level, and extrapolated to zero acceleration (0: off; see :func:`flank_zero`).
    flank_search_s: that flank must reach its top within this time (s) inside the phase from the boundary.
    max_extrapolation_s: the extrapolated boundary moves at most this far (s) beyond the level's boundary.
    speed_fit_s: the speed flank (a movement too slow for its acceleration) is fitted over at most this long (s)
        before the speed reaches ``velocity_level_mps`` (a 6-s reach needs about 1 s; a daily-life rest can
        be hours long, and the fit's cost grows with the square of its length: 10 s made a day's phases step
        1.6x slower than 4 s, with the same held-out segmentation figures).
    speed_reach_s: the velocity before an onset is integrated this far (s) into the phase (at least
        ``flank_search_s``), so that a slow start reaches ``velocity_level_mps`` for its speed flank (a 6-s reach
        needs 1.5 s; 0.6 s left 56 of 1200 stroke-slow onsets without a flank, 0.115 s late on average: issue 31).
    profile_rest_s: length (s) of the rest window near the gap's end that step 9's fit is referred to; 0: off (the
        default until issue 31's seventh round; with its two checks, 1 s, it moved 9 development trials up and
        none down, and on the held-out set one up and one down, docs/accuracy.md).
    profile_durations_s: the range (s) of the fitted last movement's duration ``T``.
    profile_min_s: step 9 moves an offset only when it lies at least this far (in units of the fitted movement's
        duration) before the fitted arrival: in the main deceleration, at 56 % of the peak speed or more.
    profile_grid_hz: step 9 searches the arrival on block means at this rate first (s^-1), then at every sample.
    profile_residual_ratio: step 9 moves an offset only when the fit's residual over the phase's last part has at
        most this many times the rms of its residual over the rest after the fitted arrival (a phase stopping
        sharply at the offset is not the fitted profile's movement, docs/accuracy.md, issue 31 seventh round).
    resume_cruise: a submovement resumed after a pause (``|a|`` above ``bridge_n_level`` levels, under the
        ``continuation_n_level``) continues the phase when its speed exceeds ``cruise_velocity_mps`` (issue 31
        point 1: stroke-curved last submovements of 9-11 cm/s at 2-3 levels; a rest's 1-2 cm/s drift stays under).
    settled_beyond_shift: a continuation that settles before the rest window extends the phase even when it ends
        more than ``max_shift_s`` after the gyroscope's offset (the bound stays on step 5's walk).
    profile_alone: step 9 judges the fitted last movement on its own: its arrival anywhere after the offset (also
        before step 2's window, which can be a real rest after a slow last submovement that steps 5-8 missed, when
        the hand moves at the offset as seen from that window too) and
        its peak speed after the offset (not its speed at the offset, which is small at a dip between
        submovements) against the velocity's noise (issue 31 tenth round; off: tied to step 2's window as before).
    gyro_floor: a gyroscope boundary that no step moved loses its samples at the rest window's gyroscope noise
        floor (step 10, :mod:`~imulog.process.segmentation.noise_floor`, issue 31 ninth round).
    flank_combine: step 7's ``t0`` is the acceleration flank's and the speed flank's averaged with weights inverse
        to their variances (:func:`~imulog.process.segmentation.flanks.combined_t0`; off: the speed flank only
        when there is no acceleration flank; issue 31 eleventh round, an option).
    flank_rest_level: step 7's acceleration flank is fitted with its rest level known to be zero to the precision
        of the rest window's mean (``rest_window_s`` of zero samples before the flank, :func:`flank_zero`'s
        ``rest_samples``): a dip or bump of the low-passed noise at the flank's foot no longer passes for the
        rest's level (issue 31 thirteenth round, the devices' noise; an option).
    flank_noise: step 7's acceleration flank is a generalised least-squares fit weighing the low-passed noise's
        correlation, known from step 1's filter (:mod:`~imulog.process.segmentation.flank_noise`; issue 31
        fourteenth round, an option).
    flank_noise_band_hz: the highest frequency (Hz) that fit trusts (the noise model's white floor is the filtered
        noise's spectral level there, :func:`~imulog.process.segmentation.flank_noise.floor`); ``cutoff_hz``'s 25 Hz.
    rest_check_s: a slow last part of a phase at ``velocity_level_mps`` or more with next to no acceleration
        extends the offset when the velocity relative to the rest window stays under half that speed for this
        long (s) after the window (the window is a rest, not a hand cruising or drifting); 0: off.
    rest_drift: step 8's limit on that velocity is raised to the trial's own where its still rests read more than
        half ``velocity_level_mps`` (:mod:`~imulog.process.segmentation.rest_drift`, 95 % of them; never lowered;
        issue 31 eleventh round).
    slow_inside: step 8 also follows a slow last part that the offset lies inside of (the hand moving at the offset at
        ``n_sigma`` sd or more of the velocity's noise, under ``velocity_level_mps``, as seen from a verified rest
        window), to where it decelerates into the rest (:func:`~imulog.process.segmentation.arrival.inside_last_part`;
        issue 31 twelfth round).
    movement_gaps: the rest next to a phase (step 2's gap) also ends at the nearest movement of the detector that
        overlaps no phase (the calibration wave before the first reach; :mod:`~imulog.process.segmentation.gaps`,
        issue 31 twelfth round, an option: on `combined` development trials such a movement right after a phase is
        often the phase's own last part), when :func:`refine_with_accelerometer` is given the movements.
    walk_noise: step 5's speed criteria before an onset count only where the speed stands ``n_sigma`` sd out of the
        velocity's own noise (:func:`~imulog.process.segmentation.arrival.velocity_noise_mps`, measured at the rest
        window): far from the window the integrated velocity's drift reaches the fixed levels (issue 31 twelfth
        round).
    """

    enabled: bool = True
    cutoff_hz: float = 25.0
    target_level_mps2: float = 0.08
    min_cutoff_hz: float = 4.0
    rest_window_s: float = 0.5
    rest_distance_s: float = 1.5
    guard_s: float = 0.05
    n_sigma: float = 5.0
    min_level_mps2: float = 0.02
    velocity_level_mps: float = 0.03
    quiet_s: float = 0.05
    min_run_s: float = 0.03
    max_shift_s: float = 2.5
    continuation_s: float = 1.0
    continuation_n_level: float = 3.0
    cruise_velocity_mps: float = 0.06
    bridge_n_level: float = 1.5
    flank_top_n_level: float = 3.0
    flank_search_s: float = 0.6
    max_extrapolation_s: float = 0.3
    speed_fit_s: float = 4.0
    rest_check_s: float = 1.5
    speed_reach_s: float = 2.0
    profile_rest_s: float = 1.0
    profile_durations_s: tuple[float, float] = (0.5, 8.0)
    profile_grid_hz: float = 10.0
    profile_min_s: float = 0.25
    profile_residual_ratio: float = 2.0
    resume_cruise: bool = True
    settled_beyond_shift: bool = True
    gyro_floor: bool = False
    profile_alone: bool = True
    flank_combine: bool = False
    rest_drift: bool = False
    slow_inside: bool = False
    movement_gaps: bool = False
    walk_noise: bool = True
    flank_rest_level: bool = False
    flank_noise: bool = False
    flank_noise_band_hz: float = 25.0
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES
