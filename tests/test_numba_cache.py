"""numba's on-disk cache of compiled kernels follows changes in the modules a kernel imports (imulog.numba_cache).

numba stamps a cached function with the hash of its own file only: a kernel inlining a helper of another module kept
the helper's old machine code after that module changed. Each check runs fresh processes on a small package (a
kernel in one module, an ``inline="always"`` helper in another), as ``git pull`` then a new run would.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

HELPER = """
from numba import njit

OFFSET = {offset}


@njit(inline="always")
def shift(x):
    return x + {step}
"""

KERNEL = """
import numpy as np
from numba import njit

from kpkg.helpers import OFFSET, shift


@njit(cache=True)
def total(a):
    s = 0.0
    for v in a:
        s += shift(v)
    return s + OFFSET
"""

RUN = """
import json, sys
{install}
from kpkg.kernel import total
import numpy as np
value = total(np.arange(3.0))
stats = total.stats
print(json.dumps({{"value": value, "hits": sum(stats.cache_hits.values()), "misses": sum(stats.cache_misses.values()),
                  "locator": type(total._cache._impl.locator).__name__,
                  "path": total._cache._impl.locator.get_cache_path()}}))
"""


def _package(root: Path, *, step: int, offset: int = 0, other: str = "") -> None:
    pkg = root / "kpkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "helpers.py").write_text(HELPER.format(step=step, offset=offset))
    (pkg / "kernel.py").write_text(KERNEL)
    (pkg / "other.py").write_text(f"VALUE = {other!r}\n")


def _run(root: Path, env_extra: dict[str, str] | None = None, *, keyed: bool = True) -> dict:
    install = "import imulog.numba_cache as c; c.install('kpkg')" if keyed else ""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT")}
    env.update(env_extra or {}, PYTHONPATH=str(root))
    out = subprocess.run(
        [sys.executable, "-c", RUN.format(install=install)], env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture
def home(tmp_path: Path) -> dict[str, str]:
    return {"XDG_CACHE_HOME": str(tmp_path / "xdg")}


def test_changed_helper_in_another_module_recompiles_the_kernel(tmp_path: Path, home: dict[str, str]) -> None:
    _package(tmp_path, step=1)
    first = _run(tmp_path, home)
    assert first["value"] == 6.0 and first["misses"] == 1 and first["locator"] == "KeyedInTreeCacheLocator"
    assert Path(first["path"]) == tmp_path / "kpkg" / "__pycache__" / "numba-keyed"
    warm = _run(tmp_path, home)
    assert warm["value"] == 6.0 and (warm["hits"], warm["misses"]) == (1, 0)  # nothing changed: no compilation
    _package(tmp_path, step=2)  # the helper's body changes, kernel.py does not
    changed = _run(tmp_path, home)
    assert changed["value"] == 9.0 and changed["misses"] == 1
    _package(tmp_path, step=2, offset=10)  # a constant the kernel imports from the other module
    assert _run(tmp_path, home)["value"] == 19.0
    again = _run(tmp_path, home)
    assert again["value"] == 19.0 and (again["hits"], again["misses"]) == (1, 0)


def test_a_module_the_kernel_does_not_import_leaves_its_cache_warm(tmp_path: Path, home: dict[str, str]) -> None:
    _package(tmp_path, step=1, other="a")
    assert _run(tmp_path, home)["misses"] == 1
    _package(tmp_path, step=1, other="b")
    after = _run(tmp_path, home)
    assert after["value"] == 6.0 and (after["hits"], after["misses"]) == (1, 0)


def test_without_a_writable_source_folder_the_user_cache_is_keyed_too(tmp_path: Path, home: dict[str, str]) -> None:
    _package(tmp_path, step=1)
    (tmp_path / "kpkg" / "__pycache__").write_text("")  # a file: no cache folder beside the sources (as root too)
    first = _run(tmp_path, home)
    assert first["locator"] == "KeyedUserWideCacheLocator" and first["path"].startswith(home["XDG_CACHE_HOME"])
    assert Path(first["path"]).parent == Path(home["XDG_CACHE_HOME"]) / "imulog" / "numba"
    assert _run(tmp_path, home)["misses"] == 0
    _package(tmp_path, step=3)
    assert _run(tmp_path, home)["value"] == 12.0


def test_numba_cache_dir_is_honoured_and_keyed(tmp_path: Path, home: dict[str, str]) -> None:
    _package(tmp_path, step=1)
    env = dict(home, NUMBA_CACHE_DIR=str(tmp_path / "nc"))
    first = _run(tmp_path, env)
    assert first["locator"] == "KeyedUserProvidedCacheLocator"
    assert Path(first["path"]).parent == tmp_path / "nc" / "imulog"
    _package(tmp_path, step=2)
    assert _run(tmp_path, env)["value"] == 9.0


def test_numba_loaded_before_imulog_gets_the_locators_too(tmp_path: Path, home: dict[str, str]) -> None:
    _package(tmp_path, step=1)
    code = textwrap.dedent(
        """
        import numba, imulog, imulog.numba_cache as c
        c.install('kpkg')
        from kpkg.kernel import total
        print(type(total._cache._impl.locator).__name__)
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=dict(os.environ, PYTHONPATH=str(tmp_path), **home),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["KeyedInTreeCacheLocator"]


def test_every_cached_kernel_of_imulog_is_keyed_over_the_modules_it_imports() -> None:
    """Every ``cache=True`` function of the package gets the keyed locator, and the kinematics solver's key covers
    the two modules whose stale helpers were seen (dh.py, solver_qp.py)."""
    code = textwrap.dedent(
        """
        import importlib, json, pathlib, re, sys
        import imulog
        from imulog.numba_cache import module_closure
        root = pathlib.Path(imulog.__file__).parent
        out = {}
        for f in sorted(root.rglob("*.py")):
            cached = len(re.findall(r"^\\s*@.*\\bcache=True", f.read_text(), re.M))
            if not cached:
                continue
            name = "imulog." + ".".join(f.relative_to(root).with_suffix("").parts)
            mod = importlib.import_module(name)
            kernels = [v for v in vars(mod).values() if getattr(v, "__module__", None) == name and hasattr(v, "_cache")
                       and hasattr(v._cache, "_impl")]
            out[name] = {"kernels": len(kernels), "cached": cached,
                         "locators": sorted({type(k._cache._impl.locator).__name__ for k in kernels}),
                         "closure": sorted(module_closure(str(f), name))}
        print(json.dumps(out))
        """
    )
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    found = json.loads(out.stdout)
    assert len(found) >= 7
    for name, info in found.items():
        assert info["kernels"] == info["cached"] and len(info["locators"]) == 1, (name, info)
        assert info["locators"][0].startswith("Keyed"), (name, info)
    core = found["imulog.process.kinematics.solver_core"]["closure"]
    assert {"imulog.process.kinematics.dh", "imulog.process.kinematics.solver_qp"} <= set(core)
