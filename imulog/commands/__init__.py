"""Click commands, one module per area; registered lazily in :mod:`imulog.cli`."""
