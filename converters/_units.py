"""Units of the quantities converters read: factors to SI, spellings, overrides from the command line."""

from __future__ import annotations

import math
import re
from typing import Any

# --------------------------------------------------------------------------------------------- units
G0 = 9.80665  # standard gravity, m/s^2


# SI product/exponent spellings (EDF+ and ISO 80000): "m.s-2", "m*s^-2", "m s-2", "m/s/s"; "deg.s-1", "rad*s^-1"
_PER_S2 = re.compile(r"^(.*?)(?:[.*·]?s\^?-2|/s/s)$")

# quantity -> normalised unit string -> factor to the model's SI unit (acc m/s^2, gyr rad/s, mag uT, degC, s)
UNIT_FACTORS: dict[str, dict[str, float]] = {
    "acc": {"g": G0, "mg": G0 / 1000.0, "m/s^2": 1.0, "m/s2": 1.0, "ms^-2": 1.0, "mps2": 1.0},
    "gyr": {
        "dps": math.pi / 180.0,
        "deg/s": math.pi / 180.0,
        "degrees/s": math.pi / 180.0,
        "degree/s": math.pi / 180.0,
        "°/s": math.pi / 180.0,
        "mdps": math.pi / 180.0 / 1000.0,
        "rad/s": 1.0,
        "rads^-1": 1.0,
    },
    "mag": {
        "ut": 1.0,
        "µt": 1.0,
        "μt": 1.0,
        "microtesla": 1.0,
        "mt": 1000.0,
        "nt": 0.001,
        "gauss": 100.0,
        "ga": 100.0,
        "g": 100.0,
        "mgauss": 0.1,
        "mga": 0.1,
        "mg": 0.1,
    },
    "temperature": {"degc": 1.0, "°c": 1.0, "c": 1.0, "celsius": 1.0, "degreescelsius": 1.0, "degreecelsius": 1.0},
    "time": {"s": 1e9, "sec": 1e9, "ms": 1e6, "us": 1e3, "µs": 1e3, "μs": 1e3, "ns": 1.0},
}


# magnetometer units that are normalised to the calibration field: kept as a separate signal, never as uT
NORMALISED_MAG_UNITS = {"a.u.", "au", "a.u", "arb", "local_flux", "localflux", "normalized", "normalised"}


SI_UNIT = {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT", "temperature": "degC", "time": "ns"}


QUANTITIES = ("acc", "gyr", "mag", "temperature")


LENGTH_TO_M = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}


# quantities a user may give a unit for (``--unit acc=g``, ``ConvertOptions.extra["units"]``)
UNIT_QUANTITIES = ("acc", "gyr", "mag", "temperature", "time", "markers")


def check_unit(quantity: str, unit: str) -> str | None:
    """None when ``unit`` is a known unit of ``quantity`` (``markers``: a length), else the problem in one line."""
    if quantity == "markers":
        return None if unit.strip().lower() in LENGTH_TO_M else f"unknown length unit {unit!r} (use m, cm or mm)"
    if quantity not in UNIT_FACTORS:
        return f"unknown quantity {quantity!r}; use {', '.join(UNIT_QUANTITIES)}"
    if unit_factor(quantity, unit) is None and not (quantity == "mag" and normalise_unit(unit) in NORMALISED_MAG_UNITS):
        return f"unknown {quantity} unit {unit!r} (known: {', '.join(sorted(UNIT_FACTORS[quantity]))})"
    return None


def unit_overrides(extra: dict[str, Any] | None) -> dict[str, str]:
    """The user's units by quantity (``ConvertOptions.extra["units"]``, from ``--unit QUANTITY=UNIT``)."""
    units = (extra or {}).get("units") or {}
    return {str(k).lower(): str(v) for k, v in units.items()}


# the degree sign as files mangle it, before "/s" or "C": UTF-8 read as Latin-1 ("Â°", twice: "Ã‚Â°"), that text
# folded to ASCII ("A /s": EDF's dimension field is ASCII-only, so a writer transliterates "Â°/s"), "?" or U+FFFD for
# an unencodable character, and the ordinal sign "º" typed for it
_DEGREE_SIGN = re.compile(r"^(?:ã‚â°|â°|âº|º|°|\ufffd|\?|a\s+)(?=/\s*s(?:ec)?$|c$)")


_PER_S = re.compile(r"^(.*?)[.*·]s\^?-1$")


def normalise_unit(unit: str) -> str:
    """Canonical spelling used for look-ups: ``m/(s^2)`` -> ``m/s^2``, ``Degrees Celsius`` -> ``degreescelsius``,
    ``m.s-2`` -> ``m/s^2``, ``deg.s-1`` -> ``deg/s``, a mangled degree sign (``Â°/s``, ``A /s``, ``?/s``) -> ``°/s``."""
    u = unit.strip().strip("[]()").strip().lower()
    u = _DEGREE_SIGN.sub("°", u)
    u = u.replace("²", "^2").replace("**", "^").replace(" ", "").replace("(", "").replace(")", "")
    u = u.replace("/second", "/s").replace("deg/sec", "deg/s").replace("/sec", "/s")
    if u not in ("ms-2", "ms^-2"):  # "ms-2" is metres per second squared, not milliseconds
        m = _PER_S2.match(u)
        if m and m.group(1) in ("m", "mm", "cm"):
            u = m.group(1) + "/s^2"
    else:
        u = "m/s^2"
    m = _PER_S.match(u)
    if m and m.group(1):
        u = m.group(1) + "/s"
    return u


def unit_factor(quantity: str, unit: str) -> float | None:
    """Factor from ``unit`` to the SI unit of ``quantity`` or None when the unit is unknown."""
    return UNIT_FACTORS.get(quantity, {}).get(normalise_unit(unit))
