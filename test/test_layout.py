"""The package layout keeps its promise: the core imports no ROS or web server, ROS code no display code.

Imports are read from the source with :mod:`ast` (top level and inside functions alike), so a lazy
``import rclpy`` inside a core function is caught too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "helireach_ros"


def imported_modules(path: Path, root: Path = PACKAGE.parent) -> set[str]:
    """Every module a file imports, absolute names (relative imports resolved against its package)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = ".".join(path.relative_to(root).with_suffix("").parts[:-1])
    names: set[str] = set()
    for node in ast.walk(tree):
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
