"""Which option of a command set a parameter object's field, so a refused value names what the user typed.

A command's option is matched to a field by click's parameter name (``--beta`` is ``beta``, the field
``OrientationParams.beta``); where the two differ a command declares them with :func:`option_fields`
(``static_threshold="StaticParams.threshold_rad_s"``). ``imulog.cli`` turns a
:class:`~imulog.params.ParamError` into ``--static-threshold: must be finite and > 0 (rad/s), got -1.0`` with
:func:`option_line`; the Python API keeps naming the field (``StaticParams.threshold_rad_s: ...``).
"""

from __future__ import annotations

from collections.abc import Callable

import click

from imulog.params import ParamError


def option_fields(**fields: str) -> Callable[[click.Command], click.Command]:
    """Decorator above ``@click.command``: ``{click parameter name: "Class.field"}`` for the options whose name is
    not their field's."""

    def declare(command: click.Command) -> click.Command:
        command.option_fields = dict(fields)  # type: ignore[attr-defined]
        return command

    return declare


def option_of(error: ParamError, command: click.Command) -> str | None:
    """The option (``--static-threshold``) of ``command`` that sets the field ``error`` names, or None."""
    declared: dict[str, str] = getattr(command, "option_fields", {})
    for param in command.params:
        if not isinstance(param, click.Option) or not param.name:
            continue
        field = declared.get(param.name)
        if field == f"{error.owner}.{error.name}" or (field is None and param.name == error.name):
            return max(param.opts, key=len)
    return None


def option_line(error: ParamError, command: click.Command | None) -> str:
    """``error``'s line naming ``command``'s option for the field, else the field (``Class.field``)."""
    option = option_of(error, command) if command is not None else None
    return error.line(option) if option else str(error)
