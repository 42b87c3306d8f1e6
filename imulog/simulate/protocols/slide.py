"""Slide bench (R2G thesis chapter 2): the BlueBuddy taped on a wooden cart on two parallel rails.

Protocol (thesis 2.2.4): 1 min static, a wave about the sensitive axis (to align Vicon and IMU),
1 min static, then ``repetitions`` (30) slides. Each slide: the cart, resting against the end
stopper where the counterweight holds it, is moved by hand to the start (``manual``), held there
~10 s, released: the 300 g counterweight accelerates it at a constant rate (``slide``) until it
hits the end stopper (``impact``: an exponentially damped oscillation, the thesis's template),
then ~10 s static. The covered distance is ~15 cm. The sensor's sliding axis is -x, +x, -y, +y
for trials 0, 1, 2, 3 (then repeating): the thesis rotates the device by 90 degrees per trial.

World frame: rails along world +x (release direction), table top at 0.75 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat
from imulog.simulate.motion import MotionPlan
from imulog.simulate.protocols.common import ProtocolResult, opening

AXES = {
    "-x": (180.0, np.array([1.0, 0.0, 0.0])),
    "+x": (0.0, np.array([1.0, 0.0, 0.0])),
    "-y": (90.0, np.array([0.0, 1.0, 0.0])),
    "+y": (-90.0, np.array([0.0, 1.0, 0.0])),
}
AXIS_ORDER = ("-x", "+x", "-y", "+y")


@dataclass(frozen=True)
class Params:
    repetitions: int = 30  # thesis 2.2.4: 30 controlled slides per axis direction
    slide_axis: str | None = None  # '-x', '+x', '-y', '+y'; None: by trial number (thesis order)
    distance_m: float = 0.15  # thesis: ~15 cm actually covered
    distance_jitter_m: float = 0.003
    counterweight_kg: float = 0.3  # thesis: ~300 g counterweight
    cart_mass_kg: float = 0.45  # wooden cart + bearings + sensor (assumed)
    rolling_friction: float = 0.02  # ball bearings on rails (assumed coefficient)
    accel_jitter: float = 0.03  # relative sd of the slide acceleration between slides
    tension_rise_s: float = 0.03  # the string tensions smoothly (no infinite jerk)
    impact_frequency_hz: float = 20.0  # end-stop collision: damped oscillation (thesis template)
    impact_damping_ratio: float = 0.35
    impact_settle_s: float = 0.5
    manual_s: float = 1.5  # hand moves the cart back to the start
    hold_s: float = 10.0  # thesis: released after about 10 s
    rest_s: float = 10.0  # thesis: 10 s static after each slide
    time_jitter_s: float = 1.0
    opening_static_s: float = 60.0  # thesis: 1 min static
    wave_cycles: int = 3
    wave_amplitude_deg: float = 30.0
    wave_half_swing_s: float = 0.3
    post_wave_static_s: float = 60.0  # thesis: another 1 min static
    closing_static_s: float = 5.0
    mount_misalignment_deg: float = 1.0  # the device is taped along a drawn guide
    table_height_m: float = 0.75


def release_law(distance_m: float, accel_mps2: float, rise_s: float, freq_hz: float, zeta: float, settle_s: float):
    """Time law of a release: smooth tension rise to a constant acceleration, impact at ``distance``,
    then a damped oscillation about the stopper. Returns (law(t) -> (s, s', s''), t_impact, total_s),
    with ``s`` the travelled fraction of ``distance_m``."""
    A, tr = accel_mps2, rise_s

    def free(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        u = np.clip(t / tr, 0.0, 1.0)
        r = u**3 * (10 - 15 * u + 6 * u * u)
        r1 = u**4 * (2.5 - 3 * u + u * u)
        r2 = u**5 * (0.5 - 0.5 * u + u * u / 7.0)
        late = t > tr
        tl = np.where(late, t - tr, 0.0)
        a = np.where(late, A, A * r)
        v = np.where(late, A * tr * 0.5 + A * tl, A * tr * r1)
        x = np.where(late, A * tr * tr / 7.0 + A * tr * 0.5 * tl + 0.5 * A * tl * tl, A * tr * tr * r2)
        return x, v, a

    # impact time: x(t_i) = distance (t_i > rise for realistic parameters)
    c = distance_m - A * tr * tr / 7.0
    tl = (-A * tr * 0.5 + np.sqrt((A * tr * 0.5) ** 2 + 2 * A * c)) / A
    t_imp = tr + tl
    v_imp = A * tr * 0.5 + A * tl
    w = 2 * np.pi * freq_hz
    sigma = zeta * w
    wd = w * np.sqrt(1 - zeta**2)

    def law(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        x, v, a = free(t)
        te = np.maximum(t - t_imp, 0.0)
        e = np.exp(-sigma * te)
        sn, cs = np.sin(wd * te), np.cos(wd * te)
        amp = v_imp / wd
        xi = distance_m + amp * e * sn
        vi = amp * e * (wd * cs - sigma * sn)
        ai = amp * e * ((sigma**2 - wd**2) * sn - 2 * sigma * wd * cs)
        hit = t >= t_imp
        x = np.where(hit, xi, x)
        v = np.where(hit, vi, v)
        a = np.where(hit, ai, a)
        return x / distance_m, v / distance_m, a / distance_m

    return law, t_imp, t_imp + settle_s


def build(params: Params, subject_rng: np.random.Generator, rng: np.random.Generator, trial: int = 0) -> ProtocolResult:
    axis_name = params.slide_axis or AXIS_ORDER[trial % 4]
    if axis_name not in AXES:
        raise ValueError(f"slide_axis must be one of {', '.join(AXES)}, got {axis_name!r}")
    yaw, sensitive = AXES[axis_name]
    mis = rng.normal(0.0, params.mount_misalignment_deg, 3)
    q = quat.from_euler_zyx(yaw + mis[0], mis[1], mis[2])
    home = np.array([0.60, 0.10, params.table_height_m + 0.03])  # cart against the end stopper
    plan = MotionPlan(home, q)
    opening(plan, params, rng, axes=(sensitive,))
    g = 9.81
    m_w, m_c = params.counterweight_kg, params.cart_mass_kg
    accel = (m_w * g - params.rolling_friction * m_c * g) / (m_w + m_c)
    x_dir = np.array([1.0, 0.0, 0.0])
    for rep in range(1, params.repetitions + 1):
        d = params.distance_m + rng.normal(0.0, params.distance_jitter_m)
        start = home - x_dir * d
        t0 = plan.t
        plan.move(max(0.5, params.manual_s + rng.normal(0.0, 0.2)), start)
        plan.mark("manual", t0, plan.t, rep)
        plan.wait(max(2.0, params.hold_s + rng.normal(0.0, params.time_jitter_s)))
        a = accel * (1.0 + rng.normal(0.0, params.accel_jitter))
        law, t_imp, total = release_law(
            d, a, params.tension_rise_s, params.impact_frequency_hz, params.impact_damping_ratio, params.impact_settle_s
        )
        t_rel = plan.t
        plan.move(total, home, law=law)
        plan.mark("slide", t_rel, t_rel + t_imp, rep)
        plan.mark("impact", t_rel + t_imp, plan.t, rep)
        if rep < params.repetitions:
            plan.wait(max(2.0, params.rest_s + rng.normal(0.0, params.time_jitter_s)))
    plan.wait(params.closing_static_s)
    return ProtocolResult(
        plan=plan,
        task="slide",
        anthropometrics={},
        trial_meta={
            "slide_axis": axis_name,
            "slide_distance_m": params.distance_m,
            "slide_accel_mps2": round(accel, 6),
        },
        end_s=plan.t,
    )
