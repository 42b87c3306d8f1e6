"""Source-format converters: device exports -> :class:`imulog.model.Recording` (no MCAP knowledge).

>>> from converters import convert_file
>>> rec = convert_file("fusion_sensor_data.csv")        # doctest: +SKIP

Formats are plug-ins found through the ``imulog.converters`` entry-point group (see docs/converters.md).
"""

from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError, UnknownFormatError
from imulog.converters.registry import available, convert_file, convert_files, detect, get, group_directory

__all__ = [
    "ConversionError",
    "ConvertOptions",
    "Converter",
    "UnknownFormatError",
    "available",
    "convert_file",
    "convert_files",
    "detect",
    "get",
    "group_directory",
]
