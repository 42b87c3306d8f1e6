"""Repetitive activities of daily living (Doshi 2011, chapter 5, Table 5.1), wrist-worn sensor.

``activity`` 1: slide in 10 gunny bags placed about one foot away (gross, 1-D along the sensor's
y axis); 2: fill an egg crate (12 cells) with cotton balls (fine, 3-D); 3: lift an empty plastic
cup 10 times like a biceps curl (gross, 2-D in the sensor's x-y plane); 4: slide 10 curtain rings
off a shower-curtain bar (gross, 1-D along the sensor's x axis, arm raised). Each repetition is
a ``reach`` then the activity movement (``pull``, ``place``, ``lift``/``lower``, ``slide``), all
minimum-jerk (Doshi's own simulator, section 6.6, uses bell-shaped minimum-jerk velocity).

Besides the IMU text and Vicon CSV, the trial is also written as raw ADC text from a WiTilt v2.5
board (MMA7260Q, ±2 g, 10-bit: zero g at ~512 counts, 256 counts per g; thesis 4.2.1), lines
``X=512 Y=498 Z=600``, co-located with the IMU (same sensor frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat
from imulog.simulate.motion import MotionPlan
from imulog.simulate.protocols.common import ProtocolResult, opening

ACTIVITIES = {1: "gunny_bags", 2: "egg_crate", 3: "cup_lift", 4: "curtain_rings"}


@dataclass(frozen=True)
class Params:
    activity: int | None = None  # 1-4 (Table 5.1); None: (trial % 4) + 1
    repetitions: int | None = None  # None: 10 (activities 1, 3, 4) or 12 (egg crate)
    bag_distance_m: float = 0.30  # 'about one foot'
    ring_slide_m: float = 0.25
    cup_elbow_angle_deg: float = 110.0  # elbow flexion range of the curl
    forearm_length_m: float = 0.26
    crate_spacing_m: float = 0.045  # egg-cell pitch
    move_s: float = 1.1
    pause_s: float = 0.4
    rest_s: float = 1.5
    duration_jitter: float = 0.12
    position_jitter_m: float = 0.01
    table_height_m: float = 0.72
    opening_static_s: float = 10.0
    wave_cycles: int = 2
    wave_amplitude_deg: float = 30.0
    wave_half_swing_s: float = 0.3
    post_wave_static_s: float = 5.0
    closing_static_s: float = 5.0
    adc_rate_hz: float = 100.0  # assumed (Doshi's 6-DOF board samples at 100 Hz; WiTilt's rate is not stated)
    adc_zero_counts: tuple[float, float] = (512.0, 6.0)  # zero-g level mean, sd between axes
    adc_counts_per_g: tuple[float, float] = (256.0, 4.0)  # sensitivity mean, sd between axes
    adc_noise_counts: float = 1.5  # Doshi measured ~2 counts sd on his 10-bit boards
    side: str = "right"


def build(params: Params, subject_rng: np.random.Generator, rng: np.random.Generator, trial: int = 0) -> ProtocolResult:
    activity = params.activity or (trial % 4) + 1
    if activity not in ACTIVITIES:
        raise ValueError(f"activity must be 1-4 (Doshi Table 5.1), got {activity}")
    reps = params.repetitions or (12 if activity == 2 else 10)
    speed = float(np.clip(subject_rng.normal(1.0, 0.15), 0.6, 2.0))
    z_table = params.table_height_m + 0.04
    jit = params.position_jitter_m

    def dur(scale: float = 1.0) -> float:
        return params.move_s * scale * speed * max(0.5, rng.normal(1.0, params.duration_jitter))

    def pause(scale: float = 1.0) -> None:
        plan.wait(params.pause_s * scale * rng.uniform(0.6, 1.4))

    if activity == 1:  # sensor y along the pull direction (world x): yaw -90 deg
        q_rest = quat.from_euler_zyx(-90.0, 0.0, 0.0)
        rest = np.array([0.10, 0.0, z_table])
    elif activity == 3:  # forearm horizontal on the table, sensor x along the forearm
        q_rest = quat.from_euler_zyx(0.0, 0.0, -90.0)
        rest = np.array([0.10, 0.0, z_table])
    elif activity == 4:  # arm raised, sensor x along the bar (world y)
        q_rest = quat.from_euler_zyx(90.0, 0.0, 0.0)
        rest = np.array([0.30, 0.0, 1.45])
    else:
        q_rest = quat.from_euler_zyx(0.0, 5.0, 0.0)
        rest = np.array([0.10, 0.0, z_table])
    plan = MotionPlan(rest, q_rest)
    opening(plan, params, rng)

    def q_jit(deg: float = 4.0) -> np.ndarray:
        return quat.multiply(q_rest, quat.from_euler_zyx(*rng.normal(0.0, deg, 3)))

    def phase(
        label: str, rep: int, seconds: float, p1: np.ndarray, q1: np.ndarray, lift: np.ndarray | None = None
    ) -> None:
        t0 = plan.t
        plan.move(seconds, p1, q1, lift=lift)
        plan.mark(label, t0, plan.t, rep)

    for rep in range(1, reps + 1):
        if activity == 1:
            far = rest + np.array([params.bag_distance_m, 0.0, 0.0]) + rng.normal(0.0, jit, 3) * [1, 1, 0.2]
            phase("reach", rep, dur(), far, q_jit())
            pause()
            phase("pull", rep, dur(1.3), rest + rng.normal(0.0, jit, 3) * [1, 1, 0.2], q_jit())
        elif activity == 2:
            bowl = rest + np.array([0.20, 0.18, 0.0]) + rng.normal(0.0, jit / 2, 3)
            cell = rest + np.array(
                [
                    0.25 + ((rep - 1) // 4) * params.crate_spacing_m,
                    -0.05 + ((rep - 1) % 4) * params.crate_spacing_m,
                    0.03,
                ]
            )
            phase("reach", rep, dur(0.8), bowl, q_jit(10.0), lift=np.array([0.0, 0.0, 0.04]))
            pause()
            phase(
                "place", rep, dur(0.8), cell + rng.normal(0.0, jit / 3, 3), q_jit(10.0), lift=np.array([0.0, 0.0, 0.06])
            )
            pause()
        elif activity == 3:
            theta = np.radians(params.cup_elbow_angle_deg * rng.uniform(0.9, 1.05))
            L = params.forearm_length_m
            elbow = rest - np.array([L, 0.0, 0.0])
            top = elbow + L * np.array([np.cos(theta), 0.0, np.sin(theta)])
            mid_chord = 0.5 * (rest + top)
            arc_mid = elbow + L * np.array([np.cos(theta / 2), 0.0, np.sin(theta / 2)])
            bulge = arc_mid - mid_chord  # the bump approximates the circular arc of the wrist
            q_top = quat.multiply(
                q_jit(), quat.from_rotation_vector(np.array([0.0, 0.0, -theta]))
            )  # flexion about the sensor z (= elbow axis, world +y)
            phase("lift", rep, dur(), top, q_top, lift=bulge)
            pause()
            phase("lower", rep, dur(), rest + rng.normal(0.0, jit / 2, 3), q_jit(), lift=bulge)
        else:
            ring = rest + np.array([0.0, -0.05, 0.0]) + rng.normal(0.0, jit, 3)
            phase("reach", rep, dur(0.7), ring, q_jit())
            pause()
            phase("slide", rep, dur(), ring + np.array([0.0, params.ring_slide_m, 0.0]), q_jit())
            pause()
            phase("return", rep, dur(0.8), rest + rng.normal(0.0, jit / 2, 3), q_jit())
        if rep < reps:
            plan.wait(params.rest_s * rng.uniform(0.6, 1.5))
    plan.wait(params.closing_static_s)
    adc = {
        "rate_hz": params.adc_rate_hz,
        "zero_counts": rng.normal(params.adc_zero_counts[0], params.adc_zero_counts[1], 3),
        "counts_per_g": rng.normal(params.adc_counts_per_g[0], params.adc_counts_per_g[1], 3),
        "noise_counts": params.adc_noise_counts,
    }
    return ProtocolResult(
        plan=plan,
        task="adl",
        anthropometrics={"forearm_length_m": params.forearm_length_m, "side": params.side},
        trial_meta={
            "side": params.side,
            "activity": activity,
            "activity_name": ACTIVITIES[activity],
            "repetitions": reps,
        },
        end_s=plan.t,
        extra={"adc_model": adc},
    )
