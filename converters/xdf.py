"""XDF recordings (Lab Streaming Layer, LabRecorder), read chunk by chunk by imulog (pyxdf is the reference).

Every stream becomes channels of its own, named from the stream's ``name`` (topic-safe; the stream id is appended
when two streams share a name):

* numeric streams -> ``/signals/<stream>`` with the declared channel labels and units (``desc/channels/channel``;
  ``ch0``.. and no unit when the header declares none). When the channel labels or types name an accelerometer /
  gyroscope / magnetometer (``AccX``, ``acc_x``, ``Gyro Z`` or type ``Accelerometer``...) with a unit imulog knows,
  those three-axis groups become ``/imu/<stream>`` in SI units and the remaining channels stay in the signal stream;
  without units they stay signals (no unit is guessed). A stream of type ``MoCap``/``Mocap`` whose channels are
  ``<marker>_X/_Y/_Z`` in m, cm or mm becomes ``/markers/<stream>`` (NaN = occluded).
* string streams (markers) -> ``/events/<stream>``: one instantaneous interval (start == end) per sample, the
  label being the string (channels joined with ``|``).
* empty streams are kept as empty channels.

Time: each stream's time stamps on the recording host's LSL clock after applying the stream's ClockOffset
measurements exactly as pyxdf's ``load_xdf(synchronize_clocks=True, handle_clock_resets=True,
dejitter_timestamps=False)`` does (:mod:`imulog.converters.xdf_clock`: host clock resets as separate clock
segments, a robust line per segment, the pylsl#67 corrupted last offset dropped); stamps are not dejittered (raw
data keeps what was recorded). ``t_ns`` = LSL seconds x 1e9. The file header's ``datetime`` (when LabRecorder
started) is the trial's ``start_time``. XDF has no checksums: the chunk structure (magic, chunk lengths, tags) and
every Samples chunk's layout (time-stamp flags, string lengths, samples filling the chunk exactly) are verified
before parsing, so truncated files and damaged chunks are reported with their chunk index; a flipped bit inside a
sample value cannot be detected by any reader.

Memory: in pieces (:func:`iter_chunks`, :mod:`imulog.converters.xdf_pieces`): a first pass keeps headers, clock
offsets, footers and counts (a few bytes per chunk), a second the synchronised first and last stamp of every
stream (declared by the first piece: a stream whose chunks come later may start earlier), then samples are decoded
chunk by chunk, about 16 MiB of values a piece; the whole file is the one-piece case.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from imulog.converters._binary import concat_chunks
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.xdf_chunks import (  # noqa: F401 (re-exported)
    CHUNK_TAGS,
    MAGIC,
    iter_chunk_headers,
    locate_damaged_samples,
    scan_chunks,
)
from imulog.converters.xdf_map import (  # noqa: F401 (re-exported)
    channel_info,
    header_start_time,
    stream_to_recording,
)

from imulog.model import Recording

#: bytes of sample values gathered before a piece is given (``iter_chunks``); None: the whole file as one piece
PIECE_BYTES = 16 << 20


def iter_chunks(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """The recording in pieces of about ``piece_bytes`` of samples, read chunk by chunk in file order (None: one
    piece). The first piece holds every stream (empty where none of its samples came yet) and declares every
    stream's span and meta (:data:`imulog.model.PIECES_RECORD`) from two passes before it: headers, clock offsets,
    footers and counts (:func:`~imulog.converters.xdf_read.scan`), then the synchronised stamps."""
    from imulog.converters.xdf_pieces import iter_pieces

    path = Path(path)
    scan_chunks(path)
    locate_damaged_samples(path)
    return iter_pieces(path, piece_bytes)


def read_xdf(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file: :func:`iter_chunks` in one piece."""
    return concat_chunks(iter_chunks(path, options, piece_bytes=None))


class XdfConverter(Converter):
    name = "xdf"
    description = (
        "XDF (Lab Streaming Layer / LabRecorder): every stream with its units, clock offsets applied (as pyxdf)"
    )
    extensions = (".xdf",)
    example = "imulog convert ../shared/data/devices/xdf/clock_resets.xdf -o lsl.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        return 0.99 if head[:4] == MAGIC else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_xdf(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        return iter_chunks(Path(path), options, piece_bytes=PIECE_BYTES)


CONVERTER = XdfConverter()
