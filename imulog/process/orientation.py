"""IMU orientation: static periods, Valenti's algebraic initial quaternion, filter backends.

All quaternions are scalar-first and rotate sensor-frame vectors into the IMU's global frame
(z up; heading arbitrary without a magnetometer). With the magnetometer fused (9D) every backend
returns the same global frame, **ENU** (:data:`GLOBAL_FRAME_9D`: x east, y magnetic north, z up): VQF
works in ENU natively, Fusion is asked for ENU, Madgwick's NWU result (x north) is turned by 90 deg
about the vertical (:func:`nwu_to_enu`). ENU is the convention of ROS (REP 103) and of geodesy, and the
default backend's own, so the default output needs no conversion. :attr:`OrientationResult.global_frame`
names the frame (``ENU``, or ``z-up, arbitrary heading`` in 6D). Accelerations in m/s^2, angular rates
in rad/s, magnetic field in any unit (only its direction is used).

Backends (:data:`BACKENDS`, chosen by :class:`OrientationParams.backend`):

``madgwick``
    The R2G thesis setting: Valenti/AQUA initial orientation from the first static period, then
    Madgwick's gradient-descent filter (beta 0.03 rad/s), compiled with numba.
``vqf``
    Laidig & Seel's VQF (Information Fusion 2023), the causal (online) filter (PyPI ``vqf``).
``vqf_offline``
    VQF's acausal offline variant (``vqf.offlineVQF``): the most accurate published filter on
    BROAD. **The default** (:data:`DEFAULT_BACKEND`): archives are processed offline, and on every
    BROAD trial it is the most accurate of the backends here (docs/orientation.md).
``imufusion``
    x-io's Fusion AHRS (optional import of PyPI ``imufusion``).
``rts``
    An error-state Kalman filter and RTS smoother over the whole trial (6D; ``orientation_smoother``).
``vqf_gyrocal``
    VQF offline on the gyroscope self-calibrated over the whole trial (sensitivity and misalignment,
    ``orientation_gyrocal``). Options, not the default: docs/orientation.md "Beyond VQF" says where they stand.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imulog.numeric import finite_rows, median_int
from imulog.params import check_params
from imulog.process import quaternion as quat

__all__ = [
    "BACKENDS",
    "DEFAULT_BACKEND",
    "GLOBAL_FRAME_6D",
    "GLOBAL_FRAME_9D",
    "GRAVITY_M_S2",
    "OrientationParams",
    "OrientationResult",
    "StaticParams",
    "aqua_quaternion",
    "available_backends",
    "detect_static",
    "estimate_orientation",
    "fit_frame_offsets",
    "gravity_free_acceleration",
    "initial_orientation",
    "nwu_to_enu",
    "orientation_errors",
]

GRAVITY_M_S2 = 9.80665
DEFAULT_BACKEND = "vqf_offline"
GLOBAL_FRAME_9D = "ENU"  # x east, y magnetic north, z up: every backend with the magnetometer fused
GLOBAL_FRAME_6D = "z-up, arbitrary heading"
#: rotation of the NWU global frame into ENU (90 deg about the vertical): q_s2enu = Q_NWU_TO_ENU * q_s2nwu
Q_NWU_TO_ENU = np.array([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])


def nwu_to_enu(q_s2nwu: np.ndarray) -> np.ndarray:
    """Sensor-to-NWU quaternions (x north, y west, z up) as sensor-to-ENU (x east, y north, z up)."""
    return quat.multiply(Q_NWU_TO_ENU, np.asarray(q_s2nwu, dtype=np.float64))


# --------------------------------------------------------------------------------------------
# static periods


@dataclass(frozen=True)
class StaticParams:
    """Static-period detection on the gyroscope norm.

    ``threshold_rad_s``: 0.1 rad/s, the R2G thesis's threshold on the angular-velocity norm.
    ``min_duration_s``: shorter runs below the threshold are not static (0.1 s).
    ``smooth_s``: moving-average window applied to the norm before thresholding (0 = none).
    """

    threshold_rad_s: float = 0.1
    min_duration_s: float = 0.1
    smooth_s: float = 0.0

    def __post_init__(self) -> None:
        check_params(self, positive=("threshold_rad_s",), non_negative=("min_duration_s", "smooth_s"))


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) indices of the True runs of ``mask``."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def detect_static(gyr_rad_s: np.ndarray, rate_hz: float, params: StaticParams = StaticParams()) -> np.ndarray:
    """Boolean (N,) mask of static samples: gyro norm below the threshold for at least min_duration."""
    g = np.asarray(gyr_rad_s, dtype=np.float64)
    sq = np.einsum("ij,ij->i", g, g)
    if params.smooth_s > 0:
        w = max(1, int(round(params.smooth_s * rate_hz)))
        norm = np.convolve(np.nan_to_num(np.sqrt(sq), nan=np.inf), np.ones(w) / w, mode="same")
        mask = norm < params.threshold_rad_s
    else:
        mask = sq < params.threshold_rad_s**2  # NaN compares False: not static
    min_len = max(1, int(round(params.min_duration_s * rate_hz)))
    starts, ends = _runs(mask)
    short = (ends - starts) < min_len
    if short.any():
        d = np.zeros(len(mask) + 1, dtype=np.int64)
        np.add.at(d, starts[short], 1)
        np.add.at(d, ends[short], -1)
        mask &= np.cumsum(d[:-1]) == 0
    return mask


# --------------------------------------------------------------------------------------------
# initial orientation (Valenti, Dryanovski & Xiao 2015, "Keeping a good attitude", AQUA)


def aqua_quaternion(acc: np.ndarray, mag: np.ndarray | None = None) -> np.ndarray:
    """Valenti's algebraic quaternion from one accelerometer (and magnetometer) sample.

    Returns AQUA's own quaternion, which is **global-to-local** (it rotates global-frame vectors
    into the sensor frame). Use :func:`initial_orientation` for the sensor-to-global convention.
    """
    a = np.asarray(acc, dtype=np.float64)
    a = a / np.linalg.norm(a)
    ax, ay, az = a
    if az >= 0:
        lam = np.sqrt(2.0 * (az + 1.0))
        q_acc = np.array([lam / 2.0, -ay / lam, ax / lam, 0.0])
    else:
        lam = np.sqrt(2.0 * (1.0 - az))
        q_acc = np.array([-ay / lam, lam / 2.0, 0.0, ax / lam])
    if mag is None:
        return q_acc
    m = np.asarray(mag, dtype=np.float64)
    # magnetic field in the intermediate (levelled) frame: l = R(q_acc)^T m
    lx, ly, _ = quat.rotate(quat.conjugate(q_acc), m)
    gamma = lx * lx + ly * ly
    sg = np.sqrt(gamma)
    if lx >= 0:
        q_mag = np.array(
            [np.sqrt(gamma + lx * sg) / np.sqrt(2.0 * gamma), 0.0, 0.0, ly / (np.sqrt(2.0) * np.sqrt(gamma + lx * sg))]
        )
    else:
        q_mag = np.array(
            [ly / (np.sqrt(2.0) * np.sqrt(gamma - lx * sg)), 0.0, 0.0, np.sqrt(gamma - lx * sg) / np.sqrt(2.0 * gamma)]
        )
    return quat.normalize(quat.multiply(q_acc, q_mag))


def initial_orientation(acc: np.ndarray, mag: np.ndarray | None = None) -> np.ndarray:
    """Sensor-to-global initial orientation from (mean) static acc (and mag): the conjugate of AQUA's.

    With ``mag`` the global x axis points to magnetic north (North-West-Up); without it the heading
    is the one that keeps the sensor's heading at zero.
    """
    return quat.canonical(quat.conjugate(aqua_quaternion(acc, mag)))


def _first_static_mean(x: np.ndarray, static: np.ndarray) -> np.ndarray:
    """Mean of ``x`` over the first static run (or the first sample when there is none)."""
    starts, ends = _runs(static)
    if len(starts) == 0:
        return np.nanmean(x[: max(1, min(len(x), 10))], axis=0)
    return np.nanmean(x[starts[0] : ends[0]], axis=0)


# --------------------------------------------------------------------------------------------
# backends


_UNITS = {"beta": "rad/s"}  # the field names that do not carry their unit


@dataclass(frozen=True)
class OrientationParams:
    """Orientation estimation settings.

    ``backend``: one of :data:`BACKENDS` (default ``vqf_offline``).
    ``beta``: Madgwick gain in rad/s (0.03, the R2G thesis / Madgwick's dynamic-performance value).
    ``use_mag``: fuse the magnetometer when the IMU has one (False: the thesis judged the field
    unreliable during motion; the heading is then arbitrary but consistent).
    ``static``: static-period detection (0.1 rad/s gyro-norm threshold).
    ``imufusion_gain``: Fusion AHRS gain (0.5, its default; dimensionless).

    >>> OrientationParams(backend="madgwick", beta=0.05).beta
    0.05
    >>> OrientationParams(beta=-1)
    Traceback (most recent call last):
    ...
    imulog.params.ParamError: OrientationParams.beta: must be finite and > 0 (rad/s), got -1
    """

    backend: str = DEFAULT_BACKEND
    beta: float = 0.03
    use_mag: bool = False
    static: StaticParams = StaticParams()
    imufusion_gain: float = 0.5

    def __post_init__(self) -> None:  # ParamError names the field and its unit; the CLI prints the same line
        check_params(
            self, positive=("beta",), non_negative=("imufusion_gain",), choices={"backend": BACKENDS}, units=_UNITS
        )


@dataclass
class OrientationResult:
    """Output of :func:`estimate_orientation`: ``quat`` (N, 4) sensor-to-global, ``static`` (N,) bool,
    ``global_frame`` :data:`GLOBAL_FRAME_9D` (magnetometer fused) or :data:`GLOBAL_FRAME_6D`; ``estimates``:
    what the backend estimated besides the orientation, as JSON values (``vqf_gyrocal``: ``gyro_correction``,
    :func:`imulog.process.orientation_gyrocal.correction_record`; empty for the others)."""

    quat: np.ndarray
    static: np.ndarray
    backend: str
    global_frame: str = GLOBAL_FRAME_6D
    estimates: dict[str, Any] = field(default_factory=dict)


#: a backend returns the quaternions (N, 4), or them and what else it estimated (``OrientationResult.estimates``)
Backend = Callable[
    [np.ndarray, np.ndarray, "np.ndarray | None", float, OrientationParams, np.ndarray],
    "np.ndarray | tuple[np.ndarray, dict[str, Any]]",
]


def _madgwick(gyr, acc, mag, rate_hz, params, static):
    from imulog.process.madgwick import madgwick_imu, madgwick_marg

    q0 = initial_orientation(_first_static_mean(acc, static), None if mag is None else _first_static_mean(mag, static))
    if mag is None:
        return madgwick_imu(gyr, acc, 1.0 / rate_hz, params.beta, q0)
    return nwu_to_enu(madgwick_marg(gyr, acc, mag, 1.0 / rate_hz, params.beta, q0))  # Madgwick's frame is NWU


def _vqf_online(gyr, acc, mag, rate_hz, params, static):
    from vqf import VQF

    f = VQF(1.0 / rate_hz)
    if mag is None:
        return np.asarray(f.updateBatch(gyr, acc)["quat6D"])
    return np.asarray(f.updateBatch(gyr, acc, mag)["quat9D"])


def _vqf_offline(gyr, acc, mag, rate_hz, params, static):
    from vqf import offlineVQF

    out = offlineVQF(gyr, acc, mag, 1.0 / rate_hz)
    return np.asarray(out["quat6D" if mag is None else "quat9D"])


def _imufusion(gyr, acc, mag, rate_hz, params, static):
    try:
        import imufusion
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise RuntimeError("the imufusion backend needs imufusion: pip install 'imulog[fusion]'") from exc
    ahrs = imufusion.Ahrs()
    # imufusion 1.3 ignores AhrsSettings(...) keyword arguments (convention and gain stayed at NWU, 0.5):
    # set the attributes instead
    settings = imufusion.AhrsSettings()
    settings.convention = imufusion.CONVENTION_ENU
    settings.gain = float(params.imufusion_gain)
    settings.sample_rate = float(rate_hz)
    ahrs.set_settings(settings)
    if hasattr(ahrs, "set_sample_period"):
        ahrs.set_sample_period(1.0 / rate_hz)
    gyr_dps = np.ascontiguousarray(np.rad2deg(gyr))
    acc_g = np.ascontiguousarray(acc / GRAVITY_M_S2)
    out = np.empty((len(gyr), 4))
    if mag is None:
        for i in range(len(gyr)):
            ahrs.update_no_magnetometer(gyr_dps[i], acc_g[i])
            out[i] = ahrs.get_quaternion()
    else:
        for i in range(len(gyr)):
            ahrs.update(gyr_dps[i], acc_g[i], mag[i])
            out[i] = ahrs.get_quaternion()
    return out


def _vqf_gyrocal(gyr, acc, mag, rate_hz, params, static):
    from imulog.process.orientation_gyrocal import vqf_gyrocal

    correction: dict[str, Any] = {}
    q = vqf_gyrocal(gyr, acc, rate_hz, mag, info=correction)[0]
    return q, {"gyro_correction": correction}  # what it estimated, for the step's provenance


def _rts(gyr, acc, mag, rate_hz, params, static):
    from imulog.process.orientation_smoother import SmootherParams, smooth_orientation

    if mag is not None:
        raise ValueError("the rts backend is 6D only (no magnetometer): use --backend vqf_offline with --mag")
    return smooth_orientation(gyr, acc, rate_hz, SmootherParams())[0]


BACKENDS: dict[str, Backend] = {
    "madgwick": _madgwick,
    "vqf": _vqf_online,
    "vqf_offline": _vqf_offline,
    "imufusion": _imufusion,
    "rts": _rts,
    "vqf_gyrocal": _vqf_gyrocal,
}


def available_backends() -> list[str]:
    """Backend names usable in this environment (``imufusion`` only when installed)."""
    names = ["madgwick", "vqf", "vqf_offline", "rts", "vqf_gyrocal"]
    try:
        import imufusion  # noqa: F401

        names.append("imufusion")
    except ImportError:  # pragma: no cover
        pass
    return names


def _fill_nan(x: np.ndarray) -> np.ndarray:
    """Linearly interpolate NaN rows (filters cannot take gaps); all-NaN columns become 0."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    if np.isfinite(x).all():
        return x
    x = x.copy()
    bad = ~finite_rows(x)
    if np.any(bad) and not np.all(bad):
        idx = np.arange(len(x))
        for c in range(x.shape[1]):
            x[bad, c] = np.interp(idx[bad], idx[~bad], x[~bad, c])
    return x


def _has_gaps(t_ns: np.ndarray) -> bool:
    """A step longer than 1.5x the median step (a dropped sample)."""
    d = np.diff(np.asarray(t_ns, dtype=np.int64))
    if len(d) == 0:
        return False
    if d.min() > 0 and d.max() <= 1.5 * d.min():  # the median lies between: no step exceeds 1.5x it, no sort
        return False
    return bool(np.any(d > 1.5 * median_int(d)))


def _on_uniform_grid(
    t_ns: np.ndarray,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray | None,
    params: OrientationParams,
) -> OrientationResult:
    """Dropped samples: filter on a uniform grid at the nominal rate, map back to ``t_ns``."""
    from imulog.process.resample import ResampleParams, resample_quaternions, uniform_grid

    t = np.asarray(t_ns, dtype=np.int64)
    nominal_hz = 1e9 / float(np.median(np.diff(t)))
    # one period past the end so every original time stamp lies inside the grid
    grid = uniform_grid(int(t[0]), int(t[-1] + 1e9 / nominal_hz), nominal_hz)
    tf, gf = t.astype(np.float64), grid.astype(np.float64)

    def interp(x: np.ndarray) -> np.ndarray:
        x = _fill_nan(x)
        return np.column_stack([np.interp(gf, tf, x[:, k]) for k in range(x.shape[1])])

    res = estimate_orientation(interp(gyr), interp(acc), nominal_hz, None if mag is None else interp(mag), params)
    q = resample_quaternions(grid, res.quat, t, ResampleParams(cutoff_ratio=0.0))
    idx = np.clip(np.searchsorted(grid, t), 0, len(grid) - 1)
    return OrientationResult(
        quat=q, static=res.static[idx], backend=res.backend, global_frame=res.global_frame, estimates=res.estimates
    )


def estimate_orientation(
    gyr_rad_s: np.ndarray,
    acc_m_s2: np.ndarray,
    rate_hz: float,
    mag: np.ndarray | None = None,
    params: OrientationParams = OrientationParams(),
    t_ns: np.ndarray | None = None,
) -> OrientationResult:
    """Sensor-to-global orientation (N, 4) of one IMU with the chosen backend.

    ``mag`` is used only when ``params.use_mag`` is True. NaN samples are bridged by linear
    interpolation before filtering. With ``t_ns`` (int64 ns) and dropped samples (a step longer
    than 1.5 nominal periods), the filter runs on a uniform grid at the nominal rate and the result
    is interpolated (slerp) back to ``t_ns``; ``rate_hz`` is then ignored.
    """
    if params.backend not in BACKENDS:
        raise ValueError(f"unknown orientation backend {params.backend!r}; choose one of {', '.join(BACKENDS)}")
    if t_ns is not None and _has_gaps(t_ns):
        return _on_uniform_grid(t_ns, gyr_rad_s, acc_m_s2, mag if params.use_mag else None, params)
    gyr = np.ascontiguousarray(_fill_nan(gyr_rad_s))
    acc = np.ascontiguousarray(_fill_nan(acc_m_s2))
    m = np.ascontiguousarray(_fill_nan(mag)) if (params.use_mag and mag is not None) else None
    static = detect_static(gyr, rate_hz, params.static)
    out = BACKENDS[params.backend](gyr, acc, m, float(rate_hz), params, static)
    out, estimates = out if isinstance(out, tuple) else (out, {})
    q = np.asarray(out, dtype=np.float64)
    # every backend returns unit quaternions; their sign is kept continuous (no w >= 0 flips)
    frame = GLOBAL_FRAME_9D if m is not None else GLOBAL_FRAME_6D
    return OrientationResult(quat=q, static=static, backend=params.backend, global_frame=frame, estimates=estimates)


def gravity_free_acceleration(
    quat_s2g: np.ndarray, acc_m_s2: np.ndarray, static: np.ndarray | None = None
) -> np.ndarray:
    """Acceleration (N, 3) m/s^2 in the global frame with gravity removed.

    Gravity is ``(0, 0, g)`` with ``g`` the mean accelerometer norm over ``static`` samples
    (absorbing the sensor's scale error), or 9.80665 m/s^2 when there are none.
    """
    acc = np.asarray(acc_m_s2, dtype=np.float64)
    g = GRAVITY_M_S2
    if static is not None and np.count_nonzero(static) > 0:
        g = float(np.nanmean(np.linalg.norm(acc[static], axis=1)))
    out = quat.rotate(quat_s2g, acc)
    out[:, 2] -= g
    return out


# --------------------------------------------------------------------------------------------
# evaluation against a reference orientation (BROAD-style)


def fit_frame_offsets(
    q_est: np.ndarray, q_ref: np.ndarray, *, heading_only: bool = True, iterations: int = 10
) -> tuple[np.ndarray, np.ndarray]:
    """Constant rotations ``(q_global, q_sensor)`` with ``q_ref ~ q_global * q_est * q_sensor``.

    The estimate's global frame differs from the reference's by a heading rotation (6D filters have
    no absolute heading; ``heading_only``) and the IMU's sensor frame from the reference body frame
    by a fixed rotation. Both are fitted by alternating least squares (chordal quaternion mean).
    """
    q_s = quat.IDENTITY.copy()
    q_g = quat.IDENTITY.copy()
    for _ in range(iterations):
        a = quat.multiply(q_est, q_s)
        q_g = quat.heading_offset(a, q_ref) if heading_only else quat.average(quat.multiply(q_ref, quat.conjugate(a)))
        q_s = quat.average(quat.multiply(quat.conjugate(quat.multiply(q_g, q_est)), q_ref))
    return q_g, q_s


def orientation_errors(
    q_est: np.ndarray, q_ref: np.ndarray, mask: np.ndarray | None = None, *, fit_sensor: bool = False
) -> dict[str, float]:
    """RMSE in degrees of ``q_est`` against ``q_ref`` over ``mask`` (and finite reference rows).

    BROAD's evaluation (Laidig et al. 2021, ``broad_utils.py``): the error quaternion in the global
    frame is ``q_est * q_ref^-1``; ``inclination_rmse_deg`` is its tilt part (independent of the
    arbitrary heading of a 6D estimate). ``heading_free_rmse_deg`` is the total rotation error after
    the constant global heading rotation between the two frames is estimated and removed
    (:func:`fit_frame_offsets`); with ``fit_sensor`` a constant sensor-side rotation is fitted as
    well (for references whose body frame is not already aligned with the IMU's, unlike BROAD).
    """
    ok = np.all(np.isfinite(q_ref), axis=1) & np.all(np.isfinite(q_est), axis=1)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    e, r = q_est[ok], q_ref[ok]
    if fit_sensor:
        q_g, q_s = fit_frame_offsets(e, r)
    else:
        q_g, q_s = quat.heading_offset(e, r), quat.IDENTITY
    corrected = quat.multiply(quat.multiply(q_g, e), q_s)

    def rms(x: np.ndarray) -> float:
        return float(np.rad2deg(np.sqrt(np.mean(x**2))))

    return {
        "inclination_rmse_deg": rms(quat.inclination_error(corrected, r)),
        "heading_free_rmse_deg": rms(quat.angle_between(corrected, r)),
        "heading_offset_deg": float(np.rad2deg(quat.angle(q_g))),
        "samples": int(ok.sum()),
    }
