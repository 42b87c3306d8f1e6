"""Metadata records: MCAP stores ``map<string, string>``; imulog stores dicts of JSON-able values.

Strings are stored as they are (readable in any MCAP tool); every other value is stored as JSON and its key
listed in the reserved entry ``_json`` (a JSON list), so reading gives back exactly the written types.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import numpy as np

JSON_KEYS = "_json"


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


def decode_record(items: dict[str, str]) -> dict[str, Any]:
    try:
        json_keys = set(json.loads(items.get(JSON_KEYS, "[]")))
    except ValueError:
        json_keys = set()
    out: dict[str, Any] = {}
    for key, value in items.items():
        if key == JSON_KEYS:
            continue
        if key in json_keys:
            try:
                out[key] = json.loads(value)
                continue
            except ValueError:
                pass
        out[key] = value
    return out
