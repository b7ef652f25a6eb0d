"""The package layout keeps its promise: the core imports no ROS or web server, ROS code no display code.

Imports are read from the source with :mod:`ast` (top level and inside functions alike), so a lazy
``import rclpy`` inside a core function is caught too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "helireach_ros"


def imported_modules(path: Path, root: Path = PACKAGE.parent, *, at_run_time: bool = False) -> set[str]:
    """Every module a file imports, absolute names (relative imports resolved against its package).

    ``at_run_time``: leave out the imports under ``if TYPE_CHECKING:``, which only the type checker runs.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = ".".join(path.relative_to(root).with_suffix("").parts[:-1])
    names: set[str] = set()
    skipped: set[int] = set()
    if at_run_time:
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                skipped.update(id(child) for statement in node.body for child in ast.walk(statement))
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                module = f"{base}.{node.module}" if node.module else base
            else:
                module = node.module or ""
            names.add(module)
            names.update(f"{module}.{alias.name}" for alias in node.names)
    return names


def offending(folder: str, forbidden: tuple[str, ...], package: Path = PACKAGE) -> dict[str, list[str]]:
    """Files under ``package/folder`` importing a forbidden module (or a submodule of one)."""
    found = {}
    for path in sorted((package / folder).rglob("*.py")):
        bad = sorted(
            name
            for name in imported_modules(path, package.parent)
            if any(name == f or name.startswith(f + ".") for f in forbidden)
        )
        if bad:
            found[str(path.relative_to(package.parent))] = bad
    return found


def test_core_imports_no_ros_web_or_upper_layers():
    forbidden = ("rclpy", "aiohttp", "helireach_ros.ros", "helireach_ros.display", "helireach_ros.cli")
    assert offending("core", forbidden) == {}


def test_ros_layer_does_not_import_the_display_or_cli():
    assert offending("ros", ("helireach_ros.display", "helireach_ros.cli", "aiohttp")) == {}


@pytest.mark.parametrize("folder", ["core", "ros", "display", "cli"])
def test_subpackage_has_a_docstring(folder):
    init = PACKAGE / folder / "__init__.py"
    assert ast.get_docstring(ast.parse(init.read_text(encoding="utf-8"))), f"{init} needs a docstring"


def test_top_level_holds_only_the_package_init():
    assert sorted(path.name for path in PACKAGE.glob("*.py")) == ["__init__.py"]


def test_the_checker_sees_lazy_and_relative_imports(tmp_path):
    # The check must be able to fail: function-level and relative imports of forbidden modules are found.
    core = tmp_path / "helireach_ros" / "core"
    core.mkdir(parents=True)
    (core / "probe.py").write_text(
        "def f():\n    import rclpy\n    from ..ros import messages\n", encoding="utf-8"
    )
    assert offending("core", ("rclpy", "helireach_ros.ros"), tmp_path / "helireach_ros") == {
        "helireach_ros/core/probe.py": ["helireach_ros.ros", "helireach_ros.ros.messages", "rclpy"]
    }


def module_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Each module of the package and the package modules it imports at run time (function-level imports too)."""
    modules = {}
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(package.parent).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return {
        name: {other for other in imported_modules(path, package.parent, at_run_time=True) if other in modules} - {name}
        for name, path in modules.items()
    }


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        for other in sorted(graph[module]):
            if other not in index:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in stack:
                low[module] = min(low[module], index[other])
        if low[module] == index[module]:
            component = []
            while True:
                other = stack.pop()
                component.append(other)
                if other == module:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return cycles


def test_no_import_cycle_even_through_function_level_imports():
    assert import_cycles(module_graph()) == []


def test_the_cycle_check_finds_a_lazy_cycle_and_ignores_type_checking_imports(tmp_path):
    core = tmp_path / "helireach_ros" / "core"
    core.mkdir(parents=True)
    (tmp_path / "helireach_ros" / "__init__.py").write_text("", encoding="utf-8")
    (core / "__init__.py").write_text("", encoding="utf-8")
    (core / "a.py").write_text("from helireach_ros.core import b\n", encoding="utf-8")
    (core / "b.py").write_text("def f():\n    from helireach_ros.core import a\n", encoding="utf-8")
    (core / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from helireach_ros.core import a\n", encoding="utf-8"
    )
    graph = module_graph(tmp_path / "helireach_ros")
    assert import_cycles(graph) == [["helireach_ros.core.a", "helireach_ros.core.b"]]
    assert graph["helireach_ros.core.c"] == set()


# The core's packages in layers (docs/development.md): a module imports only its own package and lower layers, at
# run time and in functions alike. Packages of one layer do not import each other.
CORE_LAYERS = (
    ("shared",),  # units, resources, array_codec, status_values: the core's top-level modules
    ("aircraft", "mcap_log"),
    ("ocp",),
    ("evidence",),
    ("planning", "flight"),
    ("envelope", "estimation"),
    ("policies",),
    ("robustness",),
    ("workers",),
)


def core_package(module: str) -> str | None:
    """The core package of a module (``shared`` for the core's top-level modules), None outside the core."""
    parts = module.split(".")
    if parts[:2] != ["helireach_ros", "core"]:
        return None
    if len(parts) == 2 or (PACKAGE / "core" / f"{parts[2]}.py").exists():
        return "shared"
    return parts[2]


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    rank = {package: level for level, packages in enumerate(CORE_LAYERS) for package in packages}
    found = []
    for module, imported in sorted(graph.items()):
        package = core_package(module)
        if package is None:
            continue
        for other in sorted(imported):
            other_package = core_package(other)
            if other_package is None or other_package == package:
                continue
            if package not in rank or other_package not in rank or rank[other_package] >= rank[package]:
                found.append(f"{module} ({package}) imports {other} ({other_package})")
    return found


def test_every_core_package_has_a_layer_and_imports_only_lower_layers():
    packages = {path.name for path in (PACKAGE / "core").iterdir() if (path / "__init__.py").exists()}
    assert packages | {"shared"} == {package for layer in CORE_LAYERS for package in layer}
    assert layer_violations(module_graph()) == []


def test_the_layer_check_finds_an_upward_import():
    graph = {
        "helireach_ros.core.aircraft.model": {"helireach_ros.core.planning.planner", "helireach_ros.core.units"},
        "helireach_ros.core.planning.planner": {"helireach_ros.core.aircraft.model"},
    }
    assert layer_violations(graph) == [
        "helireach_ros.core.aircraft.model (aircraft) imports helireach_ros.core.planning.planner (planning)"
    ]
