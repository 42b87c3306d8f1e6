"""Independent re-statements of the two .cwa sample-time rules, for tests (seconds, float64)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from imulog.converters.axivity import BLOCK_DTYPE, HEADER_BYTES, MAGIC_AX, rate_from_code, rtc_to_epoch_s


def ax_blocks(path: Path) -> np.ndarray:
    """The intact-or-not 'AX' data blocks of a file, as a structured array."""
    b = np.fromfile(path, dtype=BLOCK_DTYPE, offset=HEADER_BYTES)
    return b[b["magic"] == MAGIC_AX]


def skdh_rule_s(b: np.ndarray) -> np.ndarray:
    """scikit-digital-health's sample times (read_axivity.f95 get_time): block start RTC - timestampOffset / rate
    (no fraction, no shim), moved to the previous block's nominal end when that is less than 1 s before."""
    f = rate_from_code(b["rate_code"])
    n = b["count"].astype(np.float64)
    t0 = rtc_to_epoch_s(b["rtc"]).astype(np.float64) - b["offset"] / f
    t1 = t0 + n / f
    s = t0.copy()
    s[1:] = np.where(t0[1:] - t1[:-1] < 1.0, t1[:-1], t0[1:])
    return np.concatenate([s[k] + np.arange(int(n[k])) * (t1[k] - s[k]) / n[k] for k in range(len(b))])


def openmovement_block_start_s(b: np.ndarray) -> np.ndarray:
    """OpenMovement's block start: RTC + fraction - (timestampOffset + shim) / rate, shim = fraction * int(rate)."""
    f = rate_from_code(b["rate_code"])
    frac = (b["fractional"].astype(np.int64) & 0x7FFF) << 1
    shim = (frac * f.astype(np.int64)) >> 16
    return rtc_to_epoch_s(b["rtc"]) + frac / 65536 - (b["offset"] + shim) / f


def skdh_own_start_s(b: np.ndarray) -> np.ndarray:
    """skdh's start of a block that does not follow another: RTC - timestampOffset / rate (s)."""
    return rtc_to_epoch_s(b["rtc"]) - b["offset"] / rate_from_code(b["rate_code"])
