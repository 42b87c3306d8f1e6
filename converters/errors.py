"""The one exception every converter raises for input it cannot read safely."""

from __future__ import annotations

from pathlib import Path


class ConversionError(ValueError):
    """Input that cannot be converted, with a one-line message naming file, line and/or column.

    ``str(error)`` is the full one-line message, e.g.
    ``wrist.csv: line 17, column 'Gyroscope X (deg/s)': 'abc' is not a number``.
    """

    def __init__(self, path: str | Path | None, problem: str, *, line: int | None = None, column: str | None = None):
        self.path = str(path) if path is not None else None
        self.line = line
        self.column = column
        self.problem = " ".join(str(problem).split())  # one line, always
        where = []
        if line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {column!r}")
        prefix = f"{self.path}: " if self.path else ""
        location = ", ".join(where)
        super().__init__(f"{prefix}{location + ': ' if location else ''}{self.problem}")


class UnknownFormatError(ConversionError):
    """No registered converter recognises the file (or ``--format`` names no converter)."""
