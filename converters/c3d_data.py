"""imulog's own reader of C3D point and analog data (Intel layout, see :mod:`imulog.converters.c3d_format`).

Used when the C3D library cannot read a file (ezc3d refuses MIPS files and crashes on some old ones). It returns
the same structure as ezc3d's ``c3d()`` for the fields :mod:`imulog.converters.c3d` uses: ``header.points``
(``frame_rate``, ``first_frame``), ``parameters[GROUP][NAME]["value"]``, ``data.points`` (4, M, N),
``data.meta_points.residuals`` (1, M, N; -1 = invalid), ``data.meta_points.camera_masks`` (7, M, N) and
``data.analogs`` (1, C, N * ratio).

Frames: ``POINT:FRAMES`` when present (the header's 16-bit last frame wraps for long trials), else the header's
``last - first + 1``; a file with fewer whole frames is truncated. Points: int16 x ``POINT:SCALE`` (or float32 when
the scale is negative); the fourth word's sign marks an invalid point, its low byte times ``|scale|`` is the
residual and its high byte's 7 bits the cameras (the C3D guide's layout; ezc3d reads the two bytes the other way
round). Analogs: ``(raw - ANALOG:OFFSET) * ANALOG:GEN_SCALE * ANALOG:SCALE`` per channel (raw unsigned when
``ANALOG:FORMAT`` is ``UNSIGNED``).
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
from imulog.converters.c3d_format import C3dLayoutError, parameters


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


def read(data: bytes) -> dict[str, Any]:
    """The C3D content of an Intel-layout file as ezc3d structures (see the module docstring)."""
    if len(data) < 512:
        raise C3dLayoutError("too short to be a C3D file")
    n_points, analog_per_frame, first, last = struct.unpack_from("<4H", data, 2)
    (scale_h,) = struct.unpack_from("<f", data, 12)
    data_block, spf = struct.unpack_from("<HH", data, 16)
    (rate,) = struct.unpack_from("<f", data, 20)
    flat = parameters(data)
    params = _nested(flat)
    for key in list(_raw_dims(data)):
        g, _, n = key.partition(":")
        params[g][n] = {"value": _strings(data, key)}

    def num(key: str, default: Any) -> Any:
        v = flat.get(key)
        return v if isinstance(v, list) and v else default

    frames = int(num("POINT:FRAMES", [last - first + 1])[0])
    if frames < 0:  # a signed 16-bit FRAMES above 32767
        frames += 65536
    scale = float(num("POINT:SCALE", [scale_h])[0])
    word = 4 if scale < 0 else 2
    n_points = int(num("POINT:USED", [n_points])[0])
    n_analog = int(num("ANALOG:USED", [analog_per_frame // max(spf, 1) if spf else 0])[0])
    ratio = spf if spf else (analog_per_frame // n_analog if n_analog else 0)
    per_frame = n_points * 4 + n_analog * ratio
    start = (max(data_block, 1) - 1) * 512
    have = (len(data) - start) // (per_frame * word) if per_frame else 0
    if have < frames:
        raise C3dLayoutError(f"truncated C3D: {have} whole frames, POINT:FRAMES says {frames}")
    dt = "<f4" if word == 4 else "<i2"
    block = np.frombuffer(data, dtype=dt, count=frames * per_frame, offset=start).reshape(frames, per_frame)
    pts = block[:, : n_points * 4].reshape(frames, n_points, 4).astype(np.float64)
    res_word = pts[:, :, 3]
    invalid = res_word < 0
    xyz = pts[:, :, :3] * (1.0 if word == 4 else abs(scale))
    w4 = np.abs(res_word).astype(np.int64)
    resid = np.where(invalid, -1.0, (w4 & 0xFF) * abs(scale))
    bits = (np.where(invalid, 0, w4)[None, :, :] >> (8 + np.arange(7))[:, None, None]) & 1  # cameras 1-7
    cameras = np.transpose(bits.astype(bool), (0, 2, 1))  # (7, M, N) as ezc3d
    points = np.ones((4, n_points, frames))
    points[:3] = np.transpose(xyz, (2, 1, 0))
    points[:3, :, :][:, invalid.T] = np.nan
    raw_an = block[:, n_points * 4 :].reshape(frames * ratio, n_analog) if n_analog and ratio else np.zeros((0, 0))
    if raw_an.size:
        fmt = str(flat.get("ANALOG:FORMAT", "") or "").strip().upper()
        if word == 2 and fmt.startswith("UNSIGNED"):
            raw_an = raw_an.astype(np.int64) & 0xFFFF
        off = np.asarray(num("ANALOG:OFFSET", [0] * n_analog)[:n_analog], dtype=np.float64)
        sc = np.asarray(num("ANALOG:SCALE", [1.0] * n_analog)[:n_analog], dtype=np.float64)
        gen = float(num("ANALOG:GEN_SCALE", [1.0])[0])
        off = np.pad(off, (0, n_analog - len(off)))
        sc = np.pad(sc, (0, n_analog - len(sc)), constant_values=1.0)
        analogs = ((raw_an - off) * gen * sc).T[None, :, :]
    else:
        analogs = np.zeros((1, 0, 0))
    return {
        "header": {"points": {"frame_rate": float(rate), "first_frame": int(first) - 1, "size": n_points}},
        "parameters": params,
        "data": {
            "points": points,
            "meta_points": {"residuals": resid.T[None, :, :], "camera_masks": cameras},
            "analogs": analogs,
        },
    }
