"""The import graph of imulog/: no cycles, and no import from a lower layer to a higher one (docs/architecture.md,
"Layers"). Every import counts, also those inside functions (a lazy import is still a dependency)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "imulog"

#: layer of each package or module (the longest matching prefix decides); a module imports only its own layer or
#: lower ones
LAYERS = {
    "imulog": 0,  # the package's own small helpers: _lazy, heap, numeric, model, console
    "imulog.process": 1,
    "imulog.converters": 1,  # the top-level converters/ folder, installed as imulog.converters
    "imulog.archive": 2,
    "imulog.steps": 3,
    "imulog.simulate": 3,
    "imulog.view": 4,
    "imulog.live": 4,  # live capture: converters' stream mapping, the streaming writer, the viewer
    "imulog.export": 4,
    "imulog.batch": 5,
    "imulog.commands": 5,
    "imulog.cli": 5,
    "imulog.__main__": 5,
}

#: imports that still break the rules, each with its reason; the test fails when one of them is gone (remove it
#: here) or when a new one appears. Issue 24 asks for this list to be empty.
KNOWN: dict[tuple[str, str], str] = {}


def module_names() -> dict[str, Path]:
    out = {}
    for p in ROOT.rglob("*.py"):
        parts = p.relative_to(ROOT.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    for p in (ROOT.parent / "converters").rglob("*.py"):  # package-dir: converters/ is imulog.converters
        parts = ("imulog", *p.relative_to(ROOT.parent).with_suffix("").parts)
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def import_graph() -> dict[str, set[str]]:
    """{module: modules of imulog it imports}; ``from pkg import name`` counts ``pkg.name`` when that is a module,
    else ``pkg``."""
    mods = module_names()
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, p in mods.items():
        package = m if p.name == "__init__.py" else m.rpartition(".")[0]
        for node in ast.walk(ast.parse(p.read_text(), str(p))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                for a in node.names:
                    targets.append(f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base)
            for t in targets:
                while t and t not in mods:  # `import imulog.x.y` of a name inside a module: the module
                    t = t.rpartition(".")[0]
                if t and t != m:
                    graph[m].add(t)
    return graph


def layer(module: str) -> int:
    best = max((k for k in LAYERS if module == k or module.startswith(k + ".")), key=len)
    return LAYERS[best]


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (mutual reachability; the graph is small)."""
    reach: dict[str, set[str]] = {}
    for start in graph:
        seen, todo = set(), [start]
        while todo:
            for w in graph[todo.pop()]:
                if w not in seen:
                    seen.add(w)
                    todo.append(w)
        reach[start] = seen
    comps, done = [], set()
    for v in sorted(graph):
        if v in done:
            continue
        comp = sorted({v} | {w for w in reach[v] if v in reach[w]})
        done.update(comp)
        if len(comp) > 1:
            comps.append(comp)
    return comps


def test_the_graph_sees_lazy_and_relative_imports():
    graph = import_graph()
    assert "imulog.steps.windows" in graph["imulog.steps.orientation"]  # module level
    assert "imulog.archive.streaming" in graph["imulog.steps.orientation"]  # inside a function
    assert "imulog.process.alignment_search" in graph["imulog.process.alignment"]


def test_no_import_cycles():
    graph = import_graph()
    for a, b in KNOWN:
        graph[a].discard(b)
    found = cycles(graph)
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_no_import_from_a_lower_layer_to_a_higher_one():
    graph = import_graph()
    upward = {(a, b) for a, bs in graph.items() for b in bs if layer(b) > layer(a)}
    assert upward <= set(KNOWN), "imports from a lower to a higher layer: " + ", ".join(
        f"{a} -> {b}" for a, b in sorted(upward - set(KNOWN))
    )
    assert set(KNOWN) <= upward | {(a, b) for a, bs in graph.items() for b in bs}, "fixed: remove from KNOWN"


#: modules still over about 500 lines, each with its reason; the test fails when one shrinks under the limit (remove
#: it here) or a new one grows past it (split it by concern: docs/architecture.md, "Modules")
MAX_LINES = 520
LONG: dict[str, str] = {}


def test_modules_stay_under_about_500_lines():
    sizes = {m: len(p.read_text().splitlines()) for m, p in module_names().items()}
    long = {m for m, n in sizes.items() if n > MAX_LINES}
    assert long <= set(LONG), "modules over 500 lines: " + ", ".join(
        f"{m} ({sizes[m]})" for m in sorted(long - set(LONG))
    )
    assert set(LONG) <= long, "under the limit now, remove from LONG: " + ", ".join(sorted(set(LONG) - long))
