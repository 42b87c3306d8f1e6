"""Accelerometer and gyroscope calibration (R2G thesis eqs. 2.1-2.5, after Stancin & Tomazic).

Sensor model (eq. 2.1): ``q_s = K V q + q0`` (sensitivity K, misalignment V, bias q0). Calibration
(eq. 2.2) inverts it: ``q = C (q_s - q0)`` with the calibration matrix ``C = (K V)^-1``.

Accelerometer, six static orientations (each axis up, then down): with ``A+``/``A-`` the 3x3
matrices whose column i is the mean reading with axis i pointing up/down, the bias is the mean of
the six readings (eq. 2.3, ``(A+ + A-) 1 / 6``) and, because the true readings are ``+-g e_i``,
``A+ - A- = 2 g (KV)`` so ``C = 2 g (A+ - A-)^-1``.

Gyroscope, a static recording plus one known rotation about each axis: the bias is the static
mean (the thesis's ``Omega_o``); the sensitivity column i is the bias-free reading integrated over
the rotation about axis i divided by its known angle (eq. 2.5, ``(Omega_s + Omega_o) Omega^-1``
with the thesis's sign convention for the bias), and ``C`` its inverse.

Units: acc m/s^2, gyr rad/s, angles rad, rates Hz.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "CALIBRATION_FORMAT",
    "AxisCalibration",
    "Calibration",
    "SegmentParams",
    "accelerometer_six_position",
    "apply",
    "find_static_segments",
    "find_rotation_segments",
    "gyroscope_from_rotations",
    "six_position_means",
]

CALIBRATION_FORMAT = "imulog.calibration/1"
GRAVITY_M_S2 = 9.80665


@dataclass
class AxisCalibration:
    """``calibrated = matrix @ (raw - bias)`` (eq. 2.2) for one 3-axis sensor."""

    bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    matrix: np.ndarray = field(default_factory=lambda: np.eye(3))

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """Calibrated (N, 3) from raw (N, 3)."""
        return (np.asarray(raw, dtype=np.float64) - self.bias) @ self.matrix.T

    def to_dict(self) -> dict:
        return {"bias": [float(v) for v in self.bias], "matrix": [[float(v) for v in row] for row in self.matrix]}

    @classmethod
    def from_dict(cls, d: dict) -> AxisCalibration:
        bias = np.asarray(d.get("bias", [0, 0, 0]), dtype=np.float64)
        matrix = np.asarray(d.get("matrix", np.eye(3)), dtype=np.float64)
        if bias.shape != (3,) or matrix.shape != (3, 3):
            raise ValueError(f"calibration needs a 3-vector bias and a 3x3 matrix, got {bias.shape} and {matrix.shape}")
        return cls(bias, matrix)


@dataclass
class Calibration:
    """Accelerometer and gyroscope calibration of one device (JSON: :meth:`to_dict`)."""

    acc: AxisCalibration | None = None
    gyr: AxisCalibration | None = None
    device: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        out: dict = {"format": CALIBRATION_FORMAT, "device": self.device, "info": self.info}
        if self.acc is not None:
            out["acc"] = {"unit": "m/s^2", **self.acc.to_dict()}
        if self.gyr is not None:
            out["gyr"] = {"unit": "rad/s", **self.gyr.to_dict()}
        return out

    @classmethod
    def from_dict(cls, d: dict) -> Calibration:
        if d.get("format") != CALIBRATION_FORMAT:
            raise ValueError(
                f"not an imulog calibration file (format {d.get('format')!r}, expected {CALIBRATION_FORMAT!r})"
            )
        return cls(
            acc=AxisCalibration.from_dict(d["acc"]) if "acc" in d else None,
            gyr=AxisCalibration.from_dict(d["gyr"]) if "gyr" in d else None,
            device=dict(d.get("device", {})),
            info=dict(d.get("info", {})),
        )


def apply(
    cal: Calibration, acc: np.ndarray | None, gyr: np.ndarray | None
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Calibrated ``(acc, gyr)``; a channel without calibration (or missing) is passed through."""
    a = cal.acc.apply(acc) if (cal.acc is not None and acc is not None) else acc
    g = cal.gyr.apply(gyr) if (cal.gyr is not None and gyr is not None) else gyr
    return a, g


def accelerometer_six_position(
    a_plus: np.ndarray, a_minus: np.ndarray, g_m_s2: float = GRAVITY_M_S2
) -> AxisCalibration:
    """Bias (eq. 2.3) and calibration matrix from the six static means.

    ``a_plus``/``a_minus``: 3x3, column i = mean reading (m/s^2) with axis i pointing up/down.
    """
    ap = np.asarray(a_plus, dtype=np.float64)
    am = np.asarray(a_minus, dtype=np.float64)
    bias = (ap + am) @ np.ones(3) / 6.0
    sens = (ap - am) / (2.0 * g_m_s2)  # K V
    return AxisCalibration(bias=bias, matrix=np.linalg.inv(sens))


def gyroscope_from_rotations(
    static_gyr: np.ndarray, rotations: list[tuple[np.ndarray, np.ndarray]], rate_hz: float
) -> AxisCalibration:
    """Gyroscope bias and calibration matrix from a static recording and known rotations.

    ``rotations``: one ``(gyr (N, 3) rad/s, true_angle_vector (3,) rad)`` per rotation, the true
    rotation angle about each sensor axis accumulated over the segment (e.g. ``[2*pi, 0, 0]`` for one
    turn about x; a constant known rate w over T seconds gives ``w*T``). Needs >= 3 independent
    rotations; more are combined by least squares.
    """
    bias = np.nanmean(np.asarray(static_gyr, dtype=np.float64), axis=0)
    sensed = []
    true = []
    for gyr, angle in rotations:
        g = np.asarray(gyr, dtype=np.float64) - bias
        sensed.append(np.nansum(g, axis=0) / rate_hz)
        true.append(np.asarray(angle, dtype=np.float64))
    s = np.array(sensed)  # rows: integrated sensed angle = (KV) true
    t = np.array(true)
    if len(t) < 3 or np.linalg.matrix_rank(t) < 3:
        raise ValueError("gyroscope calibration needs rotations about three independent axes")
    # s_k = KV t_k  ->  S^T = T^T KV^T ; least squares KV^T = lstsq(T, S)
    kv_t, *_ = np.linalg.lstsq(t, s, rcond=None)
    return AxisCalibration(bias=bias, matrix=np.linalg.inv(kv_t.T))


# --------------------------------------------------------------------------------------------
# finding the segments of a calibration recording


@dataclass(frozen=True)
class SegmentParams:
    """Segmenting a calibration recording: static where the gyro norm stays below
    ``static_threshold_rad_s`` (0.1, the thesis's threshold) for ``min_static_s`` (2 s); a rotation
    is the motion between two static periods whose integrated (uncalibrated) angle about its
    dominant axis is within ``angle_tolerance`` (25 %) of the known angle and whose other axes
    carry less than 20 % of it (re-orientations between the six positions are thereby skipped);
    ``trim_s`` (0.25 s) is cut from both ends of each static period."""

    static_threshold_rad_s: float = 0.1
    min_static_s: float = 2.0
    angle_tolerance: float = 0.25
    trim_s: float = 0.25


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def find_static_segments(
    gyr: np.ndarray, rate_hz: float, params: SegmentParams = SegmentParams()
) -> list[tuple[int, int]]:
    """(start, end) sample ranges of static periods, trimmed by ``trim_s`` at both ends."""
    norm = np.linalg.norm(np.asarray(gyr, dtype=np.float64), axis=1)
    k = max(1, int(0.1 * rate_hz))
    smooth = np.convolve(np.nan_to_num(norm, nan=1e9), np.ones(k) / k, mode="same")
    starts, ends = _runs(smooth < params.static_threshold_rad_s)
    trim = int(params.trim_s * rate_hz)
    out = []
    for s, e in zip(starts, ends, strict=True):
        if (e - s) / rate_hz >= params.min_static_s:
            out.append((int(s + trim), int(e - trim)))
    return out


def six_position_means(acc: np.ndarray, statics: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """``A+``, ``A-`` (3x3) from static periods: each period is assigned to the axis and sign of its
    dominant mean component; periods of one orientation are averaged. Raises if one is missing."""
    acc = np.asarray(acc, dtype=np.float64)
    groups: dict[tuple[int, int], list[np.ndarray]] = {}
    for s, e in statics:
        m = np.nanmean(acc[s:e], axis=0)
        i = int(np.argmax(np.abs(m)))
        groups.setdefault((i, int(np.sign(m[i]))), []).append(m)
    missing = [f"{'+' if sg > 0 else '-'}{'xyz'[i]}" for i in range(3) for sg in (1, -1) if (i, sg) not in groups]
    if missing:
        raise ValueError(f"no static period with axis {', '.join(missing)} pointing up (need all six orientations)")
    ap = np.column_stack([np.mean(groups[(i, 1)], axis=0) for i in range(3)])
    am = np.column_stack([np.mean(groups[(i, -1)], axis=0) for i in range(3)])
    return ap, am


def find_rotation_segments(
    gyr: np.ndarray,
    rate_hz: float,
    statics: list[tuple[int, int]],
    angle_rad: float,
    params: SegmentParams = SegmentParams(),
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Rotations of the known ``angle_rad`` between consecutive static periods, about their dominant
    axis (sign from the measurement): ``[(gyr segment, true angle vector)]``; other motions between
    static periods are ignored (see :class:`SegmentParams`)."""
    gyr = np.asarray(gyr, dtype=np.float64)
    out = []
    for (_, e0), (s1, _) in zip(statics[:-1], statics[1:], strict=True):
        seg = gyr[e0:s1]
        if len(seg) == 0:
            continue
        integ = np.nansum(seg, axis=0) / rate_hz
        i = int(np.argmax(np.abs(integ)))
        others = np.delete(np.abs(integ), i)
        if abs(abs(integ[i]) - angle_rad) > params.angle_tolerance * angle_rad or others.max() > 0.2 * abs(integ[i]):
            continue
        true = np.zeros(3)
        true[i] = np.sign(integ[i]) * angle_rad
        out.append((seg, true))
    return out
