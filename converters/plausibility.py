"""Physical plausibility of IMU and marker units: what a human limb and a lab can produce (pure numpy, no I/O).

Two uses:

* :func:`recording_warnings`: after conversion, one line per channel whose values do not fit its declared unit
  (a deg/s gyroscope under a rad/s header, an accelerometer in g declared m/s^2, markers in mm declared m),
  naming the likely unit and the option that fixes it (``--unit gyr=deg/s`` or the mapping file);
* :func:`infer_acc_unit` / :func:`infer_gyr_unit`: the unit of a unit-less column group, with the evidence.

What the checks see (all on the converted SI values):

* accelerometer: the norm at rest is gravity (9.81 m/s^2): ~1 means g, ~1000 mg. Rest = windows of about 1 s
  where every axis varies by less than 2 % of the norm (unit-free, so it also works before the unit is known);
  without rest windows the median norm over the recording is used.
* gyroscope, peaks: a human limb in rehabilitation tasks turns at most a few rad/s (wrist ADL under 10 rad/s) and
  nearly every wearable gyroscope saturates at +-2000 deg/s = 34.9 rad/s, so values above 40 rad/s (99.9th
  percentile of the norm) cannot be rad/s: they are deg/s.
* gyroscope, at rest: while the accelerometer shows the sensor still, the gyroscope component perpendicular to
  gravity must be near zero (a real rotation about a horizontal axis would turn gravity in the accelerometer).
  Its mean over a rest window above 0.15 rad/s (8.6 deg/s: larger than the bias of MEMS gyroscopes) means the
  numbers are deg/s, whose bias of a few tenths of a degree per second reads as tenths of a rad/s.
* gyroscope, moving: during slow movements (accelerometer norm within 10 % of gravity) the rate at which the
  gravity direction turns in the sensor frame equals the gyroscope component perpendicular to it; their ratio is
  1 for rad/s and 57.3 for deg/s read as rad/s. Dynamic acceleration adds apparent tilt, so measured ratios are
  lower (0.5-1.0 for rad/s and 28-56 for deg/s on the real files in ../shared/data): up to 4 is rad/s, from 8
  deg/s. (The reverse, rad/s declared deg/s, is not warned about: vibration reads as tilt when the gyroscope is
  still, so a small ratio is no evidence.)

What they cannot see: a calibrated deg/s gyroscope (bias under 0.15 deg/s) declared rad/s in a recording that
never turns faster than 40 deg/s and never tilts slowly enough for the ratio test (e.g. a sensor lying still, or
spinning only about the vertical); an accelerometer whose unit error is a factor near 1; markers in cm vs mm
(a factor 10 inside the range of plausible lab coordinates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

G0 = 9.80665  # m/s^2
DEG = math.pi / 180.0
GYRO_PEAK_MAX_RAD_S = 40.0  # above the +-2000 deg/s range of wearable gyroscopes and any human limb
GYRO_REST_MAX_RAD_S = 0.15  # perpendicular-to-gravity rate allowed while the accelerometer is still
RATIO_RAD_MAX, RATIO_DEG_MIN = 4.0, 8.0  # tilt ratio: rad/s up to 4, deg/s from 8 (57.3 nominal)
REST_WINDOW_S = 1.0
REST_REL_STD = 0.02
MARKER_MAX_M = 50.0  # lab coordinates beyond this are mm (or another small unit) declared m
MARKER_MIN_SPAN_M = 0.01  # every marker within 1 cm of the origin for the whole trial: m declared mm

ACC_UNITS = {"g": 1.0, "m/s^2": G0, "mg": 1000.0}  # the norm of gravity in each unit


@dataclass(frozen=True)
class UnitGuess:
    """An inferred unit with the evidence in one phrase (``unit`` None: the data cannot tell)."""

    unit: str | None
    evidence: str


def _norm(a: np.ndarray) -> np.ndarray:
    """Row norms of an (N, C) float64 array (einsum: faster than ``np.linalg.norm(axis=1)`` for C = 3)."""
    return np.sqrt(np.einsum("ij,ij->i", a, a))


def _rate_hz(t_ns: np.ndarray) -> float:
    """Median sampling rate (Hz) from the positive time steps (at most ~50 000 of them, evenly spread)."""
    t = np.asarray(t_ns, dtype=np.int64)
    step = max(1, (len(t) - 1) // 50_000)
    dt = t[1:][::step] - t[:-1][::step]
    dt = dt[dt > 0]
    return 1e9 / float(np.median(dt)) if len(dt) else 100.0


def _rest_index(
    acc: np.ndarray, t_ns: np.ndarray, window_s: float, rate_hz: float | None = None
) -> tuple[int, np.ndarray]:
    """(window length in samples, indices of the rest windows) of consecutive windows of about ``window_s``.

    ``rate_hz``: the sampling rate of ``t_ns`` when already known (else the median from ``t_ns``)."""
    a = np.asarray(acc, dtype=np.float64)
    n = max(3, int(round(window_s * (_rate_hz(t_ns) if rate_hz is None else rate_hz))))
    m = len(a) // n
    if m == 0:
        return n, np.zeros(0, dtype=np.int64)
    w = a[: m * n].reshape(m, n, a.shape[1])
    with np.errstate(invalid="ignore", over="ignore"):
        mean = w.sum(axis=1) / n  # (m, C)
        var = np.einsum("ijk,ijk->ik", w, w) / n - mean**2  # population variance from the two sums
        norm = np.sqrt(np.einsum("ik,ik->i", mean, mean))
        # a NaN or infinity anywhere in a window makes its sum of squares non-finite
        ok = np.isfinite(var).all(axis=1) & (norm > 0) & (var.max(axis=1) < (REST_REL_STD * norm) ** 2)
    return n, np.flatnonzero(ok)


def _window_means(x: np.ndarray, n: int, index: np.ndarray) -> np.ndarray:
    """(len(index), C) means of the windows ``index`` of length ``n``."""
    a = np.asarray(x, dtype=np.float64)
    m = len(a) // n
    return a[: m * n].reshape(m, n, a.shape[1])[index].mean(axis=1)


def rest_windows(acc: np.ndarray, t_ns: np.ndarray, window_s: float = REST_WINDOW_S) -> list[slice]:
    """Windows of about ``window_s`` where every accelerometer axis varies by under 2 % of the norm (any unit)."""
    n, index = _rest_index(acc, t_ns, window_s)
    return [slice(int(i) * n, (int(i) + 1) * n) for i in index]


MAX_CHECK_SAMPLES = 120_000  # longer recordings: evenly spread 1-min excerpts (cost, memory)
EXCERPT_S = 60.0


class Excerpts:
    """Excerpts of one stream (time stamps and arrays of rows), given in pieces, that do not depend on where the
    pieces are cut: the samples fall in blocks of :data:`EXCERPT_S` of time from the first sample; every block is
    kept while the samples fit :data:`MAX_CHECK_SAMPLES`, else the blocks whose number is a multiple of ``stride``,
    the smallest power of two that makes them fit, each followed by a NaN row (so that no window, gradient or
    moving average spans two excerpts). Memory: at most that many samples and a slice of the piece being added."""

    def __init__(self) -> None:
        self.t0: int | None = None
        self.stride = 1
        self._parts: list[tuple[np.ndarray, np.ndarray, list[np.ndarray | None]]] = []  # (block, t, arrays)
        self._blocks: set[int] = set()
        self._count = 0

    def add(self, t_ns: np.ndarray, *arrays: np.ndarray | None) -> None:
        """Add the next samples (time order) of the stream: ``t_ns`` (ns) and one row of each array per sample."""
        t = np.asarray(t_ns, dtype=np.int64)
        if not len(t):
            return
        if self.t0 is None:
            self.t0 = int(t[0])
        for lo in range(0, len(t), MAX_CHECK_SAMPLES):  # a long piece a slice at a time: memory stays bounded
            sl = slice(lo, lo + MAX_CHECK_SAMPLES)
            block = (t[sl] - self.t0) // int(EXCERPT_S * 1e9)
            keep = block % self.stride == 0
            if not keep.any():
                continue
            rows = [None if a is None else np.array(np.asarray(a[sl])[keep], dtype=np.float64) for a in arrays]
            self._parts.append((block[keep], t[sl][keep], rows))
            self._blocks.update(np.unique(block[keep]).tolist())
            self._count += int(keep.sum())
            while self._size() > MAX_CHECK_SAMPLES and len(self._blocks) > 1:
                self._thin()

    def _size(self) -> int:
        """Samples the excerpts hold, with their NaN rows."""
        return self._count + (len(self._blocks) - 1 if self.stride > 1 else 0)

    def _thin(self) -> None:
        """Double the stride: keep every other excerpt."""
        self.stride *= 2
        parts = []
        for block, t, rows in self._parts:
            keep = block % self.stride == 0
            if keep.any():
                parts.append((block[keep], t[keep], [None if r is None else r[keep] for r in rows]))
        self._parts = parts
        self._blocks = {b for b in self._blocks if b % self.stride == 0}
        self._count = sum(len(p[1]) for p in parts)

    def result(self) -> tuple[np.ndarray, list[np.ndarray | None]]:
        """(time stamps, arrays) of the excerpts, a NaN row (time: the sample before + 1 ns) after each but the
        last when some blocks were left out; every sample as given while they fit."""
        if not self._parts:
            return np.zeros(0, dtype=np.int64), []
        block = np.concatenate([p[0] for p in self._parts])
        t = np.concatenate([p[1] for p in self._parts])
        rows = [
            None if self._parts[0][2][j] is None else np.concatenate([p[2][j] for p in self._parts])
            for j in range(len(self._parts[0][2]))
        ]
        if self.stride == 1:
            return t, rows
        cut = np.flatnonzero(np.diff(block)) + 1  # where the next excerpt starts
        t = np.insert(t, cut, t[cut - 1] + 1)
        return t, [None if r is None else np.insert(r, cut, np.nan, axis=0) for r in rows]


def excerpts(t_ns: np.ndarray, *arrays: np.ndarray | None) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """At most :data:`MAX_CHECK_SAMPLES` samples of long recordings (:class:`Excerpts` of one piece: the same
    excerpts as the recording given in pieces of any size). Short recordings as they are."""
    if len(t_ns) <= MAX_CHECK_SAMPLES:
        return np.asarray(t_ns), list(arrays)
    ex = Excerpts()
    ex.add(t_ns, *arrays)
    return ex.result()


def rest_acc_norm(
    acc: np.ndarray, t_ns: np.ndarray, *, rest: tuple[int, np.ndarray] | None = None
) -> tuple[float, bool]:
    """(median accelerometer norm at rest, True if rest windows were found) in the array's own unit.

    ``rest``: :func:`_rest_index` of ``acc`` when already computed."""
    a = np.asarray(acc, dtype=np.float64)
    n, index = _rest_index(a, t_ns, REST_WINDOW_S) if rest is None else rest
    if len(index):
        return float(np.median(_norm(_window_means(a, n, index)))), True
    norm = _norm(a)
    norm = norm[np.isfinite(norm)]
    return (float(np.median(norm)) if len(norm) else float("nan")), False


def infer_acc_unit(acc: np.ndarray, t_ns: np.ndarray) -> UnitGuess:
    """g, m/s^2 or mg from the norm at rest (gravity), or None when it is within 30 % of none of them."""
    norm, at_rest = rest_acc_norm(acc, t_ns)
    where = "at rest" if at_rest else "median over the recording (no rest found)"
    for unit, g in ACC_UNITS.items():
        if abs(norm / g - 1.0) < 0.3:
            return UnitGuess(unit, f"norm {where} {norm:.3g} = {norm / g:.2f} g")
    return UnitGuess(None, f"norm {where} {norm:.3g} fits neither g (1), m/s^2 (9.81) nor mg (1000)")


def gyro_peak(gyr: np.ndarray) -> float:
    """99.9th percentile of the gyroscope norm (array's unit)."""
    norm = _norm(np.asarray(gyr, dtype=np.float64))
    norm = norm[np.isfinite(norm)]
    return float(np.quantile(norm, 0.999)) if len(norm) else 0.0


def gyro_rate_at_rest(
    gyr: np.ndarray, acc: np.ndarray, t_ns: np.ndarray, *, rest: tuple[int, np.ndarray] | None = None
) -> float | None:
    """Median over rest windows of |mean gyroscope component perpendicular to gravity| (gyro's unit), or None.

    ``rest``: :func:`_rest_index` of ``acc`` when already computed."""
    n, index = _rest_index(acc, t_ns, REST_WINDOW_S) if rest is None else rest
    if not len(index):
        return None
    u = _window_means(acc, n, index)
    u = u / np.linalg.norm(u, axis=1)[:, None]
    g = _window_means(gyr, n, index)
    perp = np.linalg.norm(g - np.sum(g * u, axis=1)[:, None] * u, axis=1)
    perp = perp[np.isfinite(perp)]
    return float(np.median(perp)) if len(perp) else None


def gyro_tilt_ratio(
    gyr: np.ndarray,
    acc: np.ndarray,
    t_ns: np.ndarray,
    min_tilt_rad_s: float = 0.15,
    *,
    rest: tuple[int, np.ndarray] | None = None,
    rate_hz: float | None = None,
    ref_norm: float | None = None,
) -> float | None:
    """Gyroscope-perpendicular rate over the turning rate of the gravity direction seen by the accelerometer.

    Samples where the accelerometer norm is within 10 % of its rest value (slow movement) and gravity turns
    faster than ``min_tilt_rad_s``; a 0.1 s moving average on both, and the turning rate from directions 0.2 s
    apart (so that accelerometer noise does not read as tilt). ~1 for a rad/s gyroscope, ~57.3 for deg/s
    numbers; None with fewer than 0.5 s of such samples. ``rest`` / ``rate_hz`` / ``ref_norm``: :func:`_rest_index`
    of ``acc``, the rate of ``t_ns`` and :func:`rest_acc_norm` of ``acc`` when already computed.
    """
    a = np.asarray(acc, dtype=np.float64)
    w = np.asarray(gyr, dtype=np.float64)
    rate = _rate_hz(t_ns) if rate_hz is None else rate_hz
    k = max(1, int(round(0.1 * rate)))
    if len(a) < 4 * k + 4:
        return None
    kernel = np.ones(k) / k
    # one contiguous array per axis: numpy's reductions over a trailing axis of 3 are several times slower
    a_s = [np.convolve(a[:, j], kernel, mode="same") for j in range(3)]
    w_s = [np.convolve(w[:, j], kernel, mode="same") for j in range(3)]
    norm = np.sqrt(a_s[0] ** 2 + a_s[1] ** 2 + a_s[2] ** 2)
    ref = rest_acc_norm(a, t_ns, rest=rest)[0] if ref_norm is None else ref_norm
    with np.errstate(invalid="ignore", divide="ignore"):
        u = [c / norm for c in a_s]
        tilt = np.full(len(norm), np.nan)
        step = [c[2 * k :] - c[: -2 * k] for c in u]  # over 0.2 s
        tilt[k:-k] = np.sqrt(step[0] ** 2 + step[1] ** 2 + step[2] ** 2) * (rate / (2 * k))
        along = w_s[0] * u[0] + w_s[1] * u[1] + w_s[2] * u[2]
        perp = np.sqrt(sum((w_s[j] - along * u[j]) ** 2 for j in range(3)))
        ok = np.isfinite(tilt) & np.isfinite(perp) & (np.abs(norm / ref - 1.0) < 0.1) & (tilt > min_tilt_rad_s)
    ok[: k + 1] = False
    ok[-k - 1 :] = False
    if ok.sum() < 0.5 * rate:
        return None
    return float(np.sum(perp[ok] * tilt[ok]) / np.sum(tilt[ok] ** 2))


def infer_gyr_unit(gyr: np.ndarray, acc: np.ndarray | None, t_ns: np.ndarray) -> UnitGuess:
    """rad/s or deg/s for unit-less gyroscope numbers (peaks, rest bias vs the accelerometer, tilt ratio)."""
    peak = gyro_peak(gyr)
    if peak > GYRO_PEAK_MAX_RAD_S:
        return UnitGuess("deg/s", f"peaks of {peak:.3g}: beyond a human limb in rad/s")
    if acc is not None:
        ratio = gyro_tilt_ratio(gyr, acc, t_ns)
        if ratio is not None:
            if 0.5 * DEG * RATIO_DEG_MIN < ratio <= RATIO_RAD_MAX:
                return UnitGuess("rad/s", f"it turns as fast as gravity turns in the accelerometer (ratio {ratio:.2f})")
            if RATIO_DEG_MIN <= ratio < 2.5 / DEG:
                return UnitGuess("deg/s", f"it reads {ratio:.0f}x the rate gravity turns in the accelerometer")
        rest = gyro_rate_at_rest(gyr, acc, t_ns)
        if rest is not None and rest > GYRO_REST_MAX_RAD_S:
            return UnitGuess("deg/s", f"it reads {rest:.2g} at rest: a bias in deg/s, impossible in rad/s")
    return UnitGuess(None, f"peaks of {peak:.3g} fit both rad/s and deg/s and no slow tilt to compare with")


# --------------------------------------------------------------------------------- checks after conversion
def imu_warnings(
    topic: str, acc: np.ndarray | None, gyr: np.ndarray | None, t_ns: np.ndarray, gyr_unit: str | None = None
) -> list[str]:
    """One line per implausible IMU channel (values already in m/s^2 and rad/s; long recordings on excerpts).

    ``gyr_unit``: the unit the file declared for the gyroscope, when known; a deg/s-declared gyroscope that still
    reads too fast is not told to be deg/s (it already is): the warning then asks to check the unit or the bias.
    """
    t_ns, (acc, gyr) = excerpts(t_ns, acc, gyr)
    out = []
    rate = _rate_hz(t_ns)
    rest = _rest_index(acc, t_ns, REST_WINDOW_S, rate) if acc is not None else None  # shared by every check
    ref_norm = None
    if acc is not None and len(acc) > 2 and np.isfinite(acc).any():
        norm, at_rest = rest_acc_norm(acc, t_ns, rest=rest)
        ref_norm = norm
        if norm == 0 and not np.nanmax(np.abs(acc)) > 0:  # no data: no unit can be judged (EDF min == max)
            out.append(f"{topic}: every acc value is 0 (the channel holds no data); no unit can be judged")
        elif not 0.5 * G0 <= norm <= 2.0 * G0:
            guess = ""
            if 0.5 <= norm <= 2.0:
                guess = " (the numbers look like g: is the unit g rather than m/s^2? --unit acc=g)"
            elif 500 <= norm <= 2000:
                guess = " (the numbers look like mg: --unit acc=mg)"
            out.append(
                f"{topic}: median |acc| {'at rest ' if at_rest else ''}is {norm:.3g} m/s^2, expected about 9.81 "
                f"(gravity){guess}; check the accelerometer unit in the header or mapping file"
            )
    if gyr is not None and len(gyr) > 2 and np.isfinite(gyr).any():
        declared_rad = gyr_unit is None or _is_rad_s(gyr_unit)
        fix = (
            "is the unit deg/s rather than rad/s? --unit gyr=deg/s or the column's unit in the mapping file"
            if declared_rad
            else f"declared {gyr_unit}: check the gyroscope's unit and bias"
        )
        peak = gyro_peak(gyr)
        at_rest = gyro_rate_at_rest(gyr, acc, t_ns, rest=rest) if acc is not None else None
        ratio = gyro_tilt_ratio(gyr, acc, t_ns, rest=rest, rate_hz=rate, ref_norm=ref_norm) if acc is not None else None
        rad_ok = ratio is not None and 0.5 * DEG * RATIO_DEG_MIN < ratio <= RATIO_RAD_MAX  # motion agrees
        if peak > GYRO_PEAK_MAX_RAD_S:
            out.append(
                f"{topic}: gyroscope peaks of {peak:.3g} rad/s ({peak / DEG:.0f} deg/s), beyond a human limb and "
                f"the +-2000 deg/s range of wearable gyroscopes; {fix}"
            )
        elif ratio is not None and RATIO_DEG_MIN <= ratio < 2.5 / DEG:
            out.append(
                f"{topic}: the gyroscope reads {ratio:.0f}x the rate at which gravity turns in the accelerometer "
                f"(1x expected in rad/s); {fix}"
            )
        elif not rad_ok and at_rest is not None and at_rest > GYRO_REST_MAX_RAD_S:
            bias = (
                " (the file declares it: a large gyroscope bias?)"
                if gyr_unit is not None
                else " (or a large gyroscope bias)"
            )
            out.append(
                f"{topic}: while the accelerometer shows the sensor at rest the gyroscope reads {at_rest:.2g} rad/s "
                f"about a horizontal axis (gravity would turn {at_rest / DEG:.0f} deg/s){bias}; {fix}"
            )
    return out


class PieceExcerpts:
    """The IMU streams of a recording converted piece by piece, for :func:`imu_warnings` at the end: each IMU's
    :class:`Excerpts`, fed every piece, so the check sees what it sees in the whole recording (the same samples,
    whatever the piece size) and never holds more than :data:`MAX_CHECK_SAMPLES` per IMU."""

    def __init__(self) -> None:
        self._kept: dict[str, Excerpts] = {}
        self._declared: dict[str, str | None] = {}

    def add(self, imu) -> None:  # noqa: ANN001 - imulog.model.ImuStream (no import cycle)
        """Add this piece of ``imu``."""
        if not len(imu.t_ns):
            return
        self._declared.setdefault(imu.topic, _declared_gyr_unit(imu))
        self._kept.setdefault(imu.topic, Excerpts()).add(imu.t_ns, imu.acc, imu.gyr)

    def warnings(self) -> list[str]:
        """:func:`imu_warnings` of every IMU on its excerpts."""
        out = []
        for topic, kept in self._kept.items():
            t, (acc, gyr) = kept.result()
            out.extend(imu_warnings(topic, acc, gyr, t, self._declared[topic]))
        return out


def _declared_gyr_unit(imu) -> str | None:  # noqa: ANN001 - imulog.model.ImuStream
    """The gyroscope unit the file itself declared (delimited, Xsens, APDM: ``units``; Delsys: ``units_in_file``)."""
    units = next((u for u in (imu.meta.get("units"), imu.meta.get("units_in_file")) if isinstance(u, dict)), {})
    return units.get("gyr")


def marker_warnings(topic: str, pos_m: np.ndarray) -> list[str]:
    """One line when marker positions (m) are too large for a lab (mm declared m) or all within 1 cm (m as mm)."""
    p = np.asarray(pos_m, dtype=np.float64)
    n = int(np.count_nonzero(np.isfinite(p)))
    if n == 0:
        return []
    # the 99th percentile lies between the sorted values k and k + 1: counts alone show it is well inside
    # (MARKER_MIN_SPAN_M, MARKER_MAX_M) in one pass, without copying and partly sorting every coordinate
    k = int(np.floor(0.99 * (n - 1)))
    beyond = int(np.count_nonzero(p > 0.98 * MARKER_MAX_M) + np.count_nonzero(p < -0.98 * MARKER_MAX_M))
    near = int(np.count_nonzero((p < 1.02 * MARKER_MIN_SPAN_M) & (p > -1.02 * MARKER_MIN_SPAN_M)))
    if beyond <= n - k - 2 and near <= k:
        return []
    big = float(np.quantile(np.abs(p[np.isfinite(p)]), 0.99))
    if big > MARKER_MAX_M:
        return [
            f"{topic}: marker coordinates reach {big:.3g} m, larger than any lab: are they mm declared m? "
            "--unit markers=mm"
        ]
    if big < MARKER_MIN_SPAN_M:
        return [
            f"{topic}: every marker stays within {big * 1000:.2g} mm of the origin: are the numbers m declared mm? "
            "--unit markers=m"
        ]
    return []


def _is_rad_s(unit: str) -> bool:
    from imulog.converters._common import unit_factor

    return unit_factor("gyr", unit) == 1.0


def recording_warnings(rec) -> list[str]:  # noqa: ANN001 - imulog.model.Recording (no import cycle)
    """Plausibility warnings for every IMU and marker stream of a converted Recording."""
    out = []
    for imu in rec.imus:
        out.extend(imu_warnings(imu.topic, imu.acc, imu.gyr, imu.t_ns, _declared_gyr_unit(imu)))
    for markers in rec.markers:
        out.extend(marker_warnings(markers.topic, markers.pos))
    return out
