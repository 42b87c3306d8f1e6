"""APDM Opal exports (Mobility Lab / Motion Studio): two CSV layouts and the HDF5 file; one IMU stream per sensor.

CSV with labelled columns (what OpenSim's ``APDMDataReader`` reads)::

    Test Name:,Pendulum Test 01
    Sample Rate:,128,Hz
    Time,Static/Acceleration/X,...,Static/Orientation/Scalar,...,Static/Temperature/Scalar,Static/Pressure/Scalar,...
    s,m/s^2,...,rad/s,...,uT,...,(blank for the quaternion),deg C,kPa

Time in seconds from the start; units from the units row.

CSV ``Format=7`` (Mobility Lab)::

    Format=7,<case ID>,,,<Label>,...        14 columns per sensor
    Time,Accelerometer,,,Gyroscope,,,Magnetometer,,,Barometer,Orientation,,,
    ,X,Y,Z,X,Y,Z,X,Y,Z,,S,X,Y,Z

Time in microseconds since the Unix epoch (UTC) -> the trial's start time. No units row: APDM's SI units (m/s^2,
rad/s, uT, kPa). The Barometer column of these exports holds the IEEE-754 bit pattern of the double printed as an
integer (``4636858284341460992.000000`` is 101.72 kPa); it is reinterpreted.

HDF5 (``.h5``, the layouts scikit-digital-health and APDM's documentation read): format 5 ``/Sensors/<case ID>/``
``Accelerometer`` (N, 3) m/s^2, ``Gyroscope`` rad/s, ``Magnetometer`` uT, ``Temperature`` degC, ``Barometer`` kPa,
``Time`` (N,) microseconds since the Unix epoch (UTC), ``Configuration`` attributes ``Label 0``, ``Sample Rate`` and
``Timezone Offset`` (hours); ``/Processed/<case ID>/Orientation`` (N, 4) scalar first. Formats 3-4: root
attributes ``CaseIdList``/``MonitorLabelList``, ``/<case ID>/Time`` and ``/<case ID>/Calibrated/{Accelerometers,
Gyroscopes, Magnetometers, Temperature, Orientation}``, group attribute ``SampleRate``.

Streams are named from the sensor label (``Right Ankle`` -> ``/imu/right_ankle``), else ``opal_<case ID>``;
``--device-name 5718=pelvis`` renames by case ID (or by label). Orientation estimates go to
``/orientation/<name>``, other columns to ``/signals/<name>``.

Memory: in pieces, each layout (``iter_chunks``; ``convert`` is the one-piece case). The CSV layouts in about 16 MiB
of text (:mod:`imulog.converters.apdm_csv`, ``_pieces.iter_table``), the rate estimate refined to the whole file's
by the last piece; the HDF5 file in about 16 MiB of samples, read by h5py in guarded child processes capped at
``READER_MEMORY_BYTES`` (1 GiB): a scan of the whole file (every check, the rate from all times), then each piece's
rows (:mod:`imulog.converters.apdm_h5`).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

from imulog.converters import _h5pieces, _pieces
from imulog.converters._binary import concat_chunks
from imulog.converters._common import (
    head_lines,
    text_head_lines,
)
from imulog.converters.apdm_csv import (
    QUANTITY,
    QUANTITY_SI,
    Sensor,
    iter_format7,
    iter_labelled_csv,
    read_format7,
    read_labelled_csv,
)
from imulog.converters.apdm_h5 import (
    HDF5_MAGIC,
    READER_MEMORY_BYTES,
    READER_TIMEOUT_S,
    H5Sensor,
    _is_apdm_h5,
    h5_sensors,
    iter_apdm_h5,
    read_apdm_h5,
)
from imulog.converters.base import Converter, ConvertOptions

from imulog.model import Recording

__all__ = [
    "ApdmConverter",
    "CONVERTER",
    "h5_sensors",
    "H5Sensor",
    "HDF5_MAGIC",
    "QUANTITY",
    "QUANTITY_SI",
    "read_apdm_h5",
    "read_format7",
    "read_labelled_csv",
    "READER_MEMORY_BYTES",
    "READER_TIMEOUT_S",
    "Sensor",
]


class ApdmConverter(Converter):
    name = "apdm"
    description = "APDM Opal: labelled CSV (Label/Quantity/Axis + units row), Mobility Lab Format=7 CSV, HDF5 (.h5)"
    extensions = (".csv", ".h5")
    example = "imulog convert ../shared/data/devices/apdm_csv/imuData01.csv -o apdm.mcap"
    #: HDF5 row ranges of one size; CSV pieces of 16 MiB of text cut at a line, nearly one size: freed temporaries
    #: are reused (CPU of an hour in pieces about halved: docs/converters.md, benchmarks/bench_convert_pieces.py)
    fixed_pieces = True

    def sniff(self, path: Path, head: bytes) -> float:
        if head.startswith(HDF5_MAGIC):
            try:
                return 0.95 if _is_apdm_h5(path) else 0.0
            except Exception:  # noqa: BLE001 - cut-off HDF5: the HDF5 converters report it
                return 0.0
        lines = text_head_lines(head, 5)
        if not lines:
            return 0.0
        if lines[0].startswith("Format=") and len(lines) > 1 and lines[1].startswith("Time,"):
            return 0.95
        if lines[0].startswith("Test Name:") and any(re.search(r"/Acceleration/[XYZ]", x) for x in lines[1:4]):
            return 0.95
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return concat_chunks(self._pieces(Path(path), options, whole=True))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MiB (of samples in HDF5, of text in CSV); ``convert`` is the one-piece case."""
        return self._pieces(Path(path), options, whole=False)

    def _pieces(self, path: Path, options: ConvertOptions | None, *, whole: bool) -> Iterator[Recording]:
        options = options or ConvertOptions()
        names = {k.upper(): v for k, v in (options.extra.get("names") or {}).items()}
        with open(path, "rb") as fh:
            magic = fh.read(8)
        if magic == HDF5_MAGIC:
            yield from iter_apdm_h5(path, names, _h5pieces.PIECE_BYTES)  # whole: the pieces joined
            return
        lines = head_lines(path, max_lines=8)
        text_bytes = None if whole else _pieces.PIECE_BYTES
        if lines[0].startswith("Format="):
            yield from iter_format7(path, lines, names, text_bytes)
            return
        yield from iter_labelled_csv(path, lines, names, text_bytes)


CONVERTER = ApdmConverter()
