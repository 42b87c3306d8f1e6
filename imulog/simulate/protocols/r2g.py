"""R2G drinking task (R2G thesis chapter 3, Politecnico di Torino protocol).

Seated subject (table 0.70 m high, chest 0.30 m from the table edge), dominant (right) hand on
the table, bottle 1.5 forearm lengths from the table edge. Each of ``repetitions`` tasks has four
minimum-jerk phases -- ``reach`` (grasp the bottle), ``lift`` (to the mouth), ``return_bottle``,
``return_hand`` -- separated by ~4 s static periods, with a longer rest between tasks.

World frame (Vicon lab, z up, m): x forward from the subject towards the bottle, y to the
subject's left, origin on the floor below the table edge in front of the right shoulder.
Anthropometric displacements of the wrist sensor from its start (as the thesis defines them,
section 3.3.7, from mean Vicon displacements): ``h1`` along x to the bottle, ``h2`` along y
(sternum-to-shoulder; the hand moves towards the midline), ``h3`` height of the mouth above the
start along z. The sensor frame on the dorsal wrist: x along the forearm (distal), z out of the
back of the hand, y = z × x.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat
from imulog.simulate.motion import MotionPlan, submovement_law
from imulog.simulate.protocols.common import ProtocolResult, opening

PHASES = ("reach", "lift", "return_bottle", "return_hand")


@dataclass(frozen=True)
class Params:
    repetitions: int = 25  # thesis: 25 drinking tasks per trial
    table_height_m: float = 0.70  # thesis 3.2.1
    chest_to_table_m: float = 0.30  # thesis 3.2.1: seated 30 cm from the table
    bottle_forearm_ratio: float = 1.5  # thesis 3.2.1: bottle at 1.5 forearm lengths from the edge
    forearm_length_m: tuple[float, float] = (0.26, 0.02)  # mean, sd (adult anthropometric tables)
    hand_start_from_edge_m: float = 0.05  # wrist sensor at rest, in from the table edge
    wrist_to_bottle_m: float = 0.09  # wrist sensor to bottle axis when grasping
    h2_m: tuple[float, float] = (0.17, 0.02)  # sternum-to-shoulder (half shoulder breadth ~0.18)
    h3_m: tuple[float, float] = (0.42, 0.03)  # mouth height above the wrist's resting height
    mouth_dx_m: tuple[float, float] = (-0.20, 0.02)  # wrist x at the mouth relative to start
    grasp_dz_m: float = 0.05  # 'slight variation' of z at the bottle (thesis 3.3.7)
    wrist_rest_height_m: float = 0.04  # sensor above the table top with the hand resting
    durations_s: tuple[float, float, float, float] = (1.2, 1.4, 1.3, 1.1)  # reach, lift, return_bottle, return_hand
    subject_speed_sd: float = 0.12  # per-subject duration factor sd
    duration_jitter: float = 0.10  # per-repetition relative sd of a phase duration
    position_jitter_m: float = 0.01  # per-repetition waypoint sd per axis
    angle_jitter_deg: float = 5.0  # per-repetition key-orientation sd per Euler angle
    static_s: float = 4.0  # thesis 3.2.1: ~4 s static between phases
    static_jitter_s: float = 0.6
    rest_s: float = 8.0  # longer rest between tasks (task separation, thesis 3.3.2)
    rest_jitter_s: float = 1.5
    opening_static_s: float = 30.0  # thesis slide protocol used 1 min; shortened
    wave_cycles: int = 2
    wave_amplitude_deg: float = 30.0
    wave_half_swing_s: float = 0.3
    post_wave_static_s: float = 10.0
    closing_static_s: float = 5.0
    residual_velocity_mps: float = 0.0  # mean drift speed in the static periods (thesis subject 6)
    extra_submovement_probability: float = 0.0  # chance that a phase has a corrective sub-movement
    # key orientations (yaw, pitch, roll) in degrees: R = Rz(yaw) Ry(pitch) Rx(roll)
    pose_rest_deg: tuple[float, float, float] = (0.0, 5.0, 0.0)  # hand prone on the table
    pose_grasp_deg: tuple[float, float, float] = (20.0, 5.0, -75.0)  # neutral (thumb up) at the bottle
    pose_mouth_deg: tuple[float, float, float] = (45.0, -55.0, -100.0)  # forearm raised, bottle tilted
    side: str = "right"
    # variability of real (and stroke) drinking movements; every default is off, so the default trial is
    # unchanged; sources in docs/simulate.md ("Conditions of the accuracy grid")
    rotation_onset_frac: tuple[float, float] = (0.0, 0.0)  # wrist rotation starts this fraction into the phase
    rotation_end_frac: tuple[float, float] = (1.0, 1.0)  # ... and ends here (< 1: before the hand stops)
    curve_m: tuple[float, float] = (0.0, 0.0)  # bow of the hand path (m) across the straight line, uniform range
    curve_peak: tuple[float, float] = (0.5, 0.5)  # path fraction of the bow's peak (skew), uniform in [0.3, 0.7]
    placement_jitter_m: float = 0.0  # per-trial bottle placement shift sd in x and y (m), written as h1/bottle_dy_m
    bottle_offset_m: tuple[float, float] = (0.0, 0.0)  # bottle moved by this (x, y) from its protocol place (m)
    mouth_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # cup-at-mouth position moved by this (m)
    mouth_jitter_m: float = 0.0  # per-trial shift sd of the cup-to-mouth position in x, y, z (m)
    submovements: tuple[int, int] = (1, 1)  # submovements per phase (inclusive range): several velocity peaks
    submovement_overlap: tuple[float, float] = (0.4, 0.8)  # next submovement starts at this fraction of the last
    pause_probability: float = 0.0  # chance that a phase pauses (hand still) between two submovements
    pause_s: tuple[float, float] = (0.15, 0.45)  # length of such a pause (s)
    slowness: float = 1.0  # duration factor on every phase (stroke survivors: 1.5-2.5)


def _subject(params: Params, rng: np.random.Generator) -> dict:
    forearm = float(np.clip(rng.normal(*params.forearm_length_m), 0.20, 0.32))
    h1 = params.bottle_forearm_ratio * forearm - params.hand_start_from_edge_m - params.wrist_to_bottle_m
    return {
        "forearm_length_m": forearm,
        "bottle_distance_m": params.bottle_forearm_ratio * forearm,
        "h1_m": h1,
        "h2_m": float(np.clip(rng.normal(*params.h2_m), 0.10, 0.25)),
        "h3_m": float(np.clip(rng.normal(*params.h3_m), 0.30, 0.55)),
        "mouth_dx_m": float(rng.normal(*params.mouth_dx_m)),
        "table_height_m": params.table_height_m,
        "chest_to_table_m": params.chest_to_table_m,
        "speed_factor": float(np.clip(rng.normal(1.0, params.subject_speed_sd), 0.7, 1.4)),
        "yaw_offset_deg": float(rng.normal(0.0, 8.0)),
    }


def _pose(
    base: tuple[float, float, float], yaw_offset: float, jitter_deg: float, rng: np.random.Generator
) -> np.ndarray:
    y, p, r = np.asarray(base) + rng.normal(0.0, jitter_deg, 3)
    return quat.from_euler_zyx(y + yaw_offset, p, r)


def _varied(params: Params) -> bool:
    """Any time-law or path variation on (ranges may arrive as lists, e.g. from ``--set name=[a,b]``)."""
    return (
        tuple(params.rotation_onset_frac) != (0.0, 0.0)
        or tuple(params.rotation_end_frac) != (1.0, 1.0)
        or tuple(params.curve_m) != (0.0, 0.0)
        or tuple(params.submovements) != (1, 1)
        or params.pause_probability > 0
    )


def _varied_move(plan: MotionPlan, seconds: float, p1: np.ndarray, q1: np.ndarray, params: Params, rng) -> None:
    """One phase with its own time laws: translation as 1..n overlapping minimum-jerk submovements (optionally
    a pause between two), rotation over a sub-window of the phase, the path bowed across the straight line."""
    k = int(rng.integers(params.submovements[0], params.submovements[1] + 1))
    durations = rng.uniform(0.35, 0.7, k)  # relative to the primary submovement's
    durations[0] = 1.0
    onsets = np.zeros(k)
    pause_at = int(rng.integers(1, k)) if k > 1 and rng.random() < params.pause_probability else -1
    if k == 1 and rng.random() < params.pause_probability:  # a pause needs two submovements
        k, pause_at = 2, 1
        durations, onsets = np.array([1.0, rng.uniform(0.4, 0.8)]), np.zeros(2)
    for i in range(1, k):
        onsets[i] = onsets[i - 1] + durations[i - 1] * rng.uniform(*params.submovement_overlap)
    onsets, durations = onsets * seconds, durations * seconds  # the primary takes the nominal phase duration
    if pause_at > 0:  # the hand stops: the later submovements start after the earlier ones end, plus a pause
        ends = onsets[:pause_at] + durations[:pause_at]
        onsets[pause_at:] += max(0.0, float(ends.max()) - onsets[pause_at]) + rng.uniform(*params.pause_s)
    T = float(np.max(onsets + durations))
    weights = np.r_[1.0, rng.uniform(0.15, 0.5, k - 1)] if k > 1 else np.ones(1)
    law = submovement_law(T, onsets, durations, weights) if k > 1 else None
    a = rng.uniform(*params.rotation_onset_frac)
    b = max(a + 0.2, rng.uniform(*params.rotation_end_frac))
    rot_law = None if (a, b) == (0.0, 1.0) else submovement_law(T, [a * T], [(min(b, 1.0) - a) * T], [1.0])
    if rot_law is None and law is not None:
        rot_law = submovement_law(T, [0.0], [T], [1.0])  # the wrist turns smoothly; only the hand corrects
    dp = p1 - plan.p
    bow = rng.uniform(*params.curve_m)
    curve = None
    if bow > 0 and np.linalg.norm(dp) > 1e-6:
        u = dp / np.linalg.norm(dp)
        d = rng.normal(0.0, 1.0, 3)
        d -= u * (d @ u)
        curve = bow * d / np.linalg.norm(d)
    plan.move(T, p1, q1, law=law, rot_law=rot_law, curve=curve, curve_peak=float(rng.uniform(*params.curve_peak)))


def _phase_move(
    plan: MotionPlan, seconds: float, p1: np.ndarray, q1: np.ndarray, extra_p: float, rng: np.random.Generator
) -> None:
    """One phase; with probability ``extra_p`` split into a primary movement that stops short
    (80-92 % of the way), a short pause and a corrective sub-movement."""
    if rng.random() >= extra_p:
        plan.move(seconds, p1, q1)
        return
    frac = rng.uniform(0.80, 0.92)
    p_mid = plan.p + frac * (p1 - plan.p)
    q_mid = quat.multiply(
        plan.q, quat.from_rotation_vector(frac * quat.to_rotation_vector(quat.multiply(quat.conjugate(plan.q), q1)))
    )
    plan.move(seconds * frac, p_mid, q_mid)
    plan.wait(rng.uniform(0.25, 0.6))
    plan.move(max(0.35, seconds * 0.45), p1, q1)


def _static(plan: MotionPlan, seconds: float, drift_mps: float, rng: np.random.Generator) -> None:
    """A static period; with residual velocity the wrist drifts slowly for most of it."""
    if drift_mps <= 0:
        plan.wait(seconds)
        return
    lead = 0.1 * seconds
    plan.wait(lead)
    span = seconds - 2 * lead
    direction = rng.normal(0.0, 1.0, 3)
    direction /= np.linalg.norm(direction)
    plan.move(span, plan.p + direction * drift_mps * span)
    plan.wait(lead)


def build(params: Params, subject_rng: np.random.Generator, rng: np.random.Generator, trial: int = 0) -> ProtocolResult:
    anth = _subject(params, subject_rng)
    start = np.array([params.hand_start_from_edge_m, 0.0, params.table_height_m + params.wrist_rest_height_m])
    yaw0 = anth["yaw_offset_deg"]
    plan = MotionPlan(start, _pose(params.pose_rest_deg, yaw0, 0.0, rng))
    opening(plan, params, rng)
    speed = anth["speed_factor"]
    jit = params.position_jitter_m
    bottle = start + np.array([anth["h1_m"], anth["h2_m"], params.grasp_dz_m])
    mouth0 = np.array([anth["mouth_dx_m"], anth["h2_m"], anth["h3_m"]])
    # variation draws come from child streams, so the default trial's own draws never change
    vary_rng = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0]) if _varied(params) else None
    moved = tuple(params.bottle_offset_m) != (0.0, 0.0) or tuple(params.mouth_offset_m) != (0.0, 0.0, 0.0)
    if params.placement_jitter_m > 0 or params.mouth_jitter_m > 0 or moved:
        place_rng = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0])
        shift = place_rng.normal(0.0, params.placement_jitter_m, 2) + np.asarray(params.bottle_offset_m)
        bottle = bottle + np.r_[shift, 0.0]
        mouth0 = mouth0 + place_rng.normal(0.0, params.mouth_jitter_m, 3) + np.asarray(params.mouth_offset_m)
        anth["h1_m"] = float(bottle[0] - start[0])  # what the user measures for this trial
        anth["bottle_dy_m"] = float(bottle[1] - start[1])
        anth["h2_m"], anth["h3_m"], anth["mouth_dx_m"] = float(mouth0[1]), float(mouth0[2]), float(mouth0[0])
    for rep in range(1, params.repetitions + 1):
        durations = [
            d * speed * params.slowness * max(0.5, rng.normal(1.0, params.duration_jitter)) for d in params.durations_s
        ]
        grasp = bottle + rng.normal(0.0, jit, 3) * [1.0, 1.0, 0.3]
        mouth = start + mouth0 + rng.normal(0.0, jit, 3)
        put_back = grasp + rng.normal(0.0, jit * 0.5, 3) * [1.0, 1.0, 0.2]
        home = start + rng.normal(0.0, jit, 3) * [1.0, 1.0, 0.1]
        targets = [
            (grasp, _pose(params.pose_grasp_deg, yaw0, params.angle_jitter_deg, rng)),
            (mouth, _pose(params.pose_mouth_deg, yaw0, params.angle_jitter_deg, rng)),
            (put_back, _pose(params.pose_grasp_deg, yaw0, params.angle_jitter_deg, rng)),
            (home, _pose(params.pose_rest_deg, yaw0, params.angle_jitter_deg, rng)),
        ]
        for k, (label, (p1, q1), seconds) in enumerate(zip(PHASES, targets, durations, strict=True)):
            t_start = plan.t
            if vary_rng is not None:
                _varied_move(plan, seconds, p1, q1, params, vary_rng)
            else:
                _phase_move(plan, seconds, p1, q1, params.extra_submovement_probability, rng)
            plan.mark(label, t_start, plan.t, rep)
            if k < 3:
                _static(
                    plan,
                    max(0.5, params.static_s + rng.normal(0.0, params.static_jitter_s)),
                    params.residual_velocity_mps,
                    rng,
                )
        if rep < params.repetitions:
            _static(
                plan, max(2.0, params.rest_s + rng.normal(0.0, params.rest_jitter_s)), params.residual_velocity_mps, rng
            )
    plan.wait(params.closing_static_s)
    anthropometrics = {k: round(v, 6) for k, v in anth.items() if k.endswith("_m")}
    anthropometrics["side"] = params.side
    return ProtocolResult(
        plan=plan,
        task="r2g",
        anthropometrics=anthropometrics,
        trial_meta={"side": params.side, "repetitions": params.repetitions},
        end_s=plan.t,
    )
