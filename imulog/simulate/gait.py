"""A gait-lab session with known truth: 11 IMUs on the body and a full-body marker set, walking two passes.

The body (world frame: the optical system's, z up, the walkway along x) walks a pass of ``strides`` strides,
stands, turns on the spot in four steps, stands and walks back; it stands still at the start and the end.
Kinematics are built at 1 kHz and low-passed (``smooth_hz``), every signal derived from them:

* **feet**: per stance a pose on the floor (heel point, heading); heel rocker after heel strike (toe up
  ``heel_strike_deg``, turning about the heel), flat foot, toe rocker before toe off (turning about the toe
  point up to ``toe_off_deg``), swing from one stance to the next with a foot clearance bump;
* **pelvis** between the feet, its height lowest in double support; **thighs and shanks** from a two-link leg
  (hip to ankle, the knee bending forward); **trunk**, **head** on the pelvis; **upper arms** swinging opposite
  to the legs; every segment with a slow random wobble of about a degree;
* **IMUs** (``SEGMENTS``: pelvis, sternum, head, upper arms, thighs, shanks, feet) at a fixed pose on their
  segment (a mounting rotation, a lever arm), sampled at ``imu_rate_hz`` on the station's clock, with
  MTw-like noise and bias; the magnetometer sees the earth field disturbed near the floor (force plates);
  the device orientation is the truth in the ENU frame with a small heading error per sensor;
* **markers** (Plug-in-Gait-like names, ``MARKERS``) rigid on their segment plus ``soft_tissue_mm`` of smooth
  skin motion and ``noise_mm`` of noise, at ``marker_rate_hz`` on the optical clock; ``LANK``/``RANK`` (the
  malleoli) sit on the shank 2 cm from the ankle joint, beside the foot's markers.

Clocks: ``t_ref = t_dev + offset_ns + drift_ppm * 1e-6 * (t_dev - t0_ns)`` (``GaitSession.clock``). Positions m,
angles rad unless named ``_deg``, times s (``t_s``, reference clock) or int64 ns.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from imulog.process import quaternion as quat

G = 9.81
SEGMENTS = (
    "pelvis", "sternum", "head", "upper_arm_l", "upper_arm_r",
    "thigh_l", "thigh_r", "shank_l", "shank_r", "foot_l", "foot_r",
)  # fmt: skip
SERIALS = {s: f"00B4{0x2A10 + 7 * i:04X}" for i, s in enumerate(SEGMENTS)}
MASTER = "01200777"
L_TOE = 0.22  # heel to toe contact point, m
ANKLE = np.array([0.05, 0.0, 0.08])  # ankle joint in the foot frame (origin at the heel on the floor), m
THIGH_M, SHANK_M = 0.45, 0.44

# marker positions in their segment's frame (m); y is to the left, so a right-side point has -y
_M_LEFT = {
    "foot": {"HEE": (-0.01, 0.0, 0.03), "TOE": (0.20, 0.0, 0.03), "MT5": (0.16, 0.045, 0.02)},
    "shank": {"ANK": (-0.012, 0.035, 0.016), "TIB": (0.03, 0.05, 0.20), "SHN": (0.06, 0.0, 0.30)},
    "thigh": {"THI": (0.0, 0.07, -0.25), "THF": (0.07, 0.0, -0.20), "KNE": (0.0, 0.05, -0.45)},
    "upper_arm": {"UPA": (-0.03, 0.05, -0.15), "ELB": (0.0, 0.04, -0.30), "UA3": (0.045, 0.045, -0.12)},
}
_M_CENTRAL = {
    "pelvis": {"LASI": (0.10, 0.12, 0.08), "RASI": (0.10, -0.12, 0.08), "LPSI": (-0.10, 0.045, 0.10),
               "RPSI": (-0.10, -0.045, 0.10)},
    "sternum": {"C7": (-0.08, 0.0, 0.45), "T10": (-0.12, 0.0, 0.22), "CLAV": (0.08, 0.0, 0.40),
                "STRN": (0.12, 0.0, 0.25), "RBAK": (-0.10, -0.10, 0.32)},
    "head": {"LFHD": (0.09, 0.07, 0.12), "RFHD": (0.09, -0.07, 0.12), "LBHD": (-0.09, 0.07, 0.10),
             "RBHD": (-0.09, -0.07, 0.10)},
}  # fmt: skip
# IMU lever arms in the segment frame (m)
_IMU_AT = {
    "foot": (0.11, 0.0, 0.07), "shank": (0.04, 0.035, 0.22), "thigh": (0.03, 0.065, -0.15),
    "upper_arm": (0.0, 0.05, -0.18), "pelvis": (-0.12, 0.0, 0.08), "sternum": (0.13, 0.0, 0.30),
    "head": (0.0, 0.0, 0.18),
}  # fmt: skip


def _mirror(p: tuple[float, float, float], side: str) -> np.ndarray:
    return np.array([p[0], p[1] if side == "l" else -p[1], p[2]])


def marker_layout() -> dict[str, dict[str, np.ndarray]]:
    """``{segment: {marker: position in the segment frame (m)}}`` of every segment of ``SEGMENTS``."""
    out: dict[str, dict[str, np.ndarray]] = {k: {m: np.array(p) for m, p in v.items()} for k, v in _M_CENTRAL.items()}
    for side in "lr":
        for seg, ms in _M_LEFT.items():
            out[f"{seg}_{side}"] = {f"{side.upper()}{m}": _mirror(p, side) for m, p in ms.items()}
    return out


def imu_lever(segment: str) -> np.ndarray:
    base = segment.rsplit("_", 1)
    return _mirror(_IMU_AT[base[0]], base[1]) if base[-1] in ("l", "r") else np.array(_IMU_AT[segment])


MARKERS = {seg: tuple(ms) for seg, ms in marker_layout().items()}


@dataclass
class GaitParams:
    strides: int = 6  # full strides per foot per pass
    stride_length_m: float = 1.25
    stride_time_s: float = 1.1
    stance_fraction: float = 0.62
    clearance_m: float = 0.11
    heel_strike_deg: float = 18.0
    toe_off_deg: float = 40.0
    stand_s: float = 3.0  # standing at the start and end
    smooth_hz: float = 12.0
    imu_rate_hz: float = 100.0
    marker_rate_hz: float = 100.0
    offset_s: float = -37.17  # t_ref - t_dev at the station's first sample
    drift_ppm: float = 20.0
    imu_lead_s: float = 1.3  # the IMUs start this long before the markers, stop ``imu_tail_s`` after
    imu_tail_s: float = 0.8
    soft_tissue_mm: float = 1.0
    noise_mm: float = 0.3
    gyr_noise_dps: float = 0.07
    gyr_bias_dps: float = 0.2
    acc_noise_mps2: float = 0.005
    acc_bias_mps2: float = 0.02
    scale_sd: float = 0.002
    lab_yaw_deg: float = 30.0  # the optical world's x axis, from east (the devices' ENU frame)
    device_heading_sd_deg: float = 2.0


@dataclass
class GaitSession:
    """Everything simulated: reference times ``t_s`` (1 kHz), per segment pose, per IMU signals, markers, truth."""

    params: GaitParams
    t_s: np.ndarray
    q_seg: dict[str, np.ndarray]  # segment to world
    p_seg: dict[str, np.ndarray]
    q_mount: dict[str, np.ndarray]  # IMU to segment
    imu: dict[str, dict[str, np.ndarray]]  # segment -> t_dev_s, acc, gyr, mag, quat (device, sensor to ENU)
    marker_t_s: np.ndarray
    marker_labels: list[str]
    marker_pos: np.ndarray  # (F, M, 3) m, NaN in gaps
    stances: dict[str, list[tuple[float, float]]]  # foot -> (t_on, t_off) s, reference clock
    clock: dict = field(default_factory=dict)


def _minjerk(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def _footsteps(p: GaitParams) -> tuple[dict[str, list[dict]], float]:
    """Stance poses per foot: ``{t_on, t_off, x, y, yaw, walk}`` (walk: a walking step leaves/lands it)."""
    half, step = p.stride_time_s / 2, p.stride_length_m / 2
    swing = (1 - p.stance_fraction) * p.stride_time_s
    width = 0.09
    feet: dict[str, list[dict]] = {"l": [], "r": []}
    t = p.stand_s

    def stand(side: str, x: float, y: float, yaw: float, t_on: float) -> None:
        feet[side].append({"t_on": t_on, "x": x, "y": y, "yaw": yaw, "walk": True})

    x0, direction, yaw = 0.0, 1.0, 0.0
    stand("l", x0, width, yaw, -10.0)
    stand("r", x0, -width, yaw, -10.0)
    for pass_ in range(2):
        # right foot leads: a half step, then full steps alternating, then the closing step
        n_steps = 2 * p.strides + 1
        for k in range(n_steps):
            side = "r" if k % 2 == 0 else "l"
            y_side = -width if side == "r" else width
            last = feet[side][-1]
            advance = step if k == 0 else (2 * step if k < n_steps - 1 else step)
            feet[side][-1]["t_off"] = t
            xs = last["x"] + direction * advance
            ys = direction * y_side if pass_ == 0 else -y_side
            stand(side, xs, ys if pass_ == 0 else ys, yaw, t + swing)
            t += half
        t += swing + p.stand_s - half
        if pass_ == 1:
            break
        # turn on the spot, four steps of 90 deg per two steps, about the midpoint of the feet
        cx = 0.5 * (feet["l"][-1]["x"] + feet["r"][-1]["x"])
        for k in range(4):
            side = "l" if k % 2 == 0 else "r"
            yaw_k = yaw + np.pi * (k + 1) / 4
            lat = np.array([-np.sin(yaw_k), np.cos(yaw_k)]) * (width if side == "l" else -width)
            feet[side][-1]["t_off"] = t
            stand(side, cx + lat[0] - 0.05 * np.cos(yaw_k), lat[1] - 0.05 * np.sin(yaw_k), yaw_k, t + 0.45)
            feet[side][-1]["walk"] = False
            t += 0.6
        yaw += np.pi
        direction = -direction
        for side in "lr":
            feet[side][-1]["walk"] = True
        t += p.stand_s
    end = t
    for side in "lr":
        feet[side][-1]["t_off"] = end + 10.0
    return feet, end


def _foot_kinematics(stances: list[dict], t: np.ndarray, p: GaitParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heel position (N, 3), yaw and pitch (rad, pitch > 0 toe down) of one foot at times ``t``."""
    heel = np.zeros((len(t), 3))
    yaw = np.zeros(len(t))
    pitch = np.zeros(len(t))
    hs, to = -np.radians(p.heel_strike_deg), np.radians(p.toe_off_deg)
    d_heel, d_toe = 0.08, 0.16
    for k, s in enumerate(stances):
        nxt = stances[k + 1] if k + 1 < len(stances) else None
        walk_in = k > 0 and stances[k - 1]["walk"] and s["walk"]
        walk_out = nxt is not None and s["walk"] and nxt["walk"]
        c, sn = np.cos(s["yaw"]), np.sin(s["yaw"])
        m = (t >= s["t_on"]) & (t < s["t_off"])
        th = np.zeros(m.sum())
        tm = t[m]
        if walk_in:
            th += hs * (1 - _minjerk((tm - s["t_on"]) / d_heel))
        toe_part = np.zeros(m.sum(), bool)
        if walk_out:
            u = (tm - (s["t_off"] - d_toe)) / d_toe
            toe_part = u > 0
            th[toe_part] = to * _minjerk(u[toe_part])
        fwd = np.array([c, sn, 0.0])
        h = np.tile([s["x"], s["y"], 0.0], (m.sum(), 1))
        # toe rocker: the toe point stays, the heel rises
        toe = np.array([s["x"], s["y"], 0.0]) + L_TOE * fwd
        r = th[toe_part]
        h[toe_part] = toe - L_TOE * (np.cos(r)[:, None] * fwd + np.array([0, 0, 1.0]) * np.sin(r)[:, None])
        heel[m], yaw[m], pitch[m] = h, s["yaw"], th
        if nxt is None:
            continue
        m = (t >= s["t_off"]) & (t < nxt["t_on"])
        u = (t[m] - s["t_off"]) / (nxt["t_on"] - s["t_off"])
        r0 = to if walk_out else 0.0
        r1 = hs if walk_out else 0.0
        h0 = toe - L_TOE * (np.cos(r0) * fwd + np.array([0, 0, 1.0]) * np.sin(r0))
        h1 = np.array([nxt["x"], nxt["y"], 0.0])
        sj = _minjerk(u)[:, None]
        clear = (p.clearance_m if walk_out else 0.05) * np.sin(np.pi * u) ** 2
        heel[m] = h0 + (h1 - h0) * sj + np.column_stack([0 * u, 0 * u, clear])
        dyaw = np.angle(np.exp(1j * (nxt["yaw"] - s["yaw"])))
        yaw[m] = s["yaw"] + dyaw * sj[:, 0]
        pitch[m] = r0 + (r1 - r0) * sj[:, 0]
    return heel, np.unwrap(yaw), pitch


def _lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float) -> np.ndarray:
    from scipy import signal

    sos = signal.butter(2, cutoff_hz, fs=rate_hz, output="sos")
    return signal.sosfiltfilt(sos, x, axis=0)


def _rz(a: np.ndarray) -> np.ndarray:
    return quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), a)


def _ry(a: np.ndarray) -> np.ndarray:
    return quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), a)


def _rx(a: np.ndarray) -> np.ndarray:
    return quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), a)


def _frame(z_axis: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Quaternions of frames with ``z_axis`` as z and x the part of ``forward`` perpendicular to it."""
    z = z_axis / np.linalg.norm(z_axis, axis=1, keepdims=True)
    x = forward - np.sum(forward * z, axis=1, keepdims=True) * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    return _continuous(quat.from_rotation_matrix(np.stack([x, y, z], axis=2)))


def _continuous(q: np.ndarray) -> np.ndarray:
    """``q`` with signs chosen so that consecutive quaternions never flip (q and -q are one rotation)."""
    flip = np.sum(q[1:] * q[:-1], axis=1) < 0
    sign = np.concatenate([[1.0], np.where(np.cumsum(flip) % 2 == 1, -1.0, 1.0)])
    return q * sign[:, None]


def _wobble(n: int, rate_hz: float, sd_rad: float, rng: np.random.Generator) -> np.ndarray:
    w = _lowpass(rng.normal(size=(n, 3)), rate_hz, 0.7)
    return quat.from_rotation_vector(w / np.std(w, axis=0) * sd_rad)


def body_kinematics(p: GaitParams, rng: np.random.Generator):
    """Reference times (s, 1 kHz) and per segment (world orientation, origin position), and the stances."""
    feet, end = _footsteps(p)
    rate = 1000.0
    t = np.arange(-p.imu_lead_s - 1.0, end + p.imu_tail_s + 1.0, 1 / rate)
    q_seg: dict[str, np.ndarray] = {}
    p_seg: dict[str, np.ndarray] = {}
    heels, fwds = {}, {}
    for side in "lr":
        heel, yaw, pitch = _foot_kinematics(feet[side], t, p)
        heel, yaw, pitch = (_lowpass(a, rate, p.smooth_hz) for a in (heel, yaw, pitch))
        q = quat.multiply(_rz(yaw), _ry(pitch))
        q_seg[f"foot_{side}"], p_seg[f"foot_{side}"] = q, heel
        heels[side], fwds[side] = heel, np.column_stack([np.cos(yaw), np.sin(yaw), 0 * yaw])
    mid = 0.5 * (heels["l"] + heels["r"])
    gap = np.linalg.norm((heels["l"] - heels["r"])[:, :2], axis=1)
    fwd_mean = fwds["l"] + fwds["r"]
    body_yaw = _lowpass(np.unwrap(np.arctan2(fwd_mean[:, 1], fwd_mean[:, 0])), rate, 1.0)
    ahead = np.sum((heels["l"] - heels["r"]) * np.column_stack([np.cos(body_yaw), np.sin(body_yaw), 0 * t]), axis=1)
    pel = _lowpass(mid, rate, 1.5) + 0.09 * np.column_stack([np.cos(body_yaw), np.sin(body_yaw), 0 * t])
    pel[:, 2] = 0.90 - 0.05 * _lowpass(np.clip(gap - 0.18, 0, None), rate, 2.0) ** 2 / 0.25
    n = len(t)
    # pelvic rotation and obliquity about +-5 deg with the step, tilt at twice the stride frequency
    tilt = 0.05 + 0.03 * _lowpass(np.abs(ahead), rate, 3.0)
    q_pel = quat.multiply(_rz(body_yaw + 0.15 * ahead), quat.multiply(_rx(0.14 * ahead), _ry(tilt)))
    q_seg["pelvis"] = quat.multiply(q_pel, _wobble(n, rate, 0.01, rng))
    p_seg["pelvis"] = pel
    for side, sgn in (("l", 1.0), ("r", -1.0)):
        hip = pel + quat.rotate(q_pel, np.array([0.0, sgn * 0.09, 0.0]))
        ankle = heels[side] + quat.rotate(q_seg[f"foot_{side}"], ANKLE)
        d_vec = ankle - hip
        d = np.minimum(np.linalg.norm(d_vec, axis=1), 0.995 * (THIGH_M + SHANK_M))
        u = d_vec / np.linalg.norm(d_vec, axis=1, keepdims=True)
        a = (THIGH_M**2 - SHANK_M**2 + d**2) / (2 * d)
        h = np.sqrt(np.maximum(THIGH_M**2 - a**2, 0.0))
        v = fwds[side] - np.sum(fwds[side] * u, axis=1, keepdims=True) * u
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        knee = _lowpass(hip + a[:, None] * u + h[:, None] * v, rate, 6.0)  # smooths the straight-knee kink
        q_seg[f"thigh_{side}"], p_seg[f"thigh_{side}"] = _frame(hip - knee, fwds[side]), hip
        q_seg[f"shank_{side}"], p_seg[f"shank_{side}"] = _frame(knee - ankle, fwds[side]), ankle
    q_trunk = quat.multiply(_rz(body_yaw - 0.10 * ahead), quat.multiply(_rx(-0.05 * ahead), _ry(np.full(n, 0.08))))
    q_seg["sternum"] = quat.multiply(q_trunk, _wobble(n, rate, 0.015, rng))
    p_seg["sternum"] = pel + quat.rotate(q_pel, np.array([0.0, 0.0, 0.10]))
    q_seg["head"] = quat.multiply(quat.multiply(_rz(body_yaw), _ry(np.full(n, 0.1))), _wobble(n, rate, 0.05, rng))
    p_seg["head"] = p_seg["sternum"] + quat.rotate(q_seg["sternum"], np.array([0.0, 0.0, 0.55]))
    for side, sgn in (("l", 1.0), ("r", -1.0)):
        swing = -sgn * 0.45 * ahead  # the arm swings forward with the opposite leg
        q = quat.multiply(q_seg["sternum"], quat.multiply(_ry(-swing), _rx(np.full(n, sgn * 0.08))))
        q_seg[f"upper_arm_{side}"] = quat.multiply(q, _wobble(n, rate, 0.02, rng))
        p_seg[f"upper_arm_{side}"] = p_seg["sternum"] + quat.rotate(q_seg["sternum"], np.array([0.0, sgn * 0.18, 0.42]))
    stances = {
        f"foot_{s}": [(float(x["t_on"]), float(x["t_off"])) for x in feet[s] if x["t_on"] >= 0 and x["t_off"] < end]
        for s in "lr"
    }
    return t, q_seg, p_seg, stances, end


def _earth_field(pos_world: np.ndarray, lab_yaw: float) -> np.ndarray:
    """The field in ENU (normalised a.u., dip 65 deg), turned and weakened near the floor (force plates)."""
    dip = np.radians(65.0)
    near = np.exp(-np.maximum(pos_world[:, 2], 0.0) / 0.12) * (1 + 0.5 * np.sin(2.1 * pos_world[:, 0]))
    turn = np.radians(25.0) * near
    h = np.cos(dip) * (1 - 0.3 * near)
    return np.column_stack([-h * np.sin(turn), h * np.cos(turn), -np.sin(dip) * np.ones(len(near))])


def simulate_gait(params: GaitParams | None = None, *, seed: int = 0) -> GaitSession:
    """Simulate the session (module docstring); same seed, same session."""
    p = params or GaitParams()
    rng = np.random.default_rng([seed, 0x6A17])
    t, q_seg, p_seg, stances, end = body_kinematics(p, rng)
    rate = 1000.0
    q_enu_world = _rz(np.radians(p.lab_yaw_deg))
    # station clock: device time of the first IMU sample and the reference times of every sample
    t0_dev = 35.83
    n_imu = int((end + p.imu_lead_s + p.imu_tail_s) * p.imu_rate_hz)
    t_dev = t0_dev + np.arange(n_imu) / p.imu_rate_hz
    t_ref = t_dev + p.offset_s + p.drift_ppm * 1e-6 * (t_dev - t0_dev)
    q_mount, imu = {}, {}
    for seg in SEGMENTS:
        qm = quat.normalize(rng.normal(size=4))
        q_mount[seg] = qm
        qi = quat.multiply(q_seg[seg], qm)
        pi = p_seg[seg] + quat.rotate(q_seg[seg], imu_lever(seg))
        acc_w = np.gradient(np.gradient(pi, 1 / rate, axis=0), 1 / rate, axis=0) + np.array([0, 0, G])
        qi = _continuous(qi)
        dq = np.gradient(qi, 1 / rate, axis=0)
        omega = 2 * quat.multiply(quat.conjugate(qi), dq)[:, 1:]
        acc_s = quat.rotate_inverse(qi, acc_w)
        mag_s = quat.rotate_inverse(quat.multiply(q_enu_world, qi), _earth_field(pi, 0.0))

        def at(x: np.ndarray) -> np.ndarray:
            return np.column_stack([np.interp(t_ref, t, x[:, j]) for j in range(x.shape[1])])

        acc, gyr, mag = at(acc_s), at(omega), at(mag_s)
        scale_a, scale_g = 1 + rng.normal(0, p.scale_sd, 3), 1 + rng.normal(0, p.scale_sd, 3)
        acc = acc * scale_a + rng.normal(0, p.acc_bias_mps2, 3) + rng.normal(0, p.acc_noise_mps2, acc.shape)
        gyr = gyr * scale_g + np.radians(rng.normal(0, p.gyr_bias_dps, 3) + rng.normal(0, p.gyr_noise_dps, gyr.shape))
        mag = mag + rng.normal(0, 0.005, mag.shape)
        head_err = _rz(np.radians(rng.normal(0, p.device_heading_sd_deg)))
        q_dev = quat.multiply(head_err, quat.multiply(q_enu_world, at(qi)))
        imu[seg] = {"t_dev_s": t_dev, "acc": acc, "gyr": gyr, "mag": mag, "quat": quat.normalize(q_dev)}
    layout = marker_layout()
    mt = np.arange(0.0, end, 1 / p.marker_rate_hz)
    labels, cols = [], []
    for seg in SEGMENTS:
        qs = np.column_stack([np.interp(mt, t, q_seg[seg][:, j]) for j in range(4)])
        ps = np.column_stack([np.interp(mt, t, p_seg[seg][:, j]) for j in range(3)])
        for name, local in layout[seg].items():
            skin = _lowpass(rng.normal(size=(len(mt), 3)), p.marker_rate_hz, 0.5)
            skin *= p.soft_tissue_mm * 1e-3 / np.std(skin, axis=0)
            labels.append(name)
            cols.append(ps + quat.rotate(quat.normalize(qs), local) + skin + rng.normal(0, p.noise_mm * 1e-3, ps.shape))
    pos = np.stack(cols, axis=1)
    for _ in range(6):  # short occlusions
        m, k = rng.integers(len(labels)), rng.integers(len(mt) - 30)
        pos[k : k + rng.integers(3, 20), m] = np.nan
    clock = {
        "offset_ns": int(round((p.offset_s) * 1e9)),
        "drift_ppm": p.drift_ppm,
        "t0_ns": int(round(t0_dev * 1e9)),
        "formula": "t_ref = t_dev + offset_ns + drift_ppm * 1e-6 * (t_dev - t0_ns)",
    }
    return GaitSession(p, t, q_seg, p_seg, q_mount, imu, mt, labels, pos, stances, clock)
