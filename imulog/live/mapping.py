"""An LSL stream's header and samples -> the channels ``imulog convert`` makes for that stream in an XDF file.

The XML header of a live stream is the one LabRecorder writes into an XDF StreamHeader chunk, so it is parsed
into pyxdf's dictionary layout and handed, with each pulled chunk of samples, to
:func:`imulog.converters.xdf.stream_to_recording`: IMU streams by their channel labels and units (``/imu/<stream>``),
MoCap streams as markers, other numeric streams as signals, string streams as events, and the same
``imulog.device.<stream>`` record. Pure functions, no LSL.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from imulog.converters._common import sanitize_name
from imulog.converters.xdf import stream_to_recording
from imulog.converters.xdf_read import xml_dict
from imulog.model import Recording


def header_info(xml: str, stream_id: int) -> dict[str, Any]:
    """The ``info`` dictionary pyxdf gives for a stream whose header is ``xml`` (``stream_id`` added as XDF does)."""
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise ValueError(f"stream header is not valid XML: {exc}") from None
    info = xml_dict(root).get(root.tag)
    if not isinstance(info, dict):
        info = {}
    info["stream_id"] = [str(stream_id)]
    return info


def stream_names(names: list[str]) -> list[str]:
    """Topic-safe names of the streams, as the XDF converter names them (stream number appended to duplicates)."""
    safe = [sanitize_name(n or "stream") for n in names]
    return [n if safe.count(n) == 1 else f"{n}_{i + 1}" for i, n in enumerate(safe)]


def chunk_to_recording(
    info: dict[str, Any], name: str, stamps_s: np.ndarray, samples: list[Any] | np.ndarray, source: str
) -> Recording:
    """One pulled chunk (time stamps in s on the recorder's clock, samples) of a stream -> its channels."""
    stream = {"info": info, "time_stamps": np.asarray(stamps_s, dtype=np.float64), "time_series": samples}
    rec = stream_to_recording(Path(source), stream, name)
    rec.sources = []
    return rec
