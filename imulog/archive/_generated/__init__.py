"""Generated protobuf code: do not edit (python -m imulog.archive.generate)."""
