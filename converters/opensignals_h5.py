"""OpenSignals (PLUX) ``.h5`` files, as biosignalsnotebooks reads them (needs ``h5py``: ``imulog[hdf5]``).

Layout: one root group per device, named by its MAC address (``00:07:80:3B:46:61``), with attributes as in the
text header (``sampling rate``, ``nsamples``, ``resolution``, ``device``, ``date``, ``time``, ...) and a ``raw``
group holding ``nSeq`` and one dataset per analog channel ``channel_1``, ``channel_2``, ... (attribute ``sensor``).
The channels become the same streams as the text file's (:mod:`imulog.converters.opensignals`): counts in
``/signals/opensignals_<device>``, BITalino EMG/ECG/EDA in physical units in ``/analog/opensignals_<device>``.

Memory: in pieces of about 16 MiB of samples (:func:`iter_opensignals_h5`; the whole file is the one-piece case).
h5py runs in guarded child processes capped at ``READER_MEMORY_BYTES`` (1 GiB) and ``READER_TIMEOUT_S``: one reads
the layout (declared sizes checked against storage), one each piece's rows (:mod:`imulog.converters._h5pieces`).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from imulog.converters import _h5pieces
from imulog.converters._binary import concat_chunks
from imulog.converters._common import sanitize_name
from imulog.converters._h5pieces import PIECE_BYTES, declared_spans, row_ranges
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.bounds import check_h5_size, read_h5
from imulog.converters.errors import ConversionError
from imulog.converters.opensignals import _SeqCarry, device_streams

from imulog.model import PIECES_RECORD, Recording

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


def _scan_devices(path: str) -> list[tuple[str, dict, list[str], list[str], list[int], list[str]]]:
    """Every device group's layout (runs in the guarded child: h5py's C library on a hostile file): (MAC,
    attributes, columns, data set paths, lengths, channel sensors), declared sizes checked against storage."""
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
            cols, where, lengths, sensors = [], [], [], []
            if "nSeq" in raw:
                cols.append("nSeq")
                where.append(f"{mac}/raw/nSeq")
            for k in names:
                if raw[k].size > MAX_SAMPLES:
                    raise _Refused(f"device {mac}: {k} declares {raw[k].size} samples: too many")
                cols.append(f"A{k[8:]}")
                where.append(f"{mac}/raw/{k}")
                sensors.append(str(_text(raw[k].attrs.get("sensor", ""))))
            for p in where:
                ds = f[p]
                check_h5_size(path, ds, p)
                if ds.ndim > 1 and int(ds.shape[0]) != int(ds.size):
                    raise _Refused(f"device {mac}: {p} has shape {tuple(ds.shape)}, not one value per row")
                lengths.append(int(ds.size))
            out.append((mac, attrs, cols, where, lengths, sensors))
    return out


def _read_rows(path: str, where: list[list[str]], a: int, stops: list[int]) -> list[list[np.ndarray]]:
    """Rows ``[a, stop)`` of every device's data sets (``where``: per device, its data set paths), float64 (runs in
    the guarded child)."""
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise _Refused(f"not a readable HDF5 file: {e}") from None
    with f:
        return [
            [read_h5(path, f[p], p, dtype=np.float64, rows=slice(a, stop)).reshape(-1) for p in paths]
            for paths, stop in zip(where, stops, strict=True)
        ]


def _guarded(fn, *args, extra: dict):
    """``fn(*args)`` in the guarded child; a layout problem keeps its message, anything else is ``h5py ...``."""
    from imulog.converters._guard import GuardError, guarded

    path = Path(args[0])
    try:
        return guarded(
            fn,
            *args,
            timeout_s=float(extra.get("reader_timeout_s", READER_TIMEOUT_S)),
            memory_bytes=int(extra.get("reader_memory_bytes", READER_MEMORY_BYTES)),
        )
    except GuardError as e:
        raise ConversionError(path, str(e) if e.exc_type == "_Refused" else f"h5py {e}") from None


def read_opensignals_h5(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file: the pieces of :func:`iter_opensignals_h5` joined (each piece's rows read in a guarded child
    of its own, so a long file is not refused by the child's memory cap)."""
    return concat_chunks(iter_opensignals_h5(path, options, piece_bytes=_h5pieces.PIECE_BYTES))


def iter_opensignals_h5(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """The file's devices in pieces of about ``piece_bytes`` of samples (None: one piece), read by h5py in child
    processes under a time and memory limit (:mod:`imulog.converters._guard`): the layout in one, each piece's rows
    in another; the same streams as the text reader's (the warnings about the whole recording with the last piece)."""
    try:
        import h5py  # noqa: F401
    except ImportError:
        raise ConversionError(path, "OpenSignals .h5 needs h5py: pip install 'imulog[hdf5]'") from None
    path = Path(path)
    extra = options.extra if options else {}
    devices = []
    for mac, attrs, cols, where, lengths, sensors in _guarded(_scan_devices, str(path), extra=extra):
        names = cols[1:] if cols and cols[0] == "nSeq" else cols
        n = min(lengths)
        if any(m != n for m in lengths):
            raise ConversionError(path, f"device {mac}: channels of different lengths ({lengths})")
        res = attrs.get("resolution") or []
        res = res if isinstance(res, list) else [res]
        analog_bits = [int(r) for r in res[-len(names) :]] if len(res) >= len(names) else [0] * len(names)
        bits = ([4] if "nSeq" in cols else []) + analog_bits
        header = dict(attrs, column=cols, sensor=sensors, resolution=bits, label=cols[-len(names) :])
        rate = attrs.get("sampling rate", 0)
        rate = float(rate) if isinstance(rate, int | float) and not isinstance(rate, bool) else 0.0
        devices.append((mac, header, cols, bits, rate, where, n, _SeqCarry()))
    row_bytes = 8 * sum(len(d[2]) for d in devices)
    total = max(d[6] for d in devices)
    for a, b in row_ranges(total, row_bytes, piece_bytes):
        here = [d for d in devices if a < d[6] or a == 0]
        blocks = _guarded(_read_rows, str(path), [d[5] for d in here], a, [min(b, d[6]) for d in here], extra=extra)
        rows = dict(zip([d[0] for d in here], blocks, strict=True))
        rec = Recording(sources=[str(path)])
        for mac, header, cols, bits, rate, _, n, seq in devices:
            if mac in rows:
                block, target = np.column_stack(rows[mac]), rec
            elif b >= total:  # a device that ended earlier: its warnings with the last piece, in the devices' order
                block, target = np.zeros((0, len(cols))), Recording()
            else:
                continue
            device_streams(
                target,
                path,
                mac,
                header,
                cols,
                bits,
                rate,
                block,
                first_line=None,
                fmt="opensignals-h5",
                first_row=min(a, n),
                seq=seq,
                last=b >= total,
            )
            if target is not rec:
                rec.warnings.extend(target.warnings)
        if a == 0:  # every stream's span, known from the layout (the time axis and the recording's length)
            last = {sanitize_name(f"opensignals_{d[0]}"): round((d[6] - 1) * (1e9 / d[4])) for d in devices}
            rec.metadata[PIECES_RECORD] = declared_spans(rec, lambda topic, last=last: last[topic.rsplit("/", 1)[1]])
        yield rec


class OpenSignalsH5Converter(Converter):
    name = "opensignals-h5"
    description = "OpenSignals/BITalino .h5 (<MAC>/raw/channel_N; needs h5py): as the text file"
    extensions = (".h5",)
    example = "imulog convert opensignals_000780.h5 -o bitalino.mcap"
    fixed_pieces = True  # row ranges of one size (the last shorter): freed temporaries are reused

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

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MiB of samples (see :func:`iter_opensignals_h5`)."""
        return iter_opensignals_h5(Path(path), options, piece_bytes=_h5pieces.PIECE_BYTES)


CONVERTER = OpenSignalsH5Converter()
