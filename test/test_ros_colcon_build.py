"""The package builds with ``colcon build`` (colcon-core + colcon-ros from PyPI) and its install tree works.

The source tree is copied into a temporary workspace (``src/helireach_ros``) so the build leaves no
``build/``, ``install/`` or ``log/`` behind. Skipped only if colcon is not installed.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.build]

ROOT = Path(__file__).resolve().parent.parent
NODE_SCRIPTS = (
    "helireach_monitor",
    "helireach_envelope_status",
    "helireach_planner",
    "helireach_sim_vehicle",
    "helireach_recorder",
)
_NOT_SOURCE = shutil.ignore_patterns(
    ".venv", ".git", "build", "install", "log", "out", "__pycache__", "*.egg-info", ".pytest_cache", ".ruff_cache"
)


def colcon_executable() -> Path:
    try:
        import colcon_core  # noqa: F401
        import colcon_ros  # noqa: F401
    except ImportError as error:
        pytest.skip(f"colcon is not installed ({error}); pip install colcon-core colcon-ros")
    return Path(sys.executable).parent / "colcon"


def test_colcon_build_installs_the_package_its_scripts_and_data(tmp_path: Path) -> None:
    colcon = colcon_executable()
    shutil.copytree(ROOT, tmp_path / "src" / "helireach_ros", ignore=_NOT_SOURCE)
    environment = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    build = subprocess.run(
        [str(colcon), "build", "--event-handlers", "console_direct-"],
        cwd=tmp_path,
        env=environment,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert build.returncode == 0, build.stdout + build.stderr
    prefix = tmp_path / "install" / "helireach_ros"
    share = prefix / "share" / "helireach_ros"
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "helireach_ros").is_file()
    assert (share / "package.xml").is_file()
    for relative in (
        "config/nodes.yaml",
        "config/planner.yaml",
        "config/scenarios/demo_500ft_75kt.yaml",
        "config/airframes/uh60a_class.yaml",
        "data/envelopes/uh60a_class_total_power_loss.npz",
    ):
        assert (share / relative).is_file(), relative
    assert sorted(path.name for path in (share / "msg_docs").glob("*.md")), "msg_docs not installed"
    for script in NODE_SCRIPTS:
        assert os.access(prefix / "lib" / "helireach_ros" / script, os.X_OK), script
    # The installed package finds its data through the ament index (what `source install/setup.bash` sets up).
    site_packages = next(prefix.glob("lib/python3*/site-packages"))
    probe = subprocess.run(
        [
            sys.executable,
            "-c",
            "import helireach_ros.core.resources as r; print(r.__file__); print(r.config_path('nodes.yaml'))",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env=dict(environment, PYTHONPATH=str(site_packages), AMENT_PREFIX_PATH=str(prefix)),
    )
    assert probe.returncode == 0, probe.stderr
    module_file, config_file = probe.stdout.split()
    assert Path(module_file).is_relative_to(prefix)
    assert Path(config_file) == share / "config" / "nodes.yaml"
