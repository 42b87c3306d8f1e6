"""The one exception every converter raises for input it cannot read safely."""

from __future__ import annotations

import re
from pathlib import Path

EXCERPT_CHARS = 40  # a quoted cell, value or column name is cut to this many characters in error lines
MAX_PROBLEM_CHARS = 300  # and the whole problem text to this many
_REPEAT = "{%d,}" % (EXCERPT_CHARS + 1)  # noqa: UP031 - braces of a regex
# a quote opens where no letter or digit stands before it and closes where none follows: the apostrophes of
# "NilsPodLib's" and "session's" are not a quoted value between them
_QUOTED = re.compile(
    r"(?<!\w)'(?:[^'\\]|\\.)" + _REPEAT + r"'(?!\w)|" + r'(?<!\w)"(?:[^"\\]|\\.)' + _REPEAT + r'"(?!\w)'
)


def excerpt(value: object, limit: int = EXCERPT_CHARS) -> str:
    """``value`` as text of at most ``limit`` characters (``...`` and the full length when cut)."""
    text = str(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}... ({len(text)} chars)"


def _short(problem: str) -> str:
    """One line; quoted excerpts longer than EXCERPT_CHARS cut, the whole at most MAX_PROBLEM_CHARS."""
    text = " ".join(str(problem)[:20_000].split())  # bounded work on a hostile megabyte cell
    text = _QUOTED.sub(lambda q: f"{q.group(0)[: EXCERPT_CHARS - 3]}...{q.group(0)[0]} ({len(q.group(0))} chars)", text)
    if len(text) > MAX_PROBLEM_CHARS:
        text = f"{text[: MAX_PROBLEM_CHARS - 3]}..."
    return text


class ConversionError(ValueError):
    """Input that cannot be converted, with a one-line message naming file, line and/or column.

    ``str(error)`` is the full one-line message, e.g.
    ``wrist.csv: line 17, column 'Gyroscope X (deg/s)': 'abc' is not a number``.
    """

    def __init__(self, path: str | Path | None, problem: str, *, line: int | None = None, column: str | None = None):
        self.path = str(path) if path is not None else None
        self.line = line
        self.column = column
        self.problem = _short(problem)  # one line, always; a huge offending cell is quoted as an excerpt
        where = []
        if line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {excerpt(column)!r}")
        prefix = f"{self.path}: " if self.path else ""
        location = ", ".join(where)
        super().__init__(f"{prefix}{location + ': ' if location else ''}{self.problem}")


class UnknownFormatError(ConversionError):
    """No registered converter recognises the file (or ``--format`` names no converter)."""
