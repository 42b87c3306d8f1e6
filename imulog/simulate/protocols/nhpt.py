"""Nine-hole peg test (Bai et al. 2023, Sensors 23:360; Mathiowetz et al. 1985 for the board).

A single IMU on the back of the hand. The subject takes the pegs one at a time from the container
and puts them into the holes in the order 1..9 (as Bai et al. ask, their Figure 3), then takes them
out again one at a time back to the container. Every pick-up and every insertion has a short pause
with zero velocity (Bai et al. section 3: what their ZUPT relies on). Transports follow a lifted
arc (minimum-jerk chord plus a ``64 tau^3 (1-tau)^3`` lift). Phase labels: ``to_container``,
``place``, ``to_hole``, ``remove`` and a final ``return_hand``; ``task_index`` = peg number
(``(test - 1) * 9 + peg`` with several tests).

World frame: x forward (away from the subject), y to the subject's left, z up; table top 0.72 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat
from imulog.simulate.motion import MotionPlan
from imulog.simulate.protocols.common import ProtocolResult, opening


@dataclass(frozen=True)
class Params:
    repetitions: int = 1  # complete tests (9 pegs in, 9 pegs out) per trial
    pegs: int = 9
    hole_spacing_m: float = 0.032  # standard board: 3 x 3 holes 32 mm apart (Mathiowetz 1985)
    board_distance_m: float = 0.30  # hole-grid centre in front of the hand's rest position
    container_offset_m: tuple[float, float] = (0.0, 0.12)  # container relative to the grid centre (x, y)
    table_height_m: float = 0.72
    hand_height_m: float = 0.06  # sensor on the back of the hand above the table when picking
    insert_height_m: float = 0.09  # above the table when inserting a peg (peg length 32 mm)
    lift_m: float = 0.05  # arc height of a transport
    transport_s: float = 0.40  # a healthy adult completes the test in ~18 s (Mathiowetz norms)
    pause_s: float = 0.18  # zero-velocity pause at pick-up and insertion (Bai et al.)
    slowness: tuple[float, float] = (1.0, 0.1)  # per-subject time factor (mean, sd); >1 for patients
    duration_jitter: float = 0.12
    position_jitter_m: float = 0.004
    wrist_angle_deg: float = 15.0  # wrist flexion/pronation change when picking/inserting
    rest_between_tests_s: float = 8.0
    opening_static_s: float = 20.0
    wave_cycles: int = 2
    wave_amplitude_deg: float = 30.0
    wave_half_swing_s: float = 0.3
    post_wave_static_s: float = 5.0
    closing_static_s: float = 5.0
    side: str = "right"


def build(params: Params, subject_rng: np.random.Generator, rng: np.random.Generator, trial: int = 0) -> ProtocolResult:
    slowness = float(np.clip(subject_rng.normal(*params.slowness), 0.6, 4.0))
    z_pick = params.table_height_m + params.hand_height_m
    rest = np.array([0.05, 0.0, z_pick])
    centre = rest + np.array([params.board_distance_m, 0.0, 0.0])
    container = centre + np.array([params.container_offset_m[0], params.container_offset_m[1], 0.0])
    s = params.hole_spacing_m
    holes = [
        centre + np.array([(1 - r) * s, (c - 1) * s, params.insert_height_m - params.hand_height_m])
        for r in range(3)
        for c in range(3)
    ]
    q_rest = quat.from_euler_zyx(10.0, 10.0, 0.0)
    plan = MotionPlan(rest, q_rest)
    opening(plan, params, rng)
    lift = np.array([0.0, 0.0, params.lift_m])

    def pose(jitter: float = 1.0) -> np.ndarray:
        d = rng.normal(0.0, params.wrist_angle_deg * jitter, 3) * [0.5, 1.0, 1.0]
        return quat.multiply(q_rest, quat.from_euler_zyx(*d))

    def go(label: str, target: np.ndarray, index: int, arc: bool) -> None:
        t0 = plan.t
        seconds = params.transport_s * slowness * max(0.5, rng.normal(1.0, params.duration_jitter))
        plan.move(
            seconds,
            target + rng.normal(0.0, params.position_jitter_m, 3),
            pose(),
            lift=lift * rng.uniform(0.7, 1.3) if arc else None,
        )
        plan.mark(label, t0, plan.t, index)
        plan.wait(params.pause_s * slowness * rng.uniform(0.7, 1.4))

    for test in range(params.repetitions):
        base = test * params.pegs
        for k in range(params.pegs):
            go("to_container", container, base + k + 1, arc=k > 0)
            go("place", holes[k % 9], base + k + 1, arc=True)
        for k in range(params.pegs):
            go("to_hole", holes[k % 9], base + k + 1, arc=True)
            go("remove", container, base + k + 1, arc=True)
        t0 = plan.t
        plan.move(params.transport_s * slowness * 1.3, rest + rng.normal(0.0, params.position_jitter_m, 3), q_rest)
        plan.mark("return_hand", t0, plan.t, base + params.pegs)
        if test < params.repetitions - 1:
            plan.wait(params.rest_between_tests_s)
    plan.wait(params.closing_static_s)
    return ProtocolResult(
        plan=plan,
        task="nhpt",
        anthropometrics={"side": params.side},
        trial_meta={"side": params.side, "pegs": params.pegs},
        end_s=plan.t,
    )
