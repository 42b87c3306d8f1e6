"""Days of wrist-worn IMU data at home, written chunk by chunk as an Axivity AX6 ``.cwa`` file.

The recordings that arm-use studies send home (Doshi 2011 ch. 5; Axivity and ActiGraph wrist sensors worn for a
week at 100 Hz) are too long to simulate in memory: a week at 100 Hz is 60 M samples. This model is generated one
minute at a time from a random stream seeded by (seed, minute index), so any chunk of the recording can be made
on its own and memory does not grow with the duration.

Model, per minute of wall-clock time:

* **night** (23:00-07:00): lying still, with a short turn-over movement in 5 % of the minutes;
* **day**: a bout of arm movement (10-50 s) in 35 % of the minutes, otherwise rest;
* a **posture** (roll, pitch of the forearm) held through each minute; consecutive postures blend over the
  first 2 s of the minute, so the signal is continuous;
* a **movement** is a sum of two sinusoidal rotations (0.4-1.5 Hz, 0.2-0.8 rad) under a smooth taper, about
  the forearm's axes; gravity rotates with the sensor; tremor-free sensor noise (0.004 g, 0.2 deg/s) is added.

Ground truth is the number of moving seconds per minute (``truth_moving_s``), small enough to keep for a week.
The ``.cwa`` layout is the one :mod:`imulog.converters.axivity` reads (AX6: gyro then accel, int16, 40 samples per
512-byte block; accelerometer +-8 g, gyroscope +-2000 deg/s; device local time, no zone).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

G0 = 9.80665
SAMPLES_PER_BLOCK = 40  # AX6: 6 axes x int16 = 12 bytes per sample, 480 data bytes per block
ACC_LSB_EXP = 4  # accel LSB 1/2^(8+4) g = 1/4096 g: +-8 g in int16
GYRO_RANGE_CODE = 2  # 8000 / 2^2 = 2000 deg/s full scale
HEADER_BYTES = 1024
BLOCK_BYTES = 512


@dataclass(frozen=True)
class HomeParams:
    """A home recording: duration in days, rate in Hz (a CWA rate: 3200 / 2^k), start (device local time)."""

    days: float = 1.0
    rate_hz: float = 100.0
    start: str = "2024-03-04T09:00:00"
    seed: int = 0
    day_move_probability: float = 0.35
    night_move_probability: float = 0.05
    night_start_h: float = 23.0
    night_end_h: float = 7.0
    noise_acc_g: float = 0.004
    noise_gyr_dps: float = 0.2
    removals_per_day: int = 0
    removal_min_minutes: int = 60
    removal_max_minutes: int = 180

    @property
    def samples_per_minute(self) -> int:
        return int(round(60 * self.rate_hz))

    @property
    def minutes(self) -> int:
        return int(round(self.days * 24 * 60))


def removals(p: HomeParams) -> list[tuple[int, int]]:
    """Device-removal periods as (first minute, end minute) of the recording, sorted and non-overlapping.

    ``removals_per_day`` per whole or partial day, each starting between 08:00 and 20:00 of the recording's
    days (minutes from the start), lasting ``removal_min_minutes``-``removal_max_minutes``; the device lies
    still on a table in a fixed orientation (the ground truth of non-wear detection).
    """
    out: list[tuple[int, int]] = []
    if p.removals_per_day <= 0:
        return out
    start = datetime.fromisoformat(p.start)
    first_midnight = -(start.hour * 60 + start.minute)
    for day in range(int(np.ceil(p.days)) + 1):
        rng = np.random.default_rng([p.seed, day, 2])
        for _ in range(p.removals_per_day):
            onset = first_midnight + day * 1440 + int(rng.integers(8 * 60, 20 * 60))
            length = int(rng.integers(p.removal_min_minutes, p.removal_max_minutes + 1))
            a, b = max(0, onset), min(p.minutes, onset + length)
            if b - a < p.removal_min_minutes or any(a < e + 60 and b > s - 60 for s, e in out):
                continue  # cut by the recording's ends, or too close to another removal
            out.append((a, b))
    return sorted(out)


def _removal_pose(p: HomeParams, removal: int) -> np.ndarray:
    """Gravity in the sensor frame while the device lies on a table (nearly flat, either face up)."""
    rng = np.random.default_rng([p.seed, removal, 3])
    tilt = rng.normal(0.0, 0.05, 2)
    z = 1.0 if rng.random() < 0.7 else -1.0
    v = np.array([tilt[0], tilt[1], z])
    return v / np.linalg.norm(v)


def _minute_plan(p: HomeParams, minute: int, start: datetime) -> tuple[np.ndarray, float, float, np.ndarray]:
    """(posture roll/pitch rad, bout start s, bout length s, movement parameters) of one minute, deterministic."""
    rng = np.random.default_rng([p.seed, minute])
    hour = (start + timedelta(minutes=minute)).hour
    night = hour >= p.night_start_h or hour < p.night_end_h
    posture = rng.uniform([-1.2, -0.6], [1.2, 0.6]) if not night else rng.uniform([-0.3, -0.2], [0.3, 0.2])
    moves = rng.random() < (p.night_move_probability if night else p.day_move_probability)
    length = (rng.uniform(3.0, 8.0) if night else rng.uniform(10.0, 50.0)) if moves else 0.0
    onset = rng.uniform(2.5, 58.0 - length) if moves else 0.0
    movement = np.concatenate([rng.uniform(0.4, 1.5, 2), rng.uniform(0.2, 0.8, 2), rng.uniform(0, 2 * np.pi, 2)])
    return posture, onset, length, movement


def minute_signals(p: HomeParams, minute: int, start: datetime) -> tuple[np.ndarray, np.ndarray, float]:
    """(acc g (S, 3), gyr deg/s (S, 3), moving seconds) of one minute in the sensor frame."""
    n = p.samples_per_minute
    s = np.arange(n) / p.rate_hz
    posture, onset, length, mv = _minute_plan(p, minute, start)
    previous = _minute_plan(p, minute - 1, start)[0] if minute > 0 else posture
    blend = np.clip(s / 2.0, 0.0, 1.0)
    blend = blend * blend * (3 - 2 * blend)  # smoothstep: no jump in the angles or their rate
    angles = previous[None, :] + (posture - previous)[None, :] * blend[:, None]
    moving_s = 0.0
    if length > 0:
        u = np.clip((s - onset) / length, 0.0, 1.0)
        taper = np.sin(np.pi * u) ** 2
        freq, amp, phase = mv[0:2], mv[2:4], mv[4:6]
        wave = np.sin(2 * np.pi * freq[None, :] * s[:, None] + phase[None, :]) * amp[None, :]
        angles = angles + wave * taper[:, None]
        moving_s = length
    roll, pitch = angles[:, 0], angles[:, 1]
    # gravity in the sensor frame for R = Rx(roll) Ry(pitch): g_s = R^T [0, 0, 1]
    acc = np.column_stack([-np.sin(pitch), np.sin(roll) * np.cos(pitch), np.cos(roll) * np.cos(pitch)])
    rate = np.gradient(angles, 1.0 / p.rate_hz, axis=0)
    gyr = np.column_stack([rate[:, 0], rate[:, 1] * np.cos(roll), -rate[:, 1] * np.sin(roll)])
    rng = np.random.default_rng([p.seed, minute, 1])
    removal = _removal_at(p, minute)
    if removal is not None:  # off the wrist: still, only the sensor's noise
        acc = np.repeat(_removal_pose(p, removal)[None, :], n, axis=0)
        gyr = np.zeros_like(acc)
        moving_s = 0.0
    acc = acc + rng.normal(0, p.noise_acc_g, acc.shape)
    gyr = np.degrees(gyr) + rng.normal(0, p.noise_gyr_dps, gyr.shape)
    return acc, gyr, moving_s


_REMOVALS: dict[HomeParams, list[tuple[int, int]]] = {}


def _removal_at(p: HomeParams, minute: int) -> int | None:
    """Index of the removal holding ``minute``, or None."""
    if p.removals_per_day <= 0:
        return None
    if p not in _REMOVALS:
        _REMOVALS.clear()
        _REMOVALS[p] = removals(p)
    for k, (a, b) in enumerate(_REMOVALS[p]):
        if a <= minute < b:
            return k
    return None


def iter_minutes(p: HomeParams) -> Iterator[tuple[int, np.ndarray, np.ndarray, float]]:
    """(minute index, acc g, gyr deg/s, moving seconds) for every minute of the recording, in order."""
    start = datetime.fromisoformat(p.start)
    for minute in range(p.minutes):
        acc, gyr, moving = minute_signals(p, minute, start)
        yield minute, acc, gyr, moving


# ---------------------------------------------------------------- .cwa writing
def _rate_code(rate_hz: float, range_g: int = 8) -> int:
    k = 15 - int(round(np.log2(3200.0 / rate_hz)))
    if not 0 <= k <= 15 or abs(3200.0 / 2 ** (15 - k) - rate_hz) > 1e-9:
        raise ValueError(f"{rate_hz} Hz is not a CWA rate (3200 / 2^k Hz)")
    return ({16: 0, 8: 1, 4: 2, 2: 3}[range_g] << 6) | k


def cwa_header(p: HomeParams, device_id: int = 4321, session_id: int = 1) -> bytes:
    h = bytearray(b"\xff" * HEADER_BYTES)
    h[0:2] = b"MD"
    h[2:4] = (HEADER_BYTES - 4).to_bytes(2, "little")
    h[4] = 0x64  # AX6
    h[5:7] = (device_id & 0xFFFF).to_bytes(2, "little")
    h[7:11] = session_id.to_bytes(4, "little")
    h[11:13] = b"\xff\xff"
    h[13:17] = (0).to_bytes(4, "little")  # logging start: not set (0 = always)
    h[17:21] = (0xFFFFFFFF).to_bytes(4, "little")
    h[35] = GYRO_RANGE_CODE
    h[36] = _rate_code(p.rate_hz)
    h[41] = 53
    h[64:512] = b" " * 448
    note = f"imulog simulate home seed={p.seed}".encode()
    h[64 : 64 + len(note)] = note
    return bytes(h)


def cwa_blocks(
    t0: datetime, first_sample: int, rate_hz: float, acc_g: np.ndarray, gyr_dps: np.ndarray, first_sequence: int
) -> bytes:
    """Whole AX6 blocks for samples ``first_sample ...`` (a multiple of 40 samples), checksummed."""
    n = len(acc_g)
    if n % SAMPLES_PER_BLOCK:
        raise ValueError("cwa_blocks needs a multiple of 40 samples")
    k = n // SAMPLES_PER_BLOCK
    blocks = np.zeros((k, BLOCK_BYTES), dtype=np.uint8)
    words = blocks.view("<u2")
    rate_code = _rate_code(rate_hz)
    samples = np.empty((n, 6), dtype="<i2")
    samples[:, 0:3] = np.clip(np.round(gyr_dps * (32768.0 / 2000.0)), -32768, 32767)
    samples[:, 3:6] = np.clip(np.round(acc_g * 2 ** (8 + ACC_LSB_EXP)), -32768, 32767)
    blocks[:, 30:510] = samples.reshape(k, 240).view(np.uint8)
    start_s = (first_sample + np.arange(k) * SAMPLES_PER_BLOCK) / rate_hz
    whole = np.floor(start_s).astype(np.int64)
    frac16 = np.round((start_s - whole) * 65536).astype(np.int64) & 0xFFFE
    when = np.datetime64(t0.replace(tzinfo=None), "s") + whole.astype("timedelta64[s]")
    day = when.astype("datetime64[D]")
    month = when.astype("datetime64[M]")
    year = when.astype("datetime64[Y]").astype(np.int64) + 1970
    second_of_day = (when - day).astype(np.int64)
    rtc = (
        ((year - 2000) & 0x3F) << 26
        | ((month.astype(np.int64) % 12 + 1) & 0x0F) << 22
        | (((day - month).astype(np.int64) + 1) & 0x1F) << 17
        | ((second_of_day // 3600) & 0x1F) << 12
        | ((second_of_day // 60 % 60) & 0x3F) << 6
        | (second_of_day % 60) & 0x3F
    ).astype("<u4")
    sequence = (first_sequence + np.arange(k)).astype("<u4")
    words[:, 0] = 0x5841  # "AX"
    words[:, 1] = 508
    words[:, 2] = 0x8000 | (frac16 >> 1)
    words[:, 3:5] = np.full(k, 1, "<u4").view("<u2").reshape(k, 2)  # session id
    words[:, 5:7] = sequence.view("<u2").reshape(k, 2)
    words[:, 7:9] = rtc.view("<u2").reshape(k, 2)
    words[:, 9] = (ACC_LSB_EXP << 13) | (GYRO_RANGE_CODE << 10) | 300  # light: accel and gyro scales
    words[:, 10] = 171 + int(3.142 * 30)  # 30 degC
    blocks[:, 23] = 190  # battery
    blocks[:, 24] = rate_code
    blocks[:, 25] = 0x62
    words[:, 13] = (-((frac16 * int(rate_hz)) // 65536)).astype(np.int16).view(np.uint16)  # timestampOffset
    words[:, 14] = SAMPLES_PER_BLOCK
    sums = words[:, :255].sum(axis=1, dtype=np.uint64) & 0xFFFF
    words[:, 255] = ((0x10000 - sums) & 0xFFFF).astype(np.uint16)
    return blocks.tobytes()


def write_home_cwa(
    path: str | Path,
    p: HomeParams,
    minutes_per_write: int = 10,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Write the recording to ``path`` chunk by chunk; return moving seconds per minute (the ground truth).

    ``progress(minutes_done, minutes_total)`` is called after each write. The file appears atomically; like a
    device, it ends with the last whole 40-sample block.
    """
    path = Path(path)
    t0 = datetime.fromisoformat(p.start)
    truth = np.zeros(p.minutes, dtype=np.float32)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as f:
        f.write(cwa_header(p))
        acc_parts: list[np.ndarray] = []
        gyr_parts: list[np.ndarray] = []
        written = 0  # samples already in blocks
        for minute, acc, gyr, moving in iter_minutes(p):
            truth[minute] = moving
            acc_parts.append(acc)
            gyr_parts.append(gyr)
            if len(acc_parts) >= minutes_per_write or minute == p.minutes - 1:
                acc_c, gyr_c = np.concatenate(acc_parts), np.concatenate(gyr_parts)
                whole = len(acc_c) - len(acc_c) % SAMPLES_PER_BLOCK  # the rest waits for the next write
                seq = written // SAMPLES_PER_BLOCK
                f.write(cwa_blocks(t0, written, p.rate_hz, acc_c[:whole], gyr_c[:whole], seq))
                written += whole
                acc_parts, gyr_parts = [acc_c[whole:]], [gyr_c[whole:]]
                if progress is not None:
                    progress(minute + 1, p.minutes)
    tmp.replace(path)
    return truth


def simulate_home_to_folder(
    out_dir: str | Path, *, subjects: int = 1, trials: int = 1, seed: int = 0, progress=None, **overrides
) -> list[dict[str, Path]]:
    """``imulog simulate home``: one ``.cwa`` per subject and trial plus ``<stem>_truth.npz`` (moving s/minute,
    ``removal_minutes``: (first, end) minute of each device removal)."""
    import dataclasses
    import json

    names = {f.name for f in dataclasses.fields(HomeParams)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ValueError(f"unknown home parameter(s) {', '.join(unknown)}; known: {', '.join(sorted(names))}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for s in range(subjects):
        for t in range(trials):
            params = HomeParams(**{**overrides, "seed": seed * 1000 + s * 100 + t})
            stem = f"home_s{s:02d}_t{t:02d}"
            cwa = out / f"{stem}.cwa"
            truth = write_home_cwa(cwa, params, progress=progress)
            npz = out / f"{stem}_truth.npz"
            off = np.array(removals(params), dtype=np.int64).reshape(-1, 2)
            np.savez_compressed(
                npz, moving_s_per_minute=truth, removal_minutes=off, params=json.dumps(dataclasses.asdict(params))
            )
            written.append({"cwa": cwa, "truth_npz": npz})
    return written
