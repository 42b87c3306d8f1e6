"""BROAD benchmark HDF5 trials (github dlaidig/broad; optional extra, needs h5py).

Datasets: ``imu_acc`` m/s^2, ``imu_gyr`` rad/s, ``imu_mag`` uT, ``opt_pos`` m (NaN rows where tracking was lost),
``opt_quat`` w,x,y,z (optical body orientation w.r.t. an ENU frame), ``movement`` boolean; attribute
``sampling_rate`` Hz (285.714). IMU and optical data are already synchronised and share one clock, sample ``i``
at ``round(i / rate * 1e9)`` ns.

Output: IMU ``/imu/imu``; optical pose ``PoseStream`` ``/poses/optical`` (NaN where lost); ``Intervals``
``/events/movement`` (label ``movement``: the samples to evaluate).

Memory: h5py reads a trial's datasets whole in a guarded child process capped at ``READER_MEMORY_BYTES`` (1 GiB);
BROAD trials are minutes long.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.bounds import read_h5
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Intervals, PoseStream, Recording

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
REQUIRED = ("imu_acc", "imu_gyr")
READER_TIMEOUT_S = 60.0  # h5py runs in a guarded child
READER_MEMORY_BYTES = 1 << 30


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first, last) sample index of every run of True."""
    m = np.concatenate([[False], mask.astype(bool), [False]])
    d = np.diff(m.astype(np.int8))
    return np.nonzero(d == 1)[0], np.nonzero(d == -1)[0] - 1


def _read_datasets(f, path: Path) -> tuple[float, dict[str, np.ndarray], np.ndarray | None, str]:
    """Rate (Hz), float arrays, movement mask and info text of an open BROAD file."""
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
    arrays = {
        k: read_h5(path, f[k], k, dtype=np.float64)
        for k in ("imu_acc", "imu_gyr", "imu_mag", "opt_pos", "opt_quat")
        if k in f
    }
    movement = read_h5(path, f["movement"], "movement", dtype=bool) if "movement" in f else None
    info = f.attrs.get("info", "")
    info = info.decode(errors="replace") if isinstance(info, bytes) else str(info)
    return rate, arrays, movement, info


def _read_file(path: Path) -> tuple[float, dict[str, np.ndarray], np.ndarray | None, str]:
    import h5py

    try:
        f = h5py.File(path, "r")
    except Exception as e:  # noqa: BLE001 - h5py raises OSError variants for corrupt files
        raise ConversionError(path, f"corrupt HDF5: {e}") from None
    try:
        with f:
            return _read_datasets(f, path)
    except ConversionError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError) as e:
        # h5py reports damaged b-trees, heaps and chunks as any of these, often only when data is read
        raise ConversionError(path, f"damaged HDF5 file ({e})") from None


def read_broad(path: Path, name: str = "imu") -> Recording:
    path = Path(path)
    try:
        import h5py  # noqa: F401
    except ImportError:  # pragma: no cover - optional extra
        raise ConversionError(path, "reading BROAD HDF5 needs h5py: pip install 'imulog[hdf5]'") from None
    with open(path, "rb") as f:
        if f.read(8) != HDF5_MAGIC:
            raise ConversionError(path, "not an HDF5 file")
    from imulog.converters._guard import guarded_reader

    # h5py in a guarded child process (time and memory limit): a hostile file that hangs or crashes the HDF5
    # library ends in one line
    rate, arrays, movement, info = guarded_reader(
        path, "h5py", _read_file, path, timeout_s=READER_TIMEOUT_S, memory_bytes=READER_MEMORY_BYTES
    )
    n = len(arrays["imu_acc"])
    for key, a in arrays.items():
        width = 4 if key == "opt_quat" else 3
        if a.shape != (n, width):
            raise ConversionError(path, f"dataset {key} has shape {a.shape}, expected ({n}, {width})", column=key)
    for key in ("imu_acc", "imu_gyr", "imu_mag"):
        if key in arrays and not np.isfinite(arrays[key]).all():
            row = int(np.nonzero(~np.isfinite(arrays[key]).all(axis=1))[0][0])
            raise ConversionError(path, f"non-finite IMU value at sample {row}", column=key)
    t_ns = np.round(np.arange(n) * (1e9 / rate)).astype(np.int64)
    trial = path.stem
    meta = {
        "format": "broad-hdf5",
        "model": "myon aktos-t",
        "serial": "",
        "rate_hz": rate,
        "units": {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT"},
        "source": path.name,
        "dataset": "BROAD (Laidig et al. 2021, CC-BY-4.0)",
    }
    rec = Recording(sources=[str(path)])
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
    rec.metadata[f"imulog.device.{name}"] = meta
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
        rec.metadata["imulog.device.optical"] = {
            "format": "broad-hdf5",
            "model": "OptiTrack (8 Flex13)",
            "rate_hz": rate,
            "units": {"position": "m", "orientation": "w,x,y,z"},
            "frame": "ENU",
            "source": path.name,
        }
    if movement is not None and len(movement) == n and movement.any():
        first, last = _runs(movement)
        rec.events.append(
            Intervals(
                topic="/events/movement", start_ns=t_ns[first], end_ns=t_ns[last], labels=["movement"] * len(first)
            )
        )
    rec.metadata["imulog.trial"] = {
        "trial": trial,
        "dataset": "BROAD",
        "info": info.split("\n\n")[1] if "\n\n" in info else info,
    }
    return rec


class BroadConverter(Converter):
    name = "broad-hdf5"
    description = "BROAD benchmark trial (HDF5: IMU acc/gyr/mag + optical position and orientation) via h5py"
    extensions = (".hdf5", ".h5")
    example = "imulog convert 02_undisturbed_slow_rotation_B.hdf5 -o trial.mcap"

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


CONVERTER = BroadConverter()
