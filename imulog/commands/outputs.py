"""The one overwrite rule of every command that writes a file or folder.

An existing output is refused unless ``--overwrite`` is given, with the same one-line message everywhere:
``trial.c3d exists; add --overwrite to replace it``. Commands check before doing any work (nothing is
read or computed for an output that will be refused); the writers themselves stay atomic (temporary name,
then rename), so a replaced output is never half-written.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import click

OVERWRITE_HELP = "Replace the output if it exists (without it, an existing output is refused)."


def overwrite_option(help: str = OVERWRITE_HELP) -> Callable[[Any], Any]:
    """The ``--overwrite`` flag, the same on every writing command."""
    return click.option("--overwrite", is_flag=True, help=help)


def exists_message(path: str | os.PathLike[str]) -> str:
    """The CLI's wording for an output that exists."""
    return f"{path} exists; add --overwrite to replace it"


def occupied(path: str | os.PathLike[str]) -> bool:
    """True when ``path`` is an existing file, link, or non-empty folder (an empty folder is free to use)."""
    p = Path(path)
    if p.is_symlink() or p.is_file():
        return True
    return p.is_dir() and any(p.iterdir())


def refuse_existing(paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]], *, overwrite: bool) -> None:
    """Raise the CLI's one-line error for the first of ``paths`` that exists, unless ``overwrite``."""
    if overwrite:
        return
    items = [paths] if isinstance(paths, str | os.PathLike) else list(paths)
    for path in items:
        if occupied(path):
            raise click.ClickException(exists_message(path))
