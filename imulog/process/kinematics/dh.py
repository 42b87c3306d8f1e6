"""The ISB-consistent Denavit-Hartenberg upper-limb model of Caruso et al. (IEEE Access 2024, Table 1).

Three segments (trunk TR, upper arm UA, forearm FA) and six revolute joints:

====  =========================  ==============================  =====================  ====  ==========
 j    joint                      theta_j (rad)                   d_j (m)                a_j   alpha_j
====  =========================  ==============================  =====================  ====  ==========
 1    plane of elevation          q1                              0                      0     +pi/2
 2    elevation                   q2                              0                      0     -pi/2
 3    axial (intra-extra) rot.    q3 - pi/2                       -l_UA                  0     -pi/2
 4    flexion-extension           q4 - pi/2                       0                      0     -pi/2
 5    carrying angle (fixed)      q5 - (pi/2 + delta)             0                      0     -pi/2
 6    pronation-supination        q6 - pi/2                       -l_FA / cos(delta)     0     -pi/2
====  =========================  ==============================  =====================  ====  ==========

with ``delta = atan(h / l_FA)`` (eq. 1; ``2h`` = distance between the radial and ulnar styloids).
Each link transform is the standard ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``. Frame 3 is the UA frame,
centred in the elbow (``p_UA``), frame 6 the FA frame, centred in the wrist (``p_FA``, ulnar styloid).

The base (trunk) frame 0 is centred in the shoulder joint: ``x`` lateral (to the right for a right
arm), ``y`` anterior, ``z`` up (the paper's Appendix A: with elevation 90 deg the humerus points
along ``x`` at plane of elevation 0 and along ``y`` at 90 deg).

The five free joint angles are ordered as :data:`JOINT_NAMES`; the carrying angle is a model
parameter. User-facing parameters are in degrees and metres; every array here is in radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

__all__ = [
    "JOINT_LABELS",
    "JOINT_NAMES",
    "ArmModel",
    "ForwardKinematics",
    "JointLimits",
    "forward_kinematics",
    "jacobians",
]

JOINT_NAMES = (
    "plane_of_elevation",
    "elevation",
    "axial_rotation",
    "flexion_extension",
    "pronation_supination",
)
JOINT_LABELS = (
    "shoulder plane of elevation",
    "shoulder elevation",
    "shoulder intra-extra rotation",
    "elbow flexion-extension",
    "elbow pronation-supination",
)
N_FREE = 5


@dataclass(frozen=True)
class ArmModel:
    """Subject-specific geometry of the DH model (defaults: the paper's subject, section II-C).

    ``upper_arm_length_m``: shoulder centre to elbow centre, l_UA (0.30 m).
    ``forearm_length_m``: elbow centre to wrist centre, l_FA (0.30 m).
    ``styloid_distance_m``: distance 2h between the radial and ulnar styloids (0.06 m, delta = 5.7 deg).
    ``carrying_angle_deg``: constant carrying angle q5 (20 deg, goniometer with the elbow extended).
    """

    upper_arm_length_m: float = 0.30
    forearm_length_m: float = 0.30
    styloid_distance_m: float = 0.06
    carrying_angle_deg: float = 20.0

    def __post_init__(self) -> None:
        if not (self.upper_arm_length_m > 0 and self.forearm_length_m > 0):
            raise ValueError("segment lengths must be positive (metres)")
        if self.styloid_distance_m < 0:
            raise ValueError("styloid_distance_m must be >= 0 (metres)")

    @property
    def delta_rad(self) -> float:
        """delta = atan(h / l_FA) (eq. 1), rad."""
        return math.atan2(0.5 * self.styloid_distance_m, self.forearm_length_m)

    def dh_table(self) -> np.ndarray:
        """(6, 4) array of ``[theta offset (rad), d (m), a (m), alpha (rad)]`` for joints 1..6."""
        h = math.pi / 2
        dl = self.delta_rad
        return np.array(
            [
                [0.0, 0.0, 0.0, h],
                [0.0, 0.0, 0.0, -h],
                [-h, -self.upper_arm_length_m, 0.0, -h],
                [-h, 0.0, 0.0, -h],
                [-(h + dl), 0.0, 0.0, -h],
                [-h, -self.forearm_length_m / math.cos(dl), 0.0, -h],
            ]
        )

    def packed(self) -> np.ndarray:
        """Flat (38,) float array for the numba kernels: the DH table, the carrying angle (rad), then the cosines
        and sines of the six link twists alpha (constants, computed once instead of at every evaluation)."""
        table = self.dh_table()
        trig = [math.cos(a) for a in table[:, 3]] + [math.sin(a) for a in table[:, 3]]
        return np.concatenate([table.ravel(), [math.radians(self.carrying_angle_deg)], trig])

    @classmethod
    def from_metadata(cls, anthropometrics: dict) -> ArmModel:
        """Model from an ``imulog.anthropometrics`` record (missing keys keep the defaults)."""
        keys = ("upper_arm_length_m", "forearm_length_m", "styloid_distance_m", "carrying_angle_deg")
        return cls(**{k: float(anthropometrics[k]) for k in keys if k in anthropometrics})


@dataclass(frozen=True)
class JointLimits:
    """Physiological joint limits g1 (Table 1 of the paper), degrees, as (lower, upper) pairs."""

    plane_of_elevation_deg: tuple[float, float] = (-120.0, 120.0)  # -2pi/3 .. 2pi/3
    elevation_deg: tuple[float, float] = (0.0, 165.0)  # 0 .. 11pi/12
    axial_rotation_deg: tuple[float, float] = (-120.0, 120.0)  # -2pi/3 .. 2pi/3
    flexion_extension_deg: tuple[float, float] = (0.0, 150.0)  # 0 .. 5pi/6
    pronation_supination_deg: tuple[float, float] = (0.0, 180.0)  # 0 .. pi

    def __post_init__(self) -> None:
        for name in JOINT_NAMES:
            lo, hi = getattr(self, f"{name}_deg")
            if not lo <= hi:
                raise ValueError(f"joint limit {name}: lower {lo} > upper {hi} (deg)")

    def as_rad(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` arrays (5,) in rad, ordered as :data:`JOINT_NAMES`."""
        lo = np.radians([getattr(self, f"{n}_deg")[0] for n in JOINT_NAMES])
        hi = np.radians([getattr(self, f"{n}_deg")[1] for n in JOINT_NAMES])
        return lo, hi

    @classmethod
    def from_metadata(cls, record: dict) -> JointLimits:
        """From ``{"joint_limits_deg": {"elevation": [lo, hi], ...}}`` (missing joints keep the defaults)."""
        given = record.get("joint_limits_deg", {}) or {}
        unknown = sorted(set(given) - set(JOINT_NAMES))
        if unknown:
            raise ValueError(
                f"unknown joint(s) in joint_limits_deg: {', '.join(unknown)}; use {', '.join(JOINT_NAMES)}"
            )
        return cls(**{f"{k}_deg": (float(v[0]), float(v[1])) for k, v in given.items()})


# --------------------------------------------------------------------------------------------
# numba kernels (one configuration)


@numba.njit(cache=True, fastmath=False)
def _fk_kernel(q, model, frames_r, frames_p):
    """Fill ``frames_r`` (7, 3, 3) and ``frames_p`` (7, 3) with the rotation and origin of frames 0..6.

    ``q`` (5,) free joint angles in rad; ``model`` :meth:`ArmModel.packed` (DH table, carrying angle, twists).
    """
    for i in range(3):
        for j in range(3):
            frames_r[0, i, j] = 1.0 if i == j else 0.0
        frames_p[0, i] = 0.0
    for k in range(6):
        off = model[4 * k]
        d = model[4 * k + 1]
        a = model[4 * k + 2]
        if k < 4:
            th = q[k] + off
        elif k == 4:
            th = model[24] + off
        else:
            th = q[4] + off
        ct = math.cos(th)
        st = math.sin(th)
        ca = model[25 + k]  # cos(alpha), sin(alpha): packed by ArmModel.packed
        sa = model[31 + k]
        # local link transform Rz(th) Tz(d) Tx(a) Rx(al)
        l00 = ct
        l01 = -st * ca
        l02 = st * sa
        l10 = st
        l11 = ct * ca
        l12 = -ct * sa
        l20 = 0.0
        l21 = sa
        l22 = ca
        px = a * ct
        py = a * st
        pz = d
        for i in range(3):
            r0 = frames_r[k, i, 0]
            r1 = frames_r[k, i, 1]
            r2 = frames_r[k, i, 2]
            frames_r[k + 1, i, 0] = r0 * l00 + r1 * l10 + r2 * l20
            frames_r[k + 1, i, 1] = r0 * l01 + r1 * l11 + r2 * l21
            frames_r[k + 1, i, 2] = r0 * l02 + r1 * l12 + r2 * l22
            frames_p[k + 1, i] = frames_p[k, i] + r0 * px + r1 * py + r2 * pz


@numba.njit(cache=True)
def _jac_kernel(frames_r, frames_p, jw_ua, jw_fa, jp_el, jp_wr):
    """Analytic Jacobians (3, 5) of the UA/FA orientation (base-frame angular velocity per unit joint
    rate) and of the elbow/wrist positions, from the frames filled by :func:`_fk_kernel`."""
    # joint columns c -> DH joint index k (0-based): 0,1,2,3 -> 0,1,2,3 ; 4 -> 5
    for c in range(5):
        k = c if c < 4 else 5
        zx = frames_r[k, 0, 2]
        zy = frames_r[k, 1, 2]
        zz = frames_r[k, 2, 2]
        ox = frames_p[k, 0]
        oy = frames_p[k, 1]
        oz = frames_p[k, 2]
        jw_fa[0, c] = zx
        jw_fa[1, c] = zy
        jw_fa[2, c] = zz
        # wrist: z x (p6 - o_k)
        dx = frames_p[6, 0] - ox
        dy = frames_p[6, 1] - oy
        dz = frames_p[6, 2] - oz
        jp_wr[0, c] = zy * dz - zz * dy
        jp_wr[1, c] = zz * dx - zx * dz
        jp_wr[2, c] = zx * dy - zy * dx
        if k < 3:
            jw_ua[0, c] = zx
            jw_ua[1, c] = zy
            jw_ua[2, c] = zz
            dx = frames_p[3, 0] - ox
            dy = frames_p[3, 1] - oy
            dz = frames_p[3, 2] - oz
            jp_el[0, c] = zy * dz - zz * dy
            jp_el[1, c] = zz * dx - zx * dz
            jp_el[2, c] = zx * dy - zy * dx
        else:
            for i in range(3):
                jw_ua[i, c] = 0.0
                jp_el[i, c] = 0.0


@numba.njit(cache=True)
def _fk_batch(q, model, r_ua, r_fa, p_el, p_wr):
    frames_r = np.empty((7, 3, 3))
    frames_p = np.empty((7, 3))
    for n in range(q.shape[0]):
        _fk_kernel(q[n], model, frames_r, frames_p)
        r_ua[n] = frames_r[3]
        r_fa[n] = frames_r[6]
        p_el[n] = frames_p[3]
        p_wr[n] = frames_p[6]


@numba.njit(cache=True)
def _jac_batch(q, model, jw_ua, jw_fa, jp_el, jp_wr):
    frames_r = np.empty((7, 3, 3))
    frames_p = np.empty((7, 3))
    for n in range(q.shape[0]):
        _fk_kernel(q[n], model, frames_r, frames_p)
        _jac_kernel(frames_r, frames_p, jw_ua[n], jw_fa[n], jp_el[n], jp_wr[n])


# --------------------------------------------------------------------------------------------
# vectorised public API


@dataclass
class ForwardKinematics:
    """Segment orientations (N, 3, 3) in the trunk frame and joint centres (N, 3) in m."""

    r_upper_arm: np.ndarray
    r_forearm: np.ndarray
    elbow_m: np.ndarray
    wrist_m: np.ndarray


def _as_q(q_rad: np.ndarray) -> tuple[np.ndarray, bool]:
    q = np.ascontiguousarray(q_rad, dtype=np.float64)
    single = q.ndim == 1
    q = np.atleast_2d(q)
    if q.shape[1] != N_FREE:
        raise ValueError(f"joint angles must have {N_FREE} columns ({', '.join(JOINT_NAMES)}), got {q.shape}")
    return q, single


def forward_kinematics(q_rad: np.ndarray, model: ArmModel = ArmModel()) -> ForwardKinematics:
    """DH forward kinematics of (N, 5) or (5,) free joint angles (rad, :data:`JOINT_NAMES` order)."""
    q, single = _as_q(q_rad)
    n = len(q)
    out = ForwardKinematics(np.empty((n, 3, 3)), np.empty((n, 3, 3)), np.empty((n, 3)), np.empty((n, 3)))
    _fk_batch(q, model.packed(), out.r_upper_arm, out.r_forearm, out.elbow_m, out.wrist_m)
    if single:
        return ForwardKinematics(out.r_upper_arm[0], out.r_forearm[0], out.elbow_m[0], out.wrist_m[0])
    return out


def jacobians(q_rad: np.ndarray, model: ArmModel = ArmModel()) -> dict[str, np.ndarray]:
    """Analytic Jacobians (N, 3, 5) (or (3, 5)) w.r.t. the free joint angles (rad).

    ``omega_upper_arm`` / ``omega_forearm``: base-frame angular velocity of the segment per unit joint
    rate (``dR/dq_j = [w_j]x R``); ``elbow`` / ``wrist``: m/rad of the joint-centre positions.
    """
    q, single = _as_q(q_rad)
    n = len(q)
    out = {k: np.zeros((n, 3, 5)) for k in ("omega_upper_arm", "omega_forearm", "elbow", "wrist")}
    _jac_batch(q, model.packed(), out["omega_upper_arm"], out["omega_forearm"], out["elbow"], out["wrist"])
    if single:
        return {k: v[0] for k, v in out.items()}
    return out
