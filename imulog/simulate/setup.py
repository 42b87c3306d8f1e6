"""A whole setup with known truth: several IMUs of one station, their marker clusters, and a distractor.

Built on the two-segment arm (:mod:`imulog.simulate.arm`, with the trunk IMU: ``upper_arm``, ``forearm``,
``trunk``, each with a cluster ``{segment}_O/X/Y/A``). On top of it:

* the IMU station has its own clock: every IMU's device time is the reference time minus ``offset_s`` and a
  drift of ``drift_ppm`` (one clock for all IMUs, as the sensors of one recording);
* every marker carries a smooth soft-tissue displacement (``soft_tissue_mm``, 0.5 Hz low-pass), so clusters
  are rigid to about a millimetre as skin markers are;
* ``ELB_FA``, a marker on the forearm ``distractor_mm`` from the elbow centre, perpendicular to both segments
  (beside the joint, like a malleolus marker beside a foot cluster): its distances to the upper-arm markers
  change by a few mm only, but it turns with the forearm.

With ``rigid_bodies``, an optical system that tracks rigid bodies instead (OptiTrack, Qualisys 6DOF): the markers
are replaced by one pose channel per IMU, ``/poses/{imu}_body``, the body frame being the sensor's turned by a fixed
rotation (``SetupTrial.imu_to_body``, w,x,y,z, 15-35 deg), its origin the IMU's position, on the reference clock.

Truth: ``SetupTrial.alignment`` (offset_ns, drift_ppm, t0_ns of the station clock) and the arm truth
(``rotation_imu_to_cluster`` per segment). Positions in m, times in int64 ns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.model import ImuStream, MarkerStream, PoseStream
from imulog.simulate.arm import ArmTrial, simulate_arm

DISTRACTOR = "ELB_FA"


@dataclass
class SetupTrial:
    """The arm trial with the station clock applied and the extra marker; ``alignment`` the true clock."""

    arm: ArmTrial
    alignment: dict
    imu_to_body: dict[str, list[float]] | None = None  # with rigid_bodies: IMU-to-body rotation per IMU (w,x,y,z)

    @property
    def recording(self):
        return self.arm.recording


def _smooth(n: int, rate_hz: float, sd_m: float, rng: np.random.Generator) -> np.ndarray:
    from scipy import signal

    if sd_m <= 0:
        return np.zeros((n, 3))
    x = rng.normal(size=(n, 3))
    sos = signal.butter(2, 0.5, fs=rate_hz, output="sos")
    y = signal.sosfiltfilt(sos, x, axis=0)
    return y / np.std(y, axis=0) * sd_m


def simulate_setup(
    *,
    seed: int = 0,
    duration_s: float = 60.0,
    offset_s: float = 0.3217,
    drift_ppm: float = 40.0,
    soft_tissue_mm: float = 1.0,
    distractor_mm: float = 12.0,
    frequency_hz: tuple[float, float] = (0.3, 1.2),
    rigid_bodies: bool = False,
) -> SetupTrial:
    """Simulate the setup (see the module docstring); ``frequency_hz`` the range of the joints' movement
    frequencies (livelier than the arm trial's default 0.05-0.25 Hz, so that 5-s windows hold a lag);
    ``rigid_bodies``: one rigid body's poses per IMU instead of the markers."""
    arm = simulate_arm(seed=seed, duration_s=duration_s, trunk_imu=True, frequency_hz=frequency_hz)
    rec = arm.recording
    mk = rec.markers[0]
    rate = arm.params.rate_hz
    rng = np.random.default_rng([seed, 0x5E7])
    pos = mk.pos + np.stack([_smooth(len(mk.t_ns), rate, soft_tissue_mm * 1e-3, rng) for _ in mk.labels], axis=1)
    tr = arm.truth
    from imulog.process import quaternion as quat

    shoulder = np.asarray(arm.params.shoulder_m, dtype=np.float64)
    elbow_w = shoulder + quat.rotate(tr.q_world_trunk, tr.elbow_m)
    wrist_w = shoulder + quat.rotate(tr.q_world_trunk, tr.wrist_m)
    upper = quat.rotate(tr.q_world_trunk, tr.elbow_m) / np.linalg.norm(tr.elbow_m, axis=1, keepdims=True)
    fore = (wrist_w - elbow_w) / np.linalg.norm(wrist_w - elbow_w, axis=1, keepdims=True)
    # beside the joint: along the forearm, away from the upper arm's line, so flexion moves it on an arc
    side = fore - np.sum(fore * upper, axis=1, keepdims=True) * upper
    side /= np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-9)
    extra = elbow_w + distractor_mm * 1e-3 * side + _smooth(len(mk.t_ns), rate, soft_tissue_mm * 1e-3, rng)
    markers = MarkerStream(
        mk.name, mk.t_ns, [*mk.labels, DISTRACTOR], np.concatenate([pos, extra[:, None]], axis=1), meta=mk.meta
    )
    t0 = int(mk.t_ns[0])
    off_ns = int(round(offset_s * 1e9))
    imus = []
    for s in rec.imus:
        t_ref = s.t_ns.astype(np.int64)
        # t_ref = t_dev + offset + drift (t_dev - t0): solved for t_dev
        t_dev = t0 + np.round((t_ref - off_ns - t0) / (1 + drift_ppm * 1e-6)).astype(np.int64)
        imus.append(ImuStream(s.name, t_dev, s.acc, s.gyr, s.mag, s.temperature, s.frame_id, dict(s.meta)))
    rec.imus = imus
    rec.markers = [markers]
    truth = {"offset_ns": off_ns, "drift_ppm": float(drift_ppm), "t0_ns": t0}
    if not rigid_bodies:
        return SetupTrial(arm, truth)
    rec.markers, rec.poses, turns = [], [], {}
    for name, q_s2w in tr.q_world_sensor.items():
        axis = rng.normal(size=3)
        angle = np.radians(rng.uniform(15.0, 35.0))
        q_s2b = np.array([np.cos(angle / 2), *(np.sin(angle / 2) * axis / np.linalg.norm(axis))])
        q_b2w = quat.multiply(q_s2w, np.broadcast_to(quat.conjugate(q_s2b), q_s2w.shape))
        rec.poses.append(PoseStream(f"/poses/{name}_body", tr.t_ns, tr.imu_position_m[name], q_b2w))
        turns[name] = [float(v) for v in q_s2b]
    return SetupTrial(arm, truth, turns)
