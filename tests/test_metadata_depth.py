"""The JSON depth check of metadata records counts on the text what a walk over the decoded value counts."""

import json
import random

import pytest

from imulog.archive.metadata import MAX_JSON_DEPTH, MetadataError, _depth, loads


def _walk_depth(value) -> int:
    """Nesting depth of a decoded JSON value by walking it (the reference)."""
    if isinstance(value, dict):
        return 1 + max((_walk_depth(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_walk_depth(v) for v in value), default=0)
    return 0


def _value(rng: random.Random, level: int):
    r = rng.random()
    if level > 40 or r < 0.3:  # strings with brackets, quotes and backslashes that must not count
        return rng.choice([1, 2.5, None, True, 'a"[{b', "\\", 'x\\"]}y', "]]]", "{{", "\\\\[", "é[ü"])
    if r < 0.65:
        return [_value(rng, level + 1) for _ in range(rng.randrange(0, 4))]
    return {
        rng.choice(["k", "[", "}", 'q"', "\\"]) + str(i): _value(rng, level + 1) for i in range(rng.randrange(0, 4))
    }


def test_text_depth_equals_the_walk_on_random_values():
    rng = random.Random(0)
    deep = 0
    for _ in range(5000):
        v = _value(rng, 0)
        text = json.dumps(v, ensure_ascii=rng.random() < 0.5)
        want = min(_walk_depth(v), MAX_JSON_DEPTH + 1)
        assert min(_depth(text), MAX_JSON_DEPTH + 1) == want, text
        deep += want > MAX_JSON_DEPTH
    assert deep > 0  # some values were too deep, so the limit was exercised


def test_loads_refuses_deep_and_accepts_wide():
    wide = json.dumps([{"rows": [[i, str(i) + "]]"] for i in range(1000)]}])
    assert loads(wide, "wide") == json.loads(wide)
    with pytest.raises(MetadataError, match="nested deeper"):
        loads("[" * (MAX_JSON_DEPTH + 1) + "]" * (MAX_JSON_DEPTH + 1), "deep")
