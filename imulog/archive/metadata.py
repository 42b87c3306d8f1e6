"""Metadata records: MCAP stores ``map<string, string>``; imulog stores dicts of JSON-able values.

Strings are stored as they are (readable in any MCAP tool); every other value is stored as JSON and its key
listed in the reserved entry ``_json`` (a JSON list), so reading gives back exactly the written types.
"""

from __future__ import annotations

import dataclasses
import json
import re
from typing import Any

from imulog._lazy import LazyModule

np = LazyModule("numpy", __name__)  # imported on first use: imulog info never needs numpy

JSON_KEYS = "_json"
MAX_JSON_DEPTH = 32  # nesting levels allowed in a JSON value of a metadata record or channel metadata
MAX_RECORD_BYTES = 16 * 1024 * 1024  # largest metadata record read (bytes)


class MetadataError(ValueError):
    """A metadata record or channel metadata value is malformed (message names the key)."""


_KEEP = b'"[]{}'
_DROP = bytes(c for c in range(256) if c not in _KEEP)  # bytes deleted before counting (UTF-8: never these)
_QUOTED = re.compile(rb'"[^"]*"')
_INNERMOST = re.compile(rb"\[\]|\{\}")


def _depth(text: str, limit: int = MAX_JSON_DEPTH) -> int:
    """Nesting depth of the containers of valid JSON ``text`` (at most ``limit + 1``: deeper is not counted).

    Escaped backslashes and quotes removed (left to right, as JSON reads them), every byte but quotes and
    brackets dropped, the brackets inside strings (between quote pairs) dropped, then the innermost pairs removed
    round by round: the number of rounds is the depth. String operations in C, so a record of a week's rows
    takes milliseconds rather than a walk over its objects."""
    kept = text.replace("\\\\", "").replace('\\"', "").encode("utf-8", "surrogatepass").translate(None, _DROP)
    brackets = _QUOTED.sub(b"", kept.replace(b'""', b""))  # removing "" keeps every bracket's side of the quotes
    depth = 0
    while brackets and depth <= limit:
        brackets = _INNERMOST.sub(b"", brackets)
        depth += 1
    return depth


def loads(text: str, what: str) -> Any:
    """``json.loads`` that refuses values nested deeper than MAX_JSON_DEPTH (MetadataError naming ``what``)."""
    if text.count("[") + text.count("{") > MAX_JSON_DEPTH:
        try:
            value = json.loads(text)
        except RecursionError:
            value = None
            deep = True
        else:
            deep = _depth(text) > MAX_JSON_DEPTH
        if deep:
            raise MetadataError(f"{what}: JSON nested deeper than {MAX_JSON_DEPTH} levels")
        return value
    return json.loads(text)


def check_depth(text: str, what: str) -> None:
    """Raise MetadataError if ``text`` is JSON nested deeper than MAX_JSON_DEPTH (other text passes)."""
    if text.count("[") + text.count("{") <= MAX_JSON_DEPTH:
        return
    try:
        loads(text, what)
    except ValueError as exc:
        if isinstance(exc, MetadataError):
            raise


def _default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    if isinstance(value, set | frozenset):
        return sorted(value)
    return str(value)


def to_json(value: Any) -> str:
    """Canonical JSON (sorted keys, no spaces) used for params, inputs and metadata values."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=_default, allow_nan=True)


def encode_record(values: dict[str, Any]) -> dict[str, str]:
    out: dict[str, str] = {}
    json_keys = []
    for key, value in values.items():
        key = str(key)
        if key == JSON_KEYS:
            raise ValueError(f"metadata key {JSON_KEYS!r} is reserved")
        if isinstance(value, str):
            out[key] = value
        else:
            out[key] = to_json(value)
            json_keys.append(key)
    if json_keys:
        out[JSON_KEYS] = json.dumps(json_keys)
    return out


def decode_record(items: dict[str, str], name: str = "metadata") -> dict[str, Any]:
    """The typed values of a stored record; MetadataError for JSON nested deeper than MAX_JSON_DEPTH."""
    try:
        listed = loads(items.get(JSON_KEYS, "[]"), f"{name}: {JSON_KEYS}")
        json_keys = {k for k in listed if isinstance(k, str)} if isinstance(listed, list) else set()
    except MetadataError:
        raise
    except ValueError:
        json_keys = set()
    out: dict[str, Any] = {}
    for key, value in items.items():
        if key == JSON_KEYS:
            continue
        if key in json_keys:
            try:
                out[key] = loads(value, f"{name}: {key!r}")
                continue
            except MetadataError:
                raise
            except ValueError:
                pass
        out[key] = value
    return out


# ------------------------------------------------------------------ typed validation of imulog's own records


def _is_number(v: Any) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, int | float):
        return True
    if isinstance(v, str):
        try:
            float(v)
        except ValueError:
            return False
        return True
    return False


def _numbers(v: Any, n: int | None = None) -> bool:
    return isinstance(v, list) and (n is None or len(v) == n) and all(_is_number(x) for x in v)


def _str_map(v: Any) -> bool:
    return isinstance(v, dict) and all(isinstance(x, str) for x in v.values())


def _str_list(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


_RUN_TYPES = {
    "step": (lambda v: isinstance(v, str), "a string"),
    "algorithm": (lambda v: isinstance(v, str), "a string"),
    "params": (lambda v: isinstance(v, dict), "an object"),
    "inputs": (_str_map, "an object of topic -> hash strings"),
    "outputs": (_str_map, "an object of topic -> hash strings"),
    "metadata": (_str_list, "a list of record names"),
    "replaced": (_str_list, "a list of topics"),
    "removed": (_str_list, "a list of topics"),
}
_RAW_TYPES = {
    "sha256": (lambda v: isinstance(v, str), "a string"),
    "channels": (_str_map, "an object of topic -> hash strings"),
    "attachments": (_str_map, "an object of name -> sha256 strings"),
}
_ALIGNMENT_TYPES = {
    **{k: (_is_number, "a number") for k in ("offset_ns", "drift_ppm", "t0_ns", "score", "rotation_residual_rad_s")},
    "rotation_imu_to_cluster": (lambda v: v is None or _numbers(v, 4), "4 numbers"),
    "rotation_global_to_world": (lambda v: v is None or _numbers(v, 4), "4 numbers or null"),
    "gyr_bias_rad_s": (lambda v: _numbers(v, 3), "3 numbers"),
    "windows": (lambda v: isinstance(v, list) and all(isinstance(w, dict) for w in v), "a list of objects"),
}


def record_types(name: str) -> dict[str, tuple[Any, str]]:
    """The typed keys imulog checks in its own record ``name`` (empty for records it does not know)."""
    if name.startswith("imulog.run."):
        return _RUN_TYPES
    return {"imulog.raw": _RAW_TYPES, "imulog.alignment": _ALIGNMENT_TYPES}.get(name, {})


def validate_record(name: str, values: dict[str, Any]) -> None:
    """Raise MetadataError when a key of one of imulog's own records has the wrong type."""
    for key, (ok, expected) in record_types(name).items():
        if key in values and not ok(values[key]):
            got = type(values[key]).__name__
            raise MetadataError(f"metadata record {name!r}: {key!r} must be {expected}, not {got}")


def record_hash(record: Any) -> str:
    """Content hash of a metadata record (canonical JSON; a missing record hashes as ``null``)."""
    import hashlib

    return hashlib.sha256(to_json(record).encode()).hexdigest()
