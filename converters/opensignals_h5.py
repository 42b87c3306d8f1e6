"""OpenSignals (PLUX) ``.h5`` files, as biosignalsnotebooks reads them (needs ``h5py``: ``imulog[hdf5]``).

Layout: one root group per device, named by its MAC address (``00:07:80:3B:46:61``), with attributes as in the
text header (``sampling rate``, ``nsamples``, ``resolution``, ``device``, ``date``, ``time``, ...) and a ``raw``
group holding ``nSeq`` and one dataset per analog channel ``channel_1``, ``channel_2``, ... (attribute ``sensor``).
The channels become the same streams as the text file's (:mod:`imulog.converters.opensignals`): counts in
``/signals/opensignals_<device>``, BITalino EMG/ECG/EDA in physical units in ``/analog/opensignals_<device>``.

Memory: h5py reads the datasets whole in a guarded child process capped at ``READER_MEMORY_BYTES`` (1 GiB), which
bounds memory.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.bounds import read_h5
from imulog.converters.errors import ConversionError
from imulog.converters.opensignals import device_streams

from imulog.model import Recording

_MAC = re.compile(r"^[0-9A-Fa-f]{2}(:[0-9A-Fa-f]{2}){5}$")
MAX_SAMPLES = 1 << 31
READER_TIMEOUT_S = 60.0  # h5py runs in a guarded child (a hang, crash or runaway allocation: one line)
READER_MEMORY_BYTES = 1 << 30


def _text(value: object) -> object:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return [_text(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return value.item()
    return value


class _Refused(Exception):
    """A layout problem found in the guarded child: its message becomes the ConversionError."""


def _read_devices(path: str) -> list[tuple[str, dict, list[str], list[np.ndarray], list[str]]]:
    """Every device group as plain data (runs in the guarded child: h5py's C library on a hostile file)."""
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise _Refused(f"not a readable HDF5 file: {e}") from None
    out = []
    with f:
        macs = [k for k in f if isinstance(f[k], h5py.Group) and "raw" in f[k]]
        if not macs:
            raise _Refused("no OpenSignals device group (<MAC>/raw) in the file")
        for mac in macs:
            group, raw = f[mac], f[mac]["raw"]
            attrs = {k: _text(v) for k, v in group.attrs.items()}
            names = sorted((k for k in raw if re.fullmatch(r"channel_\d+", k)), key=lambda k: int(k[8:]))
            if not names:
                raise _Refused(f"device {mac}: no raw/channel_N datasets")
            cols, blocks, sensors = [], [], []
            if "nSeq" in raw:
                cols.append("nSeq")
                blocks.append(read_h5(path, raw["nSeq"], f"{mac}/raw/nSeq", dtype=np.float64).reshape(-1))
            for k in names:
                ds = raw[k]
                if ds.size > MAX_SAMPLES:
                    raise _Refused(f"device {mac}: {k} declares {ds.size} samples: too many")
                cols.append(f"A{k[8:]}")
                blocks.append(read_h5(path, ds, f"{mac}/raw/{k}", dtype=np.float64).reshape(-1))
                sensors.append(str(_text(ds.attrs.get("sensor", ""))))
            out.append((mac, attrs, cols, blocks, sensors))
    return out


def read_opensignals_h5(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The file's devices read by h5py in a child process under a time and memory limit
    (:mod:`imulog.converters._guard`), then the same streams as the text reader's."""
    try:
        import h5py  # noqa: F401
    except ImportError:
        raise ConversionError(path, "OpenSignals .h5 needs h5py: pip install 'imulog[hdf5]'") from None
    from imulog.converters._guard import GuardError, guarded

    path = Path(path)
    extra = options.extra if options else {}
    try:
        devices = guarded(
            _read_devices,
            str(path),
            timeout_s=float(extra.get("reader_timeout_s", READER_TIMEOUT_S)),
            memory_bytes=int(extra.get("reader_memory_bytes", READER_MEMORY_BYTES)),
        )
    except GuardError as e:
        raise ConversionError(path, str(e) if e.exc_type == "_Refused" else f"h5py {e}") from None
    rec = Recording(sources=[str(path)])
    for mac, attrs, cols, blocks, sensors in devices:
        names = cols[1:] if cols and cols[0] == "nSeq" else cols
        n = min(len(b) for b in blocks)
        if any(len(b) != n for b in blocks):
            raise ConversionError(path, f"device {mac}: channels of different lengths ({[len(b) for b in blocks]})")
        res = attrs.get("resolution") or []
        res = res if isinstance(res, list) else [res]
        analog_bits = [int(r) for r in res[-len(names) :]] if len(res) >= len(names) else [0] * len(names)
        bits = ([4] if "nSeq" in cols else []) + analog_bits
        header = dict(attrs, column=cols, sensor=sensors, resolution=bits, label=cols[-len(names) :])
        rate = attrs.get("sampling rate", 0)
        rate = float(rate) if isinstance(rate, int | float) and not isinstance(rate, bool) else 0.0
        block = np.column_stack(blocks)
        device_streams(rec, path, mac, header, cols, bits, rate, block, first_line=None, fmt="opensignals-h5")
    return rec


class OpenSignalsH5Converter(Converter):
    name = "opensignals-h5"
    description = "OpenSignals/BITalino .h5 (<MAC>/raw/channel_N; needs h5py): as the text file"
    extensions = (".h5",)
    example = "imulog convert opensignals_000780.h5 -o bitalino.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        if not head.startswith(b"\x89HDF\r\n\x1a\n") or Path(path).suffix.lower() not in (".h5", ".hdf5"):
            return 0.0
        try:
            import h5py

            with h5py.File(path, "r") as f:
                keys = list(f.keys())
                ok = bool(keys) and all(_MAC.match(k) and "raw" in f[k] for k in keys)
        except Exception:  # noqa: BLE001 - sniffing never fails
            return 0.0
        return 0.9 if ok else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_opensignals_h5(Path(path), options)


CONVERTER = OpenSignalsH5Converter()
