"""BROAD benchmark HDF5 trials (github dlaidig/broad; optional extra, needs h5py).

Datasets: ``imu_acc`` m/s^2, ``imu_gyr`` rad/s, ``imu_mag`` uT, ``opt_pos`` m (NaN rows where tracking was lost),
``opt_quat`` w,x,y,z (optical body orientation w.r.t. an ENU frame), ``movement`` boolean; attribute
``sampling_rate`` Hz (285.714). IMU and optical data are already synchronised and share one clock, sample ``i``
at ``round(i / rate * 1e9)`` ns.

Output: IMU ``/imu/imu``; optical pose ``PoseStream`` ``/poses/optical`` (NaN where lost; its device record
``imulog.device.optical`` says ``imu_frame_aligned``: the optical body frame is the IMU's); ``Intervals``
``/events/movement`` (label ``movement``: the samples to evaluate).

Memory: in pieces (:func:`iter_broad`, about 16 MiB of samples each; the whole file is the one-piece case). h5py
runs in guarded child processes capped at ``READER_MEMORY_BYTES`` (1 GiB) and ``READER_TIMEOUT_S``
(:mod:`imulog.converters._h5pieces`): one scans the file (shapes, declared sizes, finite IMU values and the movement
runs, read in slices), one reads each piece's rows, so the parent holds one piece.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from imulog.converters import _h5pieces
from imulog.converters._binary import concat_chunks
from imulog.converters._h5pieces import (
    PIECE_BYTES,
    H5Messages,
    declared_spans,
    guarded_h5,
    row_ranges,
    scan_slices,
    true_runs,
)
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.bounds import check_h5_size, read_h5
from imulog.converters.errors import ConversionError

from imulog.model import PIECES_RECORD, ImuStream, Intervals, PoseStream, Recording
from imulog.numeric import finite_rows

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
REQUIRED = ("imu_acc", "imu_gyr")
READER_TIMEOUT_S = 60.0  # h5py runs in a guarded child
READER_MEMORY_BYTES = 1 << 30


#: the float data sets of a trial, with their width (optical quaternion: 4)
DATASETS = {"imu_acc": 3, "imu_gyr": 3, "imu_mag": 3, "opt_pos": 3, "opt_quat": 4}
IMU_DATASETS = ("imu_acc", "imu_gyr", "imu_mag")


@dataclass
class BroadLayout:
    """What the scan of a BROAD file found: rate (Hz), samples, float data sets present, the movement runs
    (first, last sample) when the mask covers every sample, and the info text."""

    rate: float
    n: int
    keys: list[str]
    movement: tuple[np.ndarray, np.ndarray] | None
    info: str


def _scan(f, path: Path) -> BroadLayout:
    """The layout of an open BROAD file, checked as the whole file's reading checks it: data sets present, sizes
    against storage, shapes, finite IMU values (read in slices), the movement mask's runs."""
    missing = [k for k in REQUIRED if k not in f]
    if missing:
        raise ConversionError(path, f"not a BROAD trial: missing dataset(s) {', '.join(missing)}")
    rate = f.attrs.get("sampling_rate")
    try:
        rate = float(np.asarray(rate).item())
    except (TypeError, ValueError):
        raise ConversionError(path, "attribute 'sampling_rate' missing or not a number") from None
    if not (rate > 0 and np.isfinite(rate)):
        raise ConversionError(path, f"sampling_rate {rate!r} must be positive")
    keys = [k for k in DATASETS if k in f]
    for k in keys:
        check_h5_size(path, f[k], k)
    if "movement" in f:
        check_h5_size(path, f["movement"], "movement")
    n = int(f["imu_acc"].shape[0]) if f["imu_acc"].shape else 1
    for key in keys:
        shape = tuple(int(x) for x in f[key].shape)
        if shape != (n, DATASETS[key]):
            raise ConversionError(path, f"dataset {key} has shape {shape}, expected ({n}, {DATASETS[key]})", column=key)
    for key in IMU_DATASETS:  # the first non-finite row of each IMU data set, in the order the whole file checks
        if key not in keys:
            continue
        for rows in scan_slices(n):
            ok = finite_rows(np.asarray(f[key][rows], dtype=np.float64))
            if not ok.all():
                row = rows.start + int(np.argmin(ok))
                raise ConversionError(path, f"non-finite IMU value at sample {row}", column=key)
    movement = None
    if "movement" in f and f["movement"].shape and int(f["movement"].shape[0]) == n and f["movement"].size == n:
        ds = f["movement"]
        first, last = true_runs(np.asarray(ds[rows], dtype=bool) for rows in scan_slices(n))
        movement = (first, last) if len(first) else None
    info = f.attrs.get("info", "")
    info = info.decode(errors="replace") if isinstance(info, bytes) else str(info)
    return BroadLayout(rate, n, keys, movement, info)


def _rows(f, path: Path, keys: list[str], a: int, b: int) -> dict[str, np.ndarray]:
    """Rows ``[a, b)`` of the float data sets ``keys`` of an open BROAD file."""
    return {k: read_h5(path, f[k], k, dtype=np.float64, rows=slice(a, b)) for k in keys}


#: how h5py's failures on a BROAD file are worded
WORDS = H5Messages(
    opened="corrupt HDF5: {e}",
    damaged="damaged HDF5 file ({e})",
    open_errors=(Exception,),
    errors=(OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError),
)


def _guarded(path: Path, fn, *args):
    # h5py in a guarded child process (time and memory limit): a hostile file that hangs or crashes the HDF5
    # library ends in one line
    return guarded_h5(path, fn, *args, words=WORDS, timeout_s=READER_TIMEOUT_S, memory_bytes=READER_MEMORY_BYTES)


def iter_broad(path: Path, name: str = "imu", piece_bytes: int | None = PIECE_BYTES) -> Iterator[Recording]:
    """A BROAD trial in pieces of about ``piece_bytes`` of samples (None: one piece, the whole file): the scan
    (:func:`_scan`) in one guarded child, each piece's rows in another."""
    path = Path(path)
    try:
        import h5py  # noqa: F401
    except ImportError:  # pragma: no cover - optional extra
        raise ConversionError(path, "reading BROAD HDF5 needs h5py: pip install 'imulog[hdf5]'") from None
    with open(path, "rb") as f:
        if f.read(8) != HDF5_MAGIC:
            raise ConversionError(path, "not an HDF5 file")
    layout: BroadLayout = _guarded(path, _scan)
    rate, n = layout.rate, layout.n
    meta = {
        "format": "broad-hdf5",
        "model": "myon aktos-t",
        "serial": "",
        "rate_hz": rate,
        "units": {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT"},
        "source": path.name,
        "dataset": "BROAD (Laidig et al. 2021, CC-BY-4.0)",
    }
    records = {f"imulog.device.{name}": meta}
    if "opt_pos" in layout.keys:
        records["imulog.device.optical"] = {
            "format": "broad-hdf5",
            "model": "OptiTrack (8 Flex13)",
            "rate_hz": rate,
            "units": {"position": "m", "orientation": "w,x,y,z"},
            "frame": "ENU",
            # the files say so ("synchronized and aligned optical reference data"): the optical body frame is the
            # IMU's, so an evaluation compares the orientations as they are (imulog.steps.evaluate_orientation)
            "imu_frame_aligned": True,
            "source": path.name,
        }
    records["imulog.trial"] = {
        "trial": path.stem,
        "dataset": "BROAD",
        "info": layout.info.split("\n\n")[1] if "\n\n" in layout.info else layout.info,
    }
    row_bytes = 8 * sum(DATASETS[k] for k in layout.keys)
    for a, b in row_ranges(n, row_bytes, piece_bytes):
        arrays = _guarded(path, _rows, layout.keys, a, b)
        t_ns = np.round(np.arange(a, b) * (1e9 / rate)).astype(np.int64)
        rec = Recording(sources=[str(path)], metadata={k: dict(v) for k, v in records.items()})
        rec.imus.append(
            ImuStream(
                name=name,
                t_ns=t_ns,
                acc=arrays["imu_acc"],
                gyr=arrays["imu_gyr"],
                mag=arrays.get("imu_mag"),
                meta=dict(meta),
            )
        )
        if "opt_pos" in arrays:
            rec.poses.append(
                PoseStream(
                    topic="/poses/optical",
                    t_ns=t_ns,
                    position=arrays["opt_pos"],
                    orientation=arrays.get("opt_quat"),
                    frame_id="enu",
                )
            )
        if layout.movement is not None and a == 0:  # the runs of the whole mask (the scan's), with the first piece
            first, last = layout.movement
            rec.events.append(
                Intervals(
                    topic="/events/movement",
                    start_ns=np.round(first * (1e9 / rate)).astype(np.int64),
                    end_ns=np.round(last * (1e9 / rate)).astype(np.int64),
                    labels=["movement"] * len(first),
                )
            )
        if a == 0:  # every stream's span, known from the scan (the time axis and the recording's length)
            last = int(np.round((n - 1) * (1e9 / rate)))
            rec.metadata[PIECES_RECORD] = declared_spans(rec, lambda topic, last=last: last)
        yield rec


def read_broad(path: Path, name: str = "imu") -> Recording:
    """A whole BROAD trial: the pieces of :func:`iter_broad` joined (each piece's rows read in a guarded child of
    its own, so a long trial is not refused by the child's memory cap)."""
    return concat_chunks(iter_broad(path, name, piece_bytes=_h5pieces.PIECE_BYTES))


class BroadConverter(Converter):
    name = "broad-hdf5"
    description = "BROAD benchmark trial (HDF5: IMU acc/gyr/mag + optical position and orientation) via h5py"
    extensions = (".hdf5", ".h5")
    example = "imulog convert 02_undisturbed_slow_rotation_B.hdf5 -o trial.mcap"
    fixed_pieces = True  # row ranges of one size (the last shorter): freed temporaries are reused

    def sniff(self, path: Path, head: bytes) -> float:
        if not head.startswith(HDF5_MAGIC):
            return 0.0
        try:
            import h5py

            with h5py.File(path, "r") as f:
                return 0.95 if all(k in f for k in REQUIRED) else 0.0
        except Exception:  # noqa: BLE001 - an HDF5 file h5py cannot open (e.g. cut off): convert reports it
            return 0.3 if path.suffix.lower() in self.extensions else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_broad(Path(path))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        return iter_broad(Path(path), piece_bytes=_h5pieces.PIECE_BYTES)


CONVERTER = BroadConverter()
