"""numba's on-disk cache for imulog's compiled kernels, stamped with every module their machine code depends on.

numba (``@njit(cache=True)``) stamps a cached function with the hash of the one file that defines it, so a kernel
that inlines or calls a compiled helper from another module (``solver_core.py`` calling ``dh.py`` and
``solver_qp.py``) kept running the helper's old machine code after that module alone changed (``git pull`` on an
editable install), until ``__pycache__`` was deleted. :func:`install` (called by ``imulog/__init__.py``) puts
locators in front of numba's own that, for functions of imulog's modules only, stamp the cache with
:func:`source_key`: a hash over the defining module and every module of the package it imports at module level,
transitively (helpers, constants). When any of them changes, numba finds the stamp different, drops the index and
compiles again; when nothing changed, the cache stays warm. Where the files go, in numba's order: under
``$NUMBA_CACHE_DIR/imulog/`` when set, else ``__pycache__/numba-keyed/`` beside the source when writable (a
checkout, an editable install), else ``~/.cache/imulog/numba/`` (``$XDG_CACHE_HOME``; a read-only site-packages).

numba itself is not imported here (``imulog info`` must not load it): when it is not loaded yet, a meta-path hook
registers the locators right after ``numba.core.caching`` runs, before any kernel module is decorated.
"""

from __future__ import annotations

import functools
import importlib.machinery
import os
import sys
from types import ModuleType
from typing import Any

#: top-level packages whose compiled functions get the keyed stamp (``install``)
_PACKAGES: set[str] = set()
_CACHING = "numba.core.caching"


def install(package: str = "imulog") -> None:
    """Stamp the numba cache of every compiled function defined in ``package`` with :func:`source_key`
    (idempotent; registers now when numba is loaded, else as soon as it is)."""
    _PACKAGES.add(package)
    if _CACHING in sys.modules:
        _register(sys.modules[_CACHING])
    elif not any(isinstance(f, _AfterNumbaCaching) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumbaCaching())


def uninstall() -> None:
    """numba's own locators again for functions decorated from now on (the baseline of
    ``benchmarks/bench_numba_cache.py``)."""
    _PACKAGES.clear()
    sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, _AfterNumbaCaching)]
    if _CACHING in sys.modules:
        impl = _cache_impl(sys.modules[_CACHING])
        if impl is not None:
            impl._locator_classes[:] = [c for c in impl._locator_classes if not getattr(c, "_imulog_keyed", False)]


@functools.cache
def source_key(path: str, module: str) -> str:
    """SHA-256 (hex) over the name and content of ``module`` (file ``path``) and of every module of the same
    package it imports at module level, transitively: what a compiled function of ``module`` can depend on."""
    import hashlib

    digest = hashlib.sha256()
    for name, file in sorted(module_closure(path, module).items()):
        digest.update(name.encode() + b"\0" + hashlib.sha256(_read(file)).digest())
    return digest.hexdigest()


def module_closure(path: str, module: str) -> dict[str, str]:
    """{module name: source file} of ``module`` and the modules of its top-level package that it imports at module
    level (``import``/``from ... import`` outside functions and classes), transitively, found on disk without
    importing anything (so the key does not depend on what else was imported before)."""
    top = module.partition(".")[0]
    found = {module: path}
    todo = [(module, path)]
    while todo:
        name, file = todo.pop()
        for dep in _imports(file, name, file.endswith("__init__.py")):
            if dep.partition(".")[0] != top or dep in found:
                continue
            dep_file = _module_file(dep)
            if dep_file is not None:
                found[dep] = dep_file
                todo.append((dep, dep_file))
    return found


@functools.cache
def _module_file(name: str) -> str | None:
    """The ``.py`` file of module ``name`` (a package's ``__init__.py``), else None (not a module, or not a source
    file): from ``sys.modules`` when loaded, else located through its parent's search path, nothing executed."""
    loaded = sys.modules.get(name)
    if loaded is not None:
        file = getattr(loaded, "__file__", None)
        return file if file and file.endswith(".py") else None
    spec = _spec(name)
    return spec.origin if spec is not None and spec.origin and spec.origin.endswith(".py") else None


def _spec(name: str) -> importlib.machinery.ModuleSpec | None:
    parent, _, _ = name.rpartition(".")
    if not parent:
        return None  # a top-level package is loaded (its kernel is)
    loaded = sys.modules.get(parent)
    if loaded is not None:
        search = getattr(loaded, "__path__", None)
    else:
        spec = _spec(parent)
        search = spec.submodule_search_locations if spec is not None else None
    return importlib.machinery.PathFinder.find_spec(name, list(search)) if search else None


@functools.cache
def _imports(path: str, module: str, is_package: bool) -> tuple[str, ...]:
    """Module names that ``path`` (module ``module``) imports at module level: a ``from X import a`` gives X and
    X.a (the latter counts only when it is a module)."""
    import ast

    tree = ast.parse(_read(path), filename=path)
    package = module if is_package else module.rpartition(".")[0]
    names: list[str] = []
    stack: list[ast.stmt] = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                root = ".".join(parts[: len(parts) - node.level + 1])
                base = f"{root}.{base}" if base else root
            names.append(base)
            names += [f"{base}.{a.name}" for a in node.names]
        elif not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            for field in ("body", "orelse", "finalbody", "handlers"):  # if, try, with, for, while at module level
                stack += [n for n in getattr(node, field, []) if isinstance(n, ast.stmt | ast.excepthandler)]
    return tuple(names)


def _read(path: str) -> bytes:
    with open(path, "rb") as f:
        return f.read()


class _AfterNumbaCaching:
    """Meta-path finder: loads ``numba.core.caching`` as usual, then registers the keyed locators."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> importlib.machinery.ModuleSpec | None:
        if fullname != _CACHING:
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is not None and spec.loader is not None:
            spec.loader = _RegisteringLoader(spec.loader)
        return spec


class _RegisteringLoader:
    """Wraps numba's loader of ``numba.core.caching``: runs the module, then :func:`_register`."""

    def __init__(self, loader: Any) -> None:
        self._loader = loader

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self._loader.exec_module(module)
        _register(module)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._loader, name)


def _cache_impl(caching: ModuleType) -> Any:
    return getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)


def _register(caching: ModuleType) -> None:
    """Put the keyed locators first in numba's list (``CacheImpl._locator_classes``; ``_CacheImpl`` and
    ``_...CacheLocator`` in older numba releases)."""
    impl = _cache_impl(caching)
    bases = [getattr(caching, n, None) or getattr(caching, "_" + n, None) for n in _BASES]
    if impl is None or None in bases:
        import warnings

        warnings.warn(
            "imulog: this numba has no cache locator API imulog knows; compiled kernels are stamped per file: "
            "delete __pycache__ after changing a module a kernel imports",
            RuntimeWarning,
            stacklevel=2,
        )
        return
    if any(getattr(c, "_imulog_keyed", False) for c in impl._locator_classes):
        return
    impl._locator_classes[:0] = [_keyed(base, where) for base, where in zip(bases, _BASES.values(), strict=True)]


def _user_provided(py_file: str, numba_path: str) -> str:
    from numba.core import config

    return os.path.join(config.CACHE_DIR, "imulog", os.path.basename(numba_path))


def _in_tree(py_file: str, numba_path: str) -> str:
    return os.path.join(os.path.dirname(py_file), "__pycache__", "numba-keyed")


def _user_wide(py_file: str, numba_path: str) -> str:
    from numba.misc.appdirs import AppDirs

    root = AppDirs(appname="imulog", appauthor=False).user_cache_dir
    return os.path.join(root, "numba", os.path.basename(numba_path))


#: numba's locator (older releases prefix an underscore) -> the folder its keyed twin uses
_BASES = {
    "UserProvidedCacheLocator": _user_provided,
    "InTreeCacheLocator": _in_tree,
    "UserWideCacheLocator": _user_wide,
}


def _keyed(base: type, where: Any) -> type:
    """``base`` for functions of the installed packages only, its folder moved by ``where`` and its stamp
    :func:`source_key`."""

    class Keyed(base):  # type: ignore[misc,valid-type]
        _imulog_keyed = True

        def __init__(self, py_func: Any, py_file: str) -> None:
            super().__init__(py_func, py_file)
            self._module = py_func.__module__
            self._cache_path = where(py_file, super().get_cache_path())

        def get_cache_path(self) -> str:
            return self._cache_path

        def get_source_stamp(self) -> str:
            return source_key(self._py_file, self._module)

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if str(getattr(py_func, "__module__", "")).partition(".")[0] not in _PACKAGES:
                return None
            return super().from_function(py_func, py_file)

    Keyed.__name__ = Keyed.__qualname__ = f"Keyed{base.__name__.lstrip('_')}"
    return Keyed
