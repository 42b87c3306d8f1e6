"""The block schemas' message classes and names, shared by the encoder (:mod:`imulog.archive.codec`) and the
decoder (:mod:`imulog.archive.codec_decode`)."""

from __future__ import annotations

from imulog.archive._generated.foxglove import PoseInFrame_pb2
from imulog.archive._generated.imulog import (
    AnalogBlock_pb2,
    ImuBlock_pb2,
    IntervalEvent_pb2,
    MarkerBlock_pb2,
    PoseBlock_pb2,
    SignalBlock_pb2,
)

MESSAGE_CLASSES = {
    "imulog.ImuBlock": ImuBlock_pb2.ImuBlock,
    "imulog.MarkerBlock": MarkerBlock_pb2.MarkerBlock,
    "imulog.AnalogBlock": AnalogBlock_pb2.AnalogBlock,
    "imulog.SignalBlock": SignalBlock_pb2.SignalBlock,
    "imulog.IntervalEvent": IntervalEvent_pb2.IntervalEvent,
    "imulog.PoseBlock": PoseBlock_pb2.PoseBlock,
    "foxglove.PoseInFrame": PoseInFrame_pb2.PoseInFrame,  # poses of files written before PoseBlock
}
KIND_SCHEMA = {
    "imu": "imulog.ImuBlock",
    "markers": "imulog.MarkerBlock",
    "analog": "imulog.AnalogBlock",
    "signal": "imulog.SignalBlock",
    "intervals": "imulog.IntervalEvent",
    "pose": "imulog.PoseBlock",
}
SCHEMA_KIND = {**{v: k for k, v in KIND_SCHEMA.items()}, "foxglove.PoseInFrame": "pose"}
BLOCK_SCHEMAS = (
    "imulog.ImuBlock",
    "imulog.MarkerBlock",
    "imulog.AnalogBlock",
    "imulog.SignalBlock",
    "imulog.PoseBlock",
)


class DecodeError(ValueError):
    """A message could not be decoded into the stream type its schema promises."""
