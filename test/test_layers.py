"""The package's layers import only downward: every edge between its parts is named here.

Bottom up: ``errors``/``paths``/``progress``/``timing`` (utilities) → ``cpg`` (the generic CPG) →
``robot`` (the HOAP-2 model, PID law, contact) → ``walker`` (the HOAP-2 controller: cpg × robot, no
ROS) → ``nodes`` (the rclpy nodes and what they use) → ``graph`` (the tools that run and inspect the node
graph) → ``experiments`` → ``cli``. An import not in ALLOWED fails, naming file and line. Within a part,
too, no two modules import each other, directly or round a longer circle (imports inside functions
count): the circle found is named, module by module, with file and line.
"""

from __future__ import annotations

import ast
import itertools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "cpg_walker"

#: part -> the parts it may import (besides itself). Nothing may import ``cli`` or ``experiments``
#: except those above them.
ALLOWED: dict[str, set[str]] = {
    "errors": set(),
    "paths": {"errors"},
    "progress": set(),
    "timing": set(),
    "cpg": set(),
    "robot": {"errors", "paths"},
    "walker": {"errors", "paths", "timing", "cpg", "robot"},
    "nodes": {"errors", "paths", "timing", "cpg", "robot", "walker"},
    "graph": {"errors", "paths", "timing", "cpg", "robot", "walker", "nodes"},
    "experiments": {"errors", "paths", "progress", "timing", "cpg", "robot", "walker", "nodes", "graph"},
    "cli": {"errors", "paths", "progress", "timing", "cpg", "robot", "walker", "nodes", "graph",
            "experiments"},
    "__init__": set(),
}
#: third-party roots a part must not import (the pure layers stay free of ROS).
FORBIDDEN_EXTERNAL = {"cpg": {"rclpy", "mujoco", "launch", "launch_ros"},
                      "robot": {"rclpy", "launch", "launch_ros"},
                      "walker": {"rclpy", "launch", "launch_ros"}}


def _part(path: Path) -> str:
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, dotted module) of every import in the file, relative ones resolved."""
    out = []
    pkg = ["cpg_walker", *path.relative_to(PACKAGE).parts[:-1]]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(pkg[: len(pkg) - node.level + 1])
                mod = f"{base}.{node.module}" if node.module else base
                names = [f"{mod}.{a.name}" for a in node.names] if not node.module else [mod]
                out += [(node.lineno, n) for n in names]
            elif node.module:
                if node.module == "cpg_walker":
                    out += [(node.lineno, f"cpg_walker.{a.name}") for a in node.names]
                else:
                    out.append((node.lineno, node.module))
    return out


FILES = sorted(PACKAGE.rglob("*.py"))


def test_every_part_is_known() -> None:
    assert {_part(p) for p in FILES} <= set(ALLOWED)


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_follow_the_allowed_edges(path: Path) -> None:
    part = _part(path)
    bad = []
    for line, mod in _imports(path):
        root = mod.split(".")
        if root[0] == "cpg_walker" and len(root) > 1:
            target = root[1]
            if target != part and target not in ALLOWED[part]:
                bad.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {part} -> {target} ({mod})")
        elif root[0] in FORBIDDEN_EXTERNAL.get(part, set()):
            bad.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {part} must not import {root[0]}")
    assert not bad, "\n".join(bad)


def test_the_generic_cpg_imports_nothing_else_of_the_package() -> None:
    for path in (PACKAGE / "cpg").rglob("*.py"):
        others = [m for _, m in _imports(path)
                  if m.split(".")[0] == "cpg_walker" and m.split(".")[1:2] != ["cpg"]]
        assert not others, (path, others)


def test_no_node_imports_the_graph_tools() -> None:
    """The nodes stand on their own: the graph tooling (processes, ros2cli stand-ins) sits above them."""
    assert "graph" not in ALLOWED["nodes"]
    assert all("graph" in ALLOWED[part] for part in ("experiments", "cli"))


def test_nothing_imports_the_leaves() -> None:
    """cli and experiments are leaves: only cli may import experiments, nothing imports cli."""
    assert all("cli" not in allowed for allowed in ALLOWED.values())
    assert [part for part, allowed in ALLOWED.items() if "experiments" in allowed] == ["cli"]


# ------------------------------------------------------------------------------------ import circles

def _module_name(path: Path) -> str:
    """cpg_walker/walker/storage.py -> cpg_walker.walker.storage; a package's __init__.py -> the package."""
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in FILES}


def _resolve(dotted: str) -> str | None:
    """The package's module that importing ``dotted`` runs (``pkg.mod.NAME`` -> ``pkg.mod``), or None."""
    while dotted and dotted not in MODULES:
        dotted = dotted.rpartition(".")[0]
    return dotted or None


def _module_edges(path: Path) -> dict[str, int]:
    """The package's modules this file imports (anywhere in it, inside functions too) -> first line."""
    me = _module_name(path)
    pkg = me.split(".") if path.name == "__init__.py" else me.split(".")[:-1]
    targets: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = ".".join(pkg[: len(pkg) - node.level + 1]) if node.level else ""
            mod = ".".join(x for x in (base, node.module) if x)
            # ``from pkg import mod`` imports the module pkg.mod; ``from mod import name`` only mod
            targets += [(node.lineno, f"{mod}.{a.name}") for a in node.names]
    edges: dict[str, int] = {}
    for line, dotted in sorted(targets):
        if dotted.split(".")[0] != "cpg_walker":
            continue
        target = _resolve(dotted)
        if target is not None and target != me:
            edges.setdefault(target, line)
    return edges


def _find_circle(graph: dict[str, dict[str, int]]) -> list[str] | None:
    """One import circle of ``graph`` (module -> {imported module: line}) as [m0, m1, ..., m0], or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done (no circle through it)
    path: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        path.append(m)
        for n in sorted(graph.get(m, {})):
            if state.get(n) == 1:
                return [*path[path.index(n):], n]
            if n not in state and (circle := visit(n)):
                return circle
        path.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (circle := visit(m)):
            return circle
    return None


def _describe(circle: list[str], graph: dict[str, dict[str, int]]) -> str:
    steps = [f"{a} -> {b} ({MODULES[a].relative_to(PACKAGE.parent)}:{graph[a][b]})"
             for a, b in itertools.pairwise(circle)]
    return "import circle:\n  " + "\n  ".join(steps)


def test_no_import_circle_among_the_modules() -> None:
    graph = {m: _module_edges(p) for m, p in MODULES.items()}
    circle = _find_circle(graph)
    assert circle is None, _describe(circle, graph)


def test_the_circle_finder_finds_and_names_a_circle() -> None:
    a, b, c = "cpg_walker.walker.controller", "cpg_walker.walker.storage", "cpg_walker.walker.loop"
    graph = {a: {c: 3}, c: {b: 5}, b: {a: 16}}
    circle = _find_circle(graph)
    assert circle is not None and circle[0] == circle[-1] and set(circle) == {a, b, c}
    assert "walker/storage.py:16" in _describe(circle, graph)
    assert _find_circle({a: {b: 1}, b: {}, c: {a: 2, b: 3}}) is None
    edges = _module_edges(MODULES["cpg_walker.walker.storage"])
    assert "cpg_walker.walker.controller" in edges and "cpg_walker.cpg.network" in edges
