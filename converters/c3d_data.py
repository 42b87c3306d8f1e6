"""imulog's own reader of C3D point and analog data, frame range by frame range (:mod:`imulog.converters.c3d_format`).

Every conversion reads its data with it (ezc3d, guarded, reads only the parameters: :mod:`imulog.converters.c3d`),
so a long file is read a range of frames at a time: memory is bounded by a range, not by the file. :func:`layout`
gives where the frames are and how they decode (from the header and parameters only); :func:`read_frames` reads a
range of frames of the file, in any processor type (Intel, DEC, MIPS), as Intel words; :func:`decode` turns them
into ezc3d's structures for the fields :mod:`imulog.converters.c3d` uses: ``data.points`` (4, M, N),
``data.meta_points.residuals`` (1, M, N; -1 = invalid), ``data.meta_points.camera_masks`` (7, M, N) and
``data.analogs`` (1, C, N * ratio). :func:`read` is the whole file of an Intel layout at once, with
:func:`ezc3d_parameters` (``header.points`` and ``parameters[GROUP][NAME]["value"]`` as ezc3d gives them).

Frames: ``POINT:FRAMES`` when present (the header's 16-bit last frame wraps for long trials), else the header's
``last - first + 1``; a trial longer than 65535 frames is counted by ``TRIAL:ACTUAL_START_FIELD`` and
``ACTUAL_END_FIELD`` (two 16-bit words each, low first), else ``POINT:LONG_FRAMES`` (a float), as the `c3d` package
reads them. A file with fewer whole frames is truncated. Points: int16 x ``POINT:SCALE`` (or float32 when the scale
is negative); the fourth word's sign marks an invalid point, its low byte times ``|scale|`` is the residual and its
high byte's 7 bits the cameras (the C3D guide's layout; ezc3d reads the two bytes the other way round). Analogs:
``(raw - ANALOG:OFFSET) * ANALOG:GEN_SCALE * ANALOG:SCALE`` per channel (raw unsigned when ``ANALOG:FORMAT`` is
``UNSIGNED``).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from imulog.converters.c3d_format import C3dLayoutError, data_words, parameters

SHORT_FRAMES = 65535  # the most frames the header's and POINT:FRAMES' 16-bit words count


@dataclass(frozen=True)
class Layout:
    """Where a C3D's frames are and how they decode, from its header and parameters (Intel layout)."""

    frames: int  # frames to read
    first: int  # the first frame, 0-based (as ezc3d's header ``first_frame``)
    scale: float  # POINT:SCALE (else the header's); negative: a float file
    n_points: int
    n_analog: int
    ratio: int  # analog samples per channel per frame
    data_start: int  # byte offset of frame 0
    unsigned: bool  # ANALOG:FORMAT UNSIGNED (integer files)
    offset: np.ndarray  # (n_analog,) ANALOG:OFFSET, counts
    gain: np.ndarray  # (n_analog,) ANALOG:GEN_SCALE x ANALOG:SCALE

    @property
    def word(self) -> int:
        """Bytes per data word: 4 (float32) or 2 (int16)."""
        return 4 if self.scale < 0 else 2

    @property
    def per_frame(self) -> int:
        """Words per frame (four per point, then every analog sample of the frame)."""
        return self.n_points * 4 + self.n_analog * self.ratio

    @property
    def frame_bytes(self) -> int:
        return self.per_frame * self.word


def _u16(value: Any) -> int:
    return int(value) & 0xFFFF


def frame_count(flat: dict[str, Any], first_h: int, last_h: int) -> tuple[int, int, str]:
    """(first frame, 1-based; frames; what counted them) from the parameters and the header's first and last frame.

    ``POINT:FRAMES`` (a signed 16-bit value above 32767 wraps), else the header's count; beyond 65535 frames the
    trial's own count: ``TRIAL:ACTUAL_START_FIELD``/``ACTUAL_END_FIELD``, else ``POINT:LONG_FRAMES``."""
    start, end = flat.get("TRIAL:ACTUAL_START_FIELD"), flat.get("TRIAL:ACTUAL_END_FIELD")
    if isinstance(start, list) and isinstance(end, list) and len(start) >= 2 and len(end) >= 2:
        lo = _u16(start[0]) + (_u16(start[1]) << 16)
        hi = _u16(end[0]) + (_u16(end[1]) << 16)
        if hi - lo + 1 > SHORT_FRAMES and lo >= 1:
            return lo, hi - lo + 1, "TRIAL:ACTUAL_END_FIELD"
    long = flat.get("POINT:LONG_FRAMES")
    if isinstance(long, list) and long and np.isfinite(long[0]) and int(long[0]) > SHORT_FRAMES:
        return first_h, int(long[0]), "POINT:LONG_FRAMES"
    pf = flat.get("POINT:FRAMES")
    if isinstance(pf, list) and pf and np.isfinite(pf[0]):
        return first_h, int(pf[0]) + (65536 if int(pf[0]) < 0 else 0), "POINT:FRAMES"
    return first_h, last_h - first_h + 1, "header"


def layout(prefix: bytes, flat: dict[str, Any], file_size: int) -> Layout:
    """The data layout of an Intel C3D whose header and parameters are ``prefix`` (:func:`~imulog.converters.c3d_format.read_prefix`
    rewritten as Intel) and ``flat`` (:func:`~imulog.converters.c3d_format.parameters`); C3dLayoutError when the
    file (``file_size`` bytes) holds fewer whole frames than it declares."""
    if len(prefix) < 512:
        raise C3dLayoutError("too short to be a C3D file")
    n_points, analog_per_frame, first, last = struct.unpack_from("<4H", prefix, 2)
    (scale_h,) = struct.unpack_from("<f", prefix, 12)
    data_block, spf = struct.unpack_from("<HH", prefix, 16)

    def num(key: str, default: Any) -> Any:
        v = flat.get(key)
        return v if isinstance(v, list) and v else default

    first, frames, _ = frame_count(flat, first, last)
    scale = float(num("POINT:SCALE", [scale_h])[0])
    n_points = int(num("POINT:USED", [n_points])[0])
    n_analog = int(num("ANALOG:USED", [analog_per_frame // max(spf, 1) if spf else 0])[0])
    ratio = spf if spf else (analog_per_frame // n_analog if n_analog else 0)
    if n_points < 0 or n_analog < 0:
        raise C3dLayoutError(f"negative POINT:USED {n_points} or ANALOG:USED {n_analog}")
    word = 4 if scale < 0 else 2
    per_frame = n_points * 4 + n_analog * ratio
    start = (max(data_block, 1) - 1) * 512
    have = (file_size - start) // (per_frame * word) if per_frame else 0
    if per_frame and have < frames:
        raise C3dLayoutError(f"truncated C3D: {have} whole frames, POINT:FRAMES says {frames}")
    off = np.asarray(num("ANALOG:OFFSET", [0] * n_analog)[:n_analog], dtype=np.float64)
    sc = np.asarray(num("ANALOG:SCALE", [1.0] * n_analog)[:n_analog], dtype=np.float64)
    gen = float(num("ANALOG:GEN_SCALE", [1.0])[0])
    fmt = str(flat.get("ANALOG:FORMAT", "") or "").strip().upper()
    return Layout(
        frames=frames,
        first=int(first) - 1,
        scale=scale,
        n_points=n_points,
        n_analog=n_analog,
        ratio=ratio,
        data_start=start,
        unsigned=word == 2 and fmt.startswith("UNSIGNED"),
        offset=np.pad(off, (0, n_analog - len(off))),
        gain=gen * np.pad(sc, (0, n_analog - len(sc)), constant_values=1.0),
    )


def read_frames(f: BinaryIO, lay: Layout, proc: int, lo: int, hi: int) -> np.ndarray:
    """Frames ``[lo, hi)`` of the open file ``f`` (processor ``proc``) as (hi - lo, per_frame) Intel words."""
    f.seek(lay.data_start + lo * lay.frame_bytes)
    raw = f.read((hi - lo) * lay.frame_bytes)
    if len(raw) < (hi - lo) * lay.frame_bytes:
        raise C3dLayoutError(f"truncated C3D: the file ends inside frame {lo + len(raw) // max(lay.frame_bytes, 1)}")
    return data_words(raw, proc, lay.word == 4).reshape(hi - lo, lay.per_frame)


def decode(block: np.ndarray, lay: Layout) -> dict[str, Any]:
    """Frames of words (:func:`read_frames`) as ezc3d's ``data`` structures (see the module docstring)."""
    frames = len(block)
    pts = block[:, : lay.n_points * 4].reshape(frames, lay.n_points, 4).astype(np.float64)
    res_word = pts[:, :, 3]
    invalid = res_word < 0
    xyz = pts[:, :, :3] * (1.0 if lay.word == 4 else abs(lay.scale))
    w4 = np.abs(res_word).astype(np.int64)
    resid = np.where(invalid, -1.0, (w4 & 0xFF) * abs(lay.scale))
    bits = (np.where(invalid, 0, w4)[None, :, :] >> (8 + np.arange(7))[:, None, None]) & 1  # cameras 1-7
    cameras = np.transpose(bits.astype(bool), (0, 2, 1))  # (7, M, N) as ezc3d
    points = np.ones((4, lay.n_points, frames))
    points[:3] = np.transpose(xyz, (2, 1, 0))
    points[:3, :, :][:, invalid.T] = np.nan
    n_analog, ratio = lay.n_analog, lay.ratio
    raw_an = block[:, lay.n_points * 4 :].reshape(frames * ratio, n_analog) if n_analog and ratio else None
    if raw_an is not None and raw_an.size:
        if lay.unsigned:
            raw_an = raw_an.astype(np.int64) & 0xFFFF
        analogs = ((raw_an - lay.offset) * lay.gain).T[None, :, :]
    else:
        analogs = np.zeros((1, 0, 0))
    return {
        "points": points,
        "meta_points": {"residuals": resid.T[None, :, :], "camera_masks": cameras},
        "analogs": analogs,
    }


def _nested(params: dict[str, Any]) -> dict[str, dict[str, dict[str, Any]]]:
    """``GROUP:NAME`` -> value as ezc3d's ``parameters[GROUP][NAME]["value"]`` (strings split by their width)."""
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for key, value in params.items():
        group, _, name = key.partition(":")
        out.setdefault(group, {})[name] = {"value": value}
    return out


def _strings(data: bytes, key: str) -> list[str]:
    """A character parameter split into its entries (the first dimension is the entry width)."""
    raw = _raw_dims(data).get(key)
    if raw is None:
        return []
    text, dims = raw
    if len(dims) < 2:
        return [text.strip()]
    w = dims[0]
    return [text[i * w : (i + 1) * w].strip() for i in range(int(np.prod(dims[1:])))]


def _raw_dims(data: bytes) -> dict[str, tuple[str, list[int]]]:
    """``GROUP:NAME`` -> (characters, dims) of the character parameters of an Intel C3D."""
    p = (data[0] - 1) * 512
    pos, groups, out = p + 4, {}, {}
    while pos + 2 <= len(data):
        nchar, gid = struct.unpack_from("bb", data, pos)
        if nchar == 0:
            break
        name = data[pos + 2 : pos + 2 + abs(nchar)].decode("latin-1").strip().upper()
        (nxt,) = struct.unpack_from("<h", data, pos + 2 + abs(nchar))
        body = pos + 4 + abs(nchar)
        if gid < 0:
            groups[-gid] = name
        elif body + 2 <= len(data):
            ptype, ndim = struct.unpack_from("bB", data, body)
            if ptype == -1:
                dims = list(data[body + 2 : body + 2 + ndim])
                start = body + 2 + ndim
                n = int(np.prod(dims)) if ndim else 1
                out[(gid, name)] = (data[start : start + n].decode("latin-1"), dims)
        if nxt <= 0:
            break
        pos = pos + 2 + abs(nchar) + nxt
    return {f"{groups.get(g, str(g))}:{n}": v for (g, n), v in out.items()}


def ezc3d_parameters(prefix: bytes) -> dict[str, Any]:
    """The ``header`` and ``parameters`` of an Intel C3D's header and parameter section, as ezc3d's ``c3d()``
    gives them (for a file ezc3d cannot read)."""
    (rate,) = struct.unpack_from("<f", prefix, 20)
    n_points, _, first, _ = struct.unpack_from("<4H", prefix, 2)
    params = _nested(parameters(prefix))
    for key in list(_raw_dims(prefix)):
        g, _, n = key.partition(":")
        params[g][n] = {"value": _strings(prefix, key)}
    times = params.get("EVENT", {}).get("TIMES")
    if times is not None and isinstance(times["value"], list) and len(times["value"]) % 2 == 0:
        times["value"] = np.asarray(times["value"]).reshape(-1, 2).T  # (2, events): minutes, seconds as ezc3d
    return {
        "header": {"points": {"frame_rate": float(rate), "first_frame": int(first) - 1, "size": n_points}},
        "parameters": params,
    }


def read(data: bytes) -> dict[str, Any]:
    """The C3D content of a whole Intel-layout file as ezc3d structures (``header``, ``parameters``, ``data``)."""
    if len(data) < 512:
        raise C3dLayoutError("too short to be a C3D file")
    lay = layout(data, parameters(data), len(data))
    block = np.frombuffer(
        data, dtype="<f4" if lay.word == 4 else "<i2", count=lay.frames * lay.per_frame, offset=lay.data_start
    ).reshape(lay.frames, lay.per_frame)
    return {**ezc3d_parameters(data), "data": decode(block, lay)}
