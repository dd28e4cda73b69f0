"""The package's layout as its docstrings describe it: layers that import only downward, no import circles,
the core without ROS, and subpackage ``__init__`` files that only say what they own."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "wand_calib_ros"

#: Top-level layers, lowest first: each may import itself and those before it.
LAYERS = ("errors", "core", "io", "report", "detection", "collection", "sim", "commands", "cli", "nodes")
#: The core's parts, lowest first (``errors`` is shared by all).
CORE_LAYERS = ("errors", "parallel", "model", "adjust", "judge", "initialise", "after", "refine", "pipeline")


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(name: str) -> bool:
    relative = Path(*name.split("."))
    return (PACKAGE.parent / relative).with_suffix(".py").is_file() or (PACKAGE.parent / relative).is_dir()


def _imports(path: Path) -> set[str]:
    """Modules of this package that ``path`` imports (anywhere in it, lazy imports included)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name.startswith("wand_calib_ros"))
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("wand_calib_ros"):
            assert node.level == 0, f"{path}: relative import"
            for alias in node.names:
                candidate = f"{node.module}.{alias.name}"
                found.add(candidate if _is_module(candidate) else node.module)
    return found


@pytest.fixture(scope="module")
def graph() -> nx.DiGraph:
    g = nx.DiGraph()
    for path in PACKAGE.rglob("*.py"):
        name = _module_name(path)
        g.add_node(name)
        g.add_edges_from((name, target) for target in _imports(path) if target != name)
    return g


def _part(name: str, depth: int) -> str:
    parts = name.split(".")
    return parts[depth] if len(parts) > depth else ""


def test_there_are_no_import_circles(graph: nx.DiGraph) -> None:
    # A package importing its own submodules is how a package works; only module-to-module arrows count.
    modules = graph.subgraph(n for n in graph if not (PACKAGE.parent / Path(*n.split("."))).is_dir())
    assert list(nx.simple_cycles(modules)) == []


def test_layers_import_only_downward(graph: nx.DiGraph) -> None:
    upward = []
    for source, target in graph.edges:
        a, b = _part(source, 1), _part(target, 1)
        if a and b and LAYERS.index(b) > LAYERS.index(a):
            upward.append(f"{source} -> {target}")
    assert upward == []


def test_the_core_parts_import_only_downward(graph: nx.DiGraph) -> None:
    upward = []
    for source, target in graph.edges:
        if _part(source, 1) == "core" and _part(target, 1) == "core" and _part(source, 2) and _part(target, 2):
            a, b = _part(source, 2), _part(target, 2)
            if CORE_LAYERS.index(b) > CORE_LAYERS.index(a):
                upward.append(f"{source} -> {target}")
    assert upward == []


def test_every_core_module_belongs_to_a_part() -> None:
    parts = {
        path.parent.name if path.parent != PACKAGE / "core" else path.stem for path in (PACKAGE / "core").rglob("*.py")
    }
    assert parts - {"core", "__init__"} <= set(CORE_LAYERS)


def test_only_the_nodes_import_ros() -> None:
    ros = ("rclpy", "sensor_msgs", "std_msgs", "std_srvs", "geometry_msgs", "visualization_msgs", "diagnostic_msgs")
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        if path.parent.name == "nodes":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[0] in ros]
    assert offenders == []


def test_package_inits_are_not_re_export_shims() -> None:
    """A subpackage's ``__init__`` says what it owns; it does not gather its modules' names for callers
    (``io.export`` imports its format modules for the table that writes them, nothing for callers)."""
    shims = []
    for path in PACKAGE.rglob("__init__.py"):
        body = ast.parse(path.read_text()).body
        assert body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant), (
            f"{path}: no docstring"
        )
        own = _module_name(path)
        if own == "wand_calib_ros.io.export":
            continue
        for node in body:
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith(own + "."):
                shims.append(f"{own}: from {node.module} import ...")
    assert shims == []
