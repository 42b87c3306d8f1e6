"""Parameter objects: frozen dataclasses whose field names carry their units, checked when they are made.

    from imulog.process.orientation import OrientationParams
    OrientationParams(beta=-1)       # ParamError: OrientationParams.beta: must be > 0 (rad/s), got -1
    p = params_from_dict(OrientationParams, {"backend": "madgwick", "static": {"threshold_rad_s": 0.2}})
    params_to_dict(p)                # the plain dict a step records in its run (imulog.run.<n> "params")

A class opts in with ``__post_init__`` calling :func:`check_params` (the types of its annotations, and the
bounds and choices it names); the unit in a message comes from the field's name (``_rad_s`` -> rad/s,
``_hz`` -> Hz, ``_s`` -> s ...) or from ``units``. :func:`set_field` is the one way a dotted option
(``static.threshold_rad_s``) is set from text or JSON: ``imulog batch --set`` and :func:`params_from_dict` use it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
import types
import typing
from collections.abc import Collection, Mapping
from typing import Any, TypeVar

T = TypeVar("T")

#: unit suffixes of field names, longest first where one ends another (``_rad_s`` before ``_s``)
UNIT_SUFFIXES = (
    ("_rad_s", "rad/s"),
    ("_deg_s", "deg/s"),
    ("_m2ps4", "m^2/s^4"),
    ("_m2ps2", "m^2/s^2"),
    ("_mps2", "m/s^2"),
    ("_mps", "m/s"),
    ("_m_s2", "m/s^2"),
    ("_hours", "h"),
    ("_hz", "Hz"),
    ("_ppm", "ppm"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_cm", "cm"),
    ("_mm", "mm"),
    ("_mg", "mg"),
    ("_ms", "ms"),
    ("_ns", "ns"),
    ("_g", "g"),
    ("_m", "m"),
    ("_s", "s"),
)


class ParamError(ValueError):
    """A parameter object's field has a value it cannot take; ``str()`` names the class, the field and the unit."""

    def __init__(self, owner: str, name: str, problem: str, value: Any, unit: str = "") -> None:
        self.owner, self.name, self.problem, self.value, self.unit = owner, name, problem, value, unit
        super().__init__(self.line(f"{owner}.{name}"))

    def line(self, where: str) -> str:
        """The error's line with ``where`` in place of ``Class.field`` (the command line puts the option there)."""
        unit = f" ({self.unit})" if self.unit else ""
        return f"{where}: {self.problem}{unit}, got {self.value!r}"


def unit_of(name: str, units: Mapping[str, str] | None = None) -> str:
    """The unit of field ``name``: ``units[name]`` when given, else from its suffix (``beta`` -> ``""``)."""
    if units and name in units:
        return units[name]
    return next((unit for suffix, unit in UNIT_SUFFIXES if name.endswith(suffix)), "")


def _accepts(value: Any, hint: Any) -> bool:
    """Whether ``value`` fits the annotation ``hint`` (numbers loosely: an int is a float, a bool is neither)."""
    origin = typing.get_origin(hint)
    if hint is Any or isinstance(hint, TypeVar):
        return True
    if origin in (typing.Union, types.UnionType):
        return any(_accepts(value, h) for h in typing.get_args(hint))
    if origin is typing.Literal:
        return value in typing.get_args(hint)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool) or type(value).__name__ == "bool_"
    if hint is float:
        return isinstance(value, numbers.Real) and not isinstance(value, bool)
    if hint is int:
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)
    if origin is not None:
        return isinstance(value, origin)
    return isinstance(value, hint) if isinstance(hint, type) else True


def check_params(
    obj: Any,
    *,
    positive: Collection[str] = (),
    non_negative: Collection[str] = (),
    choices: Mapping[str, Collection[Any]] | None = None,
    units: Mapping[str, str] | None = None,
) -> None:
    """Raise :class:`ParamError` unless every field of dataclass ``obj`` has its annotation's type, the fields in
    ``positive`` are finite and > 0, those in ``non_negative`` finite and >= 0 (a tuple's items each), and those
    in ``choices`` one of their choices (a field that is None, where its annotation allows it, has no bounds)."""
    owner = type(obj).__name__
    hints = typing.get_type_hints(type(obj))
    for f in dataclasses.fields(obj):
        value, unit = getattr(obj, f.name), unit_of(f.name, units)
        hint = hints.get(f.name, Any)
        if not _accepts(value, hint):
            kind = getattr(hint, "__name__", None) or str(hint).replace("typing.", "")
            raise ParamError(owner, f.name, f"must be {kind}", value, unit)
        if choices and f.name in choices and value not in choices[f.name]:
            raise ParamError(owner, f.name, f"must be one of {', '.join(map(str, choices[f.name]))}", value)
        for names, low, word in ((positive, False, "> 0"), (non_negative, True, ">= 0")):
            if f.name in names:
                items = value if isinstance(value, tuple) else () if value is None else (value,)
                if not all(
                    isinstance(x, numbers.Real) and math.isfinite(x) and (x >= 0 if low else x > 0) for x in items
                ):
                    raise ParamError(owner, f.name, f"must be finite and {word}", value, unit)


def coerce(value: Any, default: Any, where: str, annotation: str = "") -> Any:
    """Convert a command-line string to the type of ``default`` (other values pass through; a JSON list becomes a
    tuple where the default is one).

    When the field's ``annotation`` admits ``str`` (e.g. ``float | str`` for a threshold that may be
    ``"otsu"``), a string that does not convert is kept as it is.
    """
    if not isinstance(value, str) or isinstance(default, str):
        if isinstance(default, tuple) and isinstance(value, list):
            return tuple(value)
        return value
    text = value.strip()
    if isinstance(default, tuple):  # each item the type of the default's items (epochs_s=10,60: floats)
        items = [x.strip() for x in text.split(",") if x.strip()]
        if default and not isinstance(default[0], str):
            return tuple(coerce(x, default[0], where) for x in items)
        return tuple(items)
    try:
        if isinstance(default, bool):
            if text.lower() in ("1", "true", "yes", "on"):
                return True
            if text.lower() in ("0", "false", "no", "off"):
                return False
            raise ValueError(f"expected true/false, got {value!r}")
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)

        if default is None:
            value = json.loads(text)
            return tuple(value) if isinstance(value, list) and "tuple" in annotation else value
    except ValueError as exc:
        if "str" in str(annotation):
            return text
        raise ValueError(f"{where}: {exc}") from None
    # a union field (e.g. threshold: float | "otsu"): a number if it parses as one, else the string
    try:
        return float(text)
    except ValueError:
        return text


def set_field(obj: T, dotted: str, value: Any, where: str = "") -> T:
    """A copy of dataclass ``obj`` with field ``a.b.c`` replaced by ``value`` (coerced to the field's type; a dict
    for a nested parameter object sets its fields). An unknown name raises ValueError listing the fields."""
    head, _, rest = dotted.partition(".")
    fields = dataclasses.fields(obj)  # type: ignore[arg-type]
    names = {f.name for f in fields}
    if head not in names:
        raise ValueError(
            f"{where or type(obj).__name__}: unknown option {dotted!r} (fields: {', '.join(sorted(names))})"
        )
    current = getattr(obj, head)
    if rest:
        if not dataclasses.is_dataclass(current):
            raise ValueError(f"{where}: {head!r} has no sub-fields")
        return dataclasses.replace(obj, **{head: set_field(current, rest, value, where)})  # type: ignore[type-var]
    if dataclasses.is_dataclass(current) and isinstance(value, dict):
        sub = current
        for k, v in value.items():
            sub = set_field(sub, k, v, where)
        return dataclasses.replace(obj, **{head: sub})  # type: ignore[type-var]
    annotation = next(f.type for f in fields if f.name == head)
    return dataclasses.replace(obj, **{head: coerce(value, current, f"{where} {dotted}", str(annotation))})  # type: ignore[type-var]


def params_from_dict(cls: type[T], data: Mapping[str, Any], *, base: T | None = None) -> T:
    """The parameter object ``cls`` (from its defaults, or ``base``) with the fields of ``data`` set, nested
    objects from nested dicts: the inverse of :func:`params_to_dict`. An unknown key raises ValueError."""
    obj = cls() if base is None else base
    for key, value in data.items():
        obj = set_field(obj, str(key), value, cls.__name__)
    return obj


def params_to_dict(obj: Any) -> dict[str, Any]:
    """The plain, JSON-able dict of a parameter object (nested objects as dicts, tuples as lists)."""
    return json.loads(json.dumps(dataclasses.asdict(obj)))
