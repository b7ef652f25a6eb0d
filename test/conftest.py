"""Shared test fixtures: ROS 2 discovery isolation, and SIGINT for the processes the tests start.

In-process tests turn discovery off; cross-process tests use LOCALHOST discovery on a domain id
that no other test of this run uses, spread by process id so that concurrent runs on one machine
are unlikely to meet (a meeting shows up as foreign messages, never as a silent pass).

A suite started as a background job (``make test &`` in a script) inherits SIGINT ignored, and so would
every node it starts: a node that ignores SIGINT during its start-up runs on, and the tests that stop
nodes with SIGINT would hang. The suite's own process therefore takes Python's default SIGINT handler,
which its children's exec resets to the default action.
"""

from __future__ import annotations

import itertools
import os
import signal

import pytest

from helireach_ros.core.aircraft.airframe import Airframe, load_airframe
from helireach_ros.core.ocp.settings import PlannerSettings, load_settings

if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

_NEXT_DOMAIN = itertools.count()
_DOMAIN_COUNT = 200  # ids 1..200 are valid for every RMW on Linux


def next_domain_id() -> int:
    """A ROS_DOMAIN_ID in 1..200, different for each call within this test run."""
    return 1 + (os.getpid() * 37 + next(_NEXT_DOMAIN)) % _DOMAIN_COUNT


@pytest.fixture
def localhost_ros_domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """LOCALHOST discovery on a domain of this test's own (this process and its children)."""
    domain_id = next_domain_id()
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain_id))
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    return domain_id


@pytest.fixture
def no_ros_discovery(monkeypatch: pytest.MonkeyPatch) -> None:
    """No discovery beyond this process (same-process delivery still works)."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(next_domain_id()))


@pytest.fixture
def context(no_ros_discovery):
    """A fresh rclpy context with the default node parameters (config/nodes.yaml), discovery off."""
    import rclpy
    from rclpy.context import Context

    from helireach_ros.ros.bringup import ros_arguments

    fresh = Context()
    rclpy.init(context=fresh, args=ros_arguments())
    yield fresh
    rclpy.try_shutdown(context=fresh)


@pytest.fixture(scope="session", autouse=True)
def envelope_solver_state_cache(tmp_path_factory: pytest.TempPathFactory):
    """The envelopes' solver-state cache of this run (this process and its children), not the user's: a test sees
    the shipped envelope as a fresh installation does (no cached solver state)."""
    from helireach_ros.core.envelope.data import SOLVER_STATE_CACHE_ENV

    previous = os.environ.get(SOLVER_STATE_CACHE_ENV)
    os.environ[SOLVER_STATE_CACHE_ENV] = str(tmp_path_factory.mktemp("envelope_solver_state"))
    yield
    if previous is None:
        os.environ.pop(SOLVER_STATE_CACHE_ENV, None)
    else:
        os.environ[SOLVER_STATE_CACHE_ENV] = previous


@pytest.fixture(scope="module")
def airframe() -> Airframe:
    """The default airframe, as shipped."""
    return load_airframe("uh60a_class")


@pytest.fixture(scope="module")
def settings() -> PlannerSettings:
    """The default planner settings (config/planner.yaml)."""
    return load_settings()


# Markers for the inner loop (`make test-fast` deselects them; `make test` and CI run everything). A test gets
# `system` when it uses the real middleware (a ROS context, a localhost domain, the display's ROS harness) and
# `browser` when it drives Chromium; whole files that start node processes, compile code, run the demo in real
# time or fly many closed loops are marked in their own `pytestmark`.
_SYSTEM_FIXTURES = {"context", "localhost_ros_domain", "ros"}


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        if fixtures & _SYSTEM_FIXTURES:
            item.add_marker(pytest.mark.system)
        if "browser" in fixtures:
            item.add_marker(pytest.mark.browser)
