"""Build older Genea ``.bin`` files by the documented layout (GGIRread's readGenea.R; converters/genea.py).

The layout was checked on GGIRread's real ``genea_testfile.bin`` (tests/data/genea_testfile.bin.xz): a
``GENEA/1.00`` line and ``Key:Value`` lines ending with CRLF, a blank line, then 2048-byte pages of 341 six-byte
chunks and two zero bytes; one time stamp chunk before every ``rate`` accelerometer chunks, one battery chunk per
page, the first byte of every chunk varying (unused by the reference reader). The builder writes the same, with
known counts and times.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

GAINS = (8144, 8132, 8004)
OFFSETS = (1, -3, -13)
T0 = 1269950917  # the real file's first stamp, 2010-03-30 12:08:37 on the device clock
BATTERY_RAW = 113


@dataclass
class Built:
    path: Path
    counts: np.ndarray  # (N, 3) signed 12-bit counts as stored
    t_rel_s: np.ndarray  # (N,) s after the first time stamp (T0), on the device clock
    battery_at: np.ndarray  # (B,) index of the sample before each battery chunk
    g: np.ndarray  # (N, 3) the published conversion, in g


def acc_chunk(xyz: np.ndarray, first: np.ndarray) -> np.ndarray:
    """(N, 3) signed counts -> (N, 6) type-0 chunks."""
    v = np.asarray(xyz, dtype=np.int64) & 0xFFF
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    return np.column_stack([first, x >> 8, x & 0xFF, y >> 4, ((y & 0xF) << 4) | (z >> 8), z & 0xFF]).astype(np.uint8)


def build_genea(
    path: Path,
    seconds: int = 20,
    rate: int = 80,
    lead: int = 48,
    tail: int = 13,
    seed: int = 0,
    header_rate: str | None = "80Hz",
    drop: dict[int, int] | None = None,
    stamp_edits: dict[int, int] | None = None,
) -> Built:
    """A Genea file: ``lead`` samples, then ``seconds`` stamps each followed by ``rate`` samples (fewer where
    ``drop`` = {second: samples lost}), then at least ``tail`` samples after one last stamp (as many as fill the
    last page); a battery chunk every 210 chunks.
    ``stamp_edits`` = {second: value} writes a wrong stamp (its samples keep their true times)."""
    rng = np.random.default_rng(seed)
    drop = drop or {}
    stamp_edits = stamp_edits or {}
    rows: list[np.ndarray] = []  # chunks in order
    counts, times = [], []

    def samples(n: int, t_first: float) -> None:  # t_first: s after T0
        c = np.clip(np.round(rng.normal([0, 0, -350], 300, (n, 3))), -2048, 2047).astype(np.int64)
        counts.append(c)
        times.append(t_first + np.arange(n) / rate)
        rows.append(acc_chunk(c, rng.integers(0, 256, n)))

    def stamp(value: int) -> None:
        b = int(value).to_bytes(4, "big")
        rows.append(np.array([[rng.integers(0, 256), 0x20, *b]], dtype=np.uint8))

    base = lead + seconds + 1 + sum(rate - drop.get(s, 0) for s in range(seconds))
    while (base + tail + (base + tail - 1) // 210) % 341:  # whole pages: the tail takes what the last page holds
        tail += 1
    samples(lead, -lead / rate)
    for s in range(seconds + 1):
        stamp(stamp_edits.get(s, T0 + s))
        n = tail if s == seconds else rate - drop.get(s, 0)
        samples(n, float(s))
    chunks = np.concatenate(rows)
    # a battery chunk after every 210th chunk (the real file has one per page)
    out, battery_at, n_acc = [], [], 0
    is_acc = (chunks[:, 1] >> 4) == 0
    for k in range(len(chunks)):
        if k and k % 210 == 0:
            out.append(np.array([[rng.integers(0, 256), 0x40, BATTERY_RAW, 0x14, 0xFF, 0xCE]], dtype=np.uint8))
            battery_at.append(max(n_acc - 1, 0))
        out.append(chunks[k : k + 1])
        n_acc += int(is_acc[k])
    allc = np.concatenate(out)
    assert len(allc) % 341 == 0
    pages = allc.reshape(-1, 341 * 6)
    pages = np.concatenate([pages, np.zeros((len(pages), 2), np.uint8)], axis=1)
    header = ["GENEA/1.00", "Serial-Number:01275", "Firmware-Version:c7931 /trunk 601", "Body-Location:RW"]
    header += [
        "Trial-Start:2010-03-30 12:08:36",
        "Accel-Offsets:" + " ".join(map(str, OFFSETS)),
        "Accel-Gains:" + " ".join(map(str, GAINS)),
        "Battery-Voltage:4.0",
    ]
    if header_rate is not None:
        header.append(f"Sample-Rate:{header_rate}")
    header.append("Upload:Finished  ")
    path.write_bytes(("\r\n".join(header) + "\r\n\r\n").encode("latin-1") + pages.tobytes())
    c = np.concatenate(counts)
    g = (c * np.array([-1, 1, -1]) + OFFSETS) * np.array(GAINS) / (8192 * 340)
    return Built(path, c, np.concatenate(times), np.array(battery_at), g)
