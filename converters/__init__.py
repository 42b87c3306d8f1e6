"""Source-format converters: device exports -> :class:`imulog.model.Recording` (no MCAP knowledge)."""
