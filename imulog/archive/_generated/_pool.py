"""Private descriptor pool for imulog's generated protobuf modules (written by imulog.archive.generate)."""

from google.protobuf import descriptor_pool, timestamp_pb2

POOL = descriptor_pool.DescriptorPool()
POOL.AddSerializedFile(timestamp_pb2.DESCRIPTOR.serialized_pb)
