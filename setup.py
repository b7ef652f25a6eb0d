"""ament_python package definition for helireach_ros (also installs with plain pip)."""

import os
from glob import glob

from setuptools import find_packages, setup

package_name = "helireach_ros"


def _files(pattern: str) -> list[str]:
    return sorted(path for path in glob(pattern, recursive=True) if not path.endswith("/"))


def _requirements(path: str) -> list[str]:
    """The requirement lines of a pip requirements file (comments and blank lines dropped)."""
    with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), path)) as lines:
        return [line.split("#", 1)[0].strip() for line in lines if line.split("#", 1)[0].strip()]


setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    package_data={package_name + ".display": ["web/*"], package_name + ".core.ocp": ["block_ldl.c"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", _files("config/*.yaml")),
        ("share/" + package_name + "/config/airframes", _files("config/airframes/*.yaml")),
        ("share/" + package_name + "/data/envelopes", _files("data/envelopes/*")),
        ("share/" + package_name + "/config/scenarios", _files("config/scenarios/*.yaml")),
        ("share/" + package_name + "/msg_docs", _files("msg_docs/*.md")),
    ],
    # the runtime requirements (requirements.txt); the tests' are in requirements-test.txt
    install_requires=_requirements("requirements.txt"),
    zip_safe=True,
    maintainer="helireach_ros maintainers",
    maintainer_email="maintainers@helireach.invalid",
    description="Helicopter engine-failure reachability: verified landing plans, H-V envelopes, ROS 2 nodes.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "helireach = helireach_ros.cli.main:main",
            "helireach_monitor = helireach_ros.ros.nodes.monitor:main",
            "helireach_envelope_status = helireach_ros.ros.nodes.envelope_status:main",
            "helireach_planner = helireach_ros.ros.nodes.planner_node:main",
            "helireach_sim_vehicle = helireach_ros.ros.nodes.sim_vehicle:main",
            "helireach_recorder = helireach_ros.ros.nodes.recorder:main",
            "helireach_display = helireach_ros.display.node:main",
            "helireach_replay = helireach_ros.ros.replay:main",
        ],
    },
)
