"""The package's layers import only downward: every edge between its parts is named here.

Bottom up: ``errors``/``paths``/``progress`` (utilities) → ``cpg`` (the generic CPG) → ``robot`` (the
HOAP-2 model, PID law, contact) → ``walker`` (the HOAP-2 controller: cpg × robot, no ROS) → ``nodes``
(the rclpy nodes and what they use) → ``graph`` (the tools that run and inspect the node graph) →
``experiments`` → ``cli``. An import not in ALLOWED fails, naming file and line.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "cpg_walker"

#: part -> the parts it may import (besides itself). Nothing may import ``cli`` or ``experiments``
#: except those above them.
ALLOWED: dict[str, set[str]] = {
    "errors": set(),
    "paths": {"errors"},
    "progress": set(),
    "cpg": set(),
    "robot": {"errors", "paths"},
    "walker": {"errors", "paths", "cpg", "robot"},
    "nodes": {"errors", "paths", "cpg", "robot", "walker"},
    "graph": {"errors", "paths", "cpg", "robot", "walker", "nodes"},
    "experiments": {"errors", "paths", "progress", "cpg", "robot", "walker", "nodes", "graph"},
    "cli": {"errors", "paths", "progress", "cpg", "robot", "walker", "nodes", "graph", "experiments"},
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
