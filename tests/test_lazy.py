"""imulog._lazy: a stand-in that imports its module on first use and then gets out of the way."""

from __future__ import annotations

import sys
import types

from imulog._lazy import LazyModule


def test_first_attribute_imports_and_rebinds_the_owners_global(monkeypatch):
    owner = types.ModuleType("lazy_owner_probe")
    owner.mod = LazyModule("colorsys", owner.__name__)
    monkeypatch.setitem(sys.modules, owner.__name__, owner)
    monkeypatch.delitem(sys.modules, "colorsys", raising=False)
    assert isinstance(owner.mod, LazyModule) and "colorsys" not in sys.modules
    assert owner.mod.rgb_to_hsv(1.0, 0.0, 0.0) == (0.0, 1.0, 1.0)
    assert owner.mod is sys.modules["colorsys"]  # rebound: no indirection from now on


def test_imulog_modules_on_the_info_path_use_numpy_lazily():
    import imulog.archive.reader as reader
    import imulog.model as model

    model.np.int64  # noqa: B018 - the first use
    assert model.np is sys.modules["numpy"] and reader.np.ndarray is sys.modules["numpy"].ndarray
