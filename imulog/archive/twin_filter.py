"""Anti-alias filter of the IMU viewer twins: a zero-phase FIR low-pass applied before keeping every k-th sample.

A twin keeps every ``k``-th sample (:func:`imulog.archive.twins.decimation`), so its Nyquist frequency is
``rate / (2 k)``. Before decimation each filtered signal goes through a linear-phase (zero delay: the
kernel is centred on its sample) Kaiser-window FIR whose pass band is flat (ripple <= 0.1 %) up to
:data:`PASS_FRACTION` of the twin's Nyquist and whose stop band, from the twin's Nyquist up, is at least
:data:`STOP_DB` down: content that would alias into the twin is removed instead.

The kernel is finite (:func:`margin` samples on each side), so a recording written piece by piece gives
the same twin as one written whole when each piece sees ``margin`` samples of its neighbours
(:class:`PieceFilter` holds them). Samples that do not exist (NaN, before the start and
after the end, across a time gap longer than 1.5 periods) get no weight; the kernel's remaining weights
are renormalised (the value at the sample itself is NaN when the sample is).
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache
from typing import Any

import numpy as np

PASS_FRACTION = 0.8  # pass band edge, as a fraction of the twin's Nyquist frequency
STOP_DB = 60.0  # attenuation from the twin's Nyquist frequency up
GAP_PERIODS = 1.5  # a step longer than this many median periods is a gap the filter does not cross


@lru_cache(maxsize=64)
def taps(k: int) -> np.ndarray:
    """The FIR kernel for decimation by ``k`` (odd length, symmetric, sums to 1); ``[1.0]`` for k <= 1."""
    if k <= 1:
        return np.ones(1)
    nyquist = 0.5 / k  # the twin's, in cycles per source sample
    edge = PASS_FRACTION * nyquist
    # Kaiser's design formulas (as scipy.signal.kaiserord; numpy only: scipy.signal takes 0.7 s to import)
    beta = 0.1102 * (STOP_DB - 8.7)
    n = int(np.ceil((STOP_DB - 7.95) / (2.285 * 2 * np.pi * (nyquist - edge)) + 1)) | 1
    m = np.arange(n) - (n - 1) / 2
    cut = 0.5 * (edge + nyquist)
    h = 2 * cut * np.sinc(2 * cut * m) * np.kaiser(n, beta)
    h /= h.sum()
    h.flags.writeable = False
    return h


def margin(k: int) -> int:
    """Samples the kernel reaches on each side of its centre."""
    return len(taps(k)) // 2


def segments(t_ns: np.ndarray) -> np.ndarray:
    """Segment number of each sample: a new segment after every step > :data:`GAP_PERIODS` median periods."""
    t = np.asarray(t_ns, np.int64)
    if len(t) < 2:
        return np.zeros(len(t), np.int64)
    dt = np.diff(t)
    med = float(np.median(dt))
    return np.concatenate([[0], np.cumsum(dt > GAP_PERIODS * med)]) if med > 0 else np.zeros(len(t), np.int64)


def _fir_at(x: np.ndarray, h: np.ndarray, first: int, count: int, k: int) -> np.ndarray:
    """``sum_m h[m] x[c - half + m]`` at ``c = first + j k`` (j < count), x (n, C) zero outside: (count, C).

    Polyphase: phase ``p`` correlates every k-th sample from ``first + p`` with every k-th tap from ``p``
    (``np.correlate``, no BLAS threads, no window copies): count * len(h) multiply-adds per column.
    """
    half = len(h) // 2
    taps_per_phase = -(-len(h) // k)
    span = (count - 1 + taps_per_phase) * k + 1  # samples of the padded signal the outputs reach
    pad = np.zeros((first + span + k, x.shape[1]))
    n = min(len(x), len(pad) - half)
    pad[half : half + n] = x[:n]
    out = np.zeros((count, x.shape[1]))
    for p in range(min(k, len(h))):
        g = h[p::k]
        seq = pad[first + p :: k][: count + len(g) - 1]
        for col in range(x.shape[1]):
            out[:, col] += np.correlate(seq[:, col], g, "valid")[:count]
    return out


def _filter_run(x: np.ndarray, ok: np.ndarray, first: int, count: int, k: int) -> np.ndarray:
    """Filtered (count, C) values at ``first, first + k, ...`` of one gap-free run ``x`` (n, C)."""
    h = taps(k)
    every = bool(ok.all())
    num = _fir_at(x if every else np.where(ok, x, 0.0), h, first, count, k)
    mask = np.ones((len(x), 1)) if every else ok.astype(np.float64)  # all present: one weight column for all
    den = _fir_at(mask, h, first, count, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 1e-3, num / den, np.nan)


def lowpass_at(values: np.ndarray, keep: np.ndarray, k: int, t_ns: np.ndarray | None = None) -> np.ndarray:
    """Low-passed ``values`` (N, ...) at the kept indices ``keep`` (every k-th sample), same trailing shape.

    ``t_ns``: the samples' times (time gaps split the filter); NaN samples have no weight and stay NaN.
    """
    v = np.asarray(values, np.float64)
    shape = v.shape[1:]
    flat = v.reshape(len(v), -1)
    keep = np.asarray(keep, np.int64)
    if k <= 1 or not len(keep):
        return flat[keep].reshape((len(keep), *shape))
    out = np.full((len(keep), flat.shape[1]), np.nan)
    seg = segments(t_ns) if t_ns is not None else np.zeros(len(flat), np.int64)
    bounds = np.flatnonzero(np.diff(seg)) + 1
    starts, ends = np.concatenate([[0], bounds]), np.concatenate([bounds, [len(flat)]])
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        lo, hi = np.searchsorted(keep, a), np.searchsorted(keep, b)
        if hi <= lo:
            continue
        x = flat[a:b]
        ok = np.isfinite(x)
        out[lo:hi] = _filter_run(x, ok, int(keep[lo]) - a, hi - lo, k)
    out[~np.isfinite(flat[keep])] = np.nan
    return out.reshape((len(keep), *shape))


FILTERED_FIELDS = ("acc", "gyr", "mag")  # the ImuStream arrays that are filtered


def filtered(stream: Any) -> bool:
    """True for the streams whose twins are low-passed: IMU streams.

    Marker positions are not: on pyomeca's real Nexus trial (51 markers, 100 Hz) their content above a 25 Hz
    twin's Nyquist is -60 dB (median) to -46 dB (max) of their power, below what the filter is for, and
    filtering 120 columns would cost 0.3 s per 10 minutes of a 40-marker capture.
    """
    from imulog.model import ImuStream

    return isinstance(stream, ImuStream)


def lowpassed(stream: Any, keep: np.ndarray, k: int) -> Any:
    """``take_samples(stream, keep)`` with its IMU axes (acc, gyr, mag) low-passed for decimation by ``k``."""
    from imulog.model import take_samples

    out = take_samples(stream, keep)
    for name in FILTERED_FIELDS:
        arr = getattr(stream, name, None)
        if isinstance(arr, np.ndarray) and len(arr) == len(stream.t_ns):
            setattr(out, name, lowpass_at(arr, keep, k, stream.t_ns))
    return out


def _concat(a: Any, b: Any) -> Any:
    """Two consecutive pieces of one stream as one (per-sample arrays joined; the rest from ``b``)."""
    fields = {}
    for f in dataclasses.fields(b):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(y, np.ndarray) and y.ndim >= 1 and len(y) == len(b.t_ns) and isinstance(x, np.ndarray):
            y = np.concatenate([x, y])
        fields[f.name] = y
    return type(b)(**fields)


def _slice(stream: Any, start: int) -> Any:
    from imulog.model import take_samples

    return take_samples(stream, np.arange(start, len(stream.t_ns)))


class PieceFilter:
    """The twin samples of a stream written piece by piece, equal to filtering the whole recording.

    :meth:`push` returns the decimated, low-passed samples whose right margin has arrived (the last
    :func:`margin` samples wait for the next piece); :meth:`flush` the rest at the end. Kept samples are the
    global indices ``0, k, 2k, ...`` of the recording.
    """

    def __init__(self, k: int) -> None:
        self.k, self.half = k, margin(k)
        self._buf: Any = None  # held samples: left margin + samples not yet emitted
        self._base = 0  # global index of self._buf's first sample
        self._next = 0  # buffer index of the first sample not yet emitted

    def _emit(self, buf: Any, stop: int) -> Any:
        i = np.arange(self._next, max(stop, self._next))
        keep = i[(self._base + i) % self.k == 0]
        return lowpassed(buf, keep, self.k) if len(keep) else None

    def push(self, piece: Any) -> Any:
        """The ready twin samples after ``piece`` (a Stream of the kept samples, or None)."""
        buf = piece if self._buf is None else _concat(self._buf, piece)
        n = len(buf.t_ns)
        stop = n - self.half
        out = self._emit(buf, stop)
        self._next = max(self._next, stop)
        cut = max(0, min(self._next - self.half, n))
        self._buf, self._base, self._next = _slice(buf, cut), self._base + cut, self._next - cut
        return out

    def flush(self) -> Any:
        """The samples still held (the recording's last ``margin``), filtered with what exists."""
        if self._buf is None:
            return None
        out = self._emit(self._buf, len(self._buf.t_ns))
        self._buf = None
        return out
