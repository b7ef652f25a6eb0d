"""The failure path's plumbing: nodes served in the order they were added, and log lines without source lookups.

Real rclpy middleware (discovery off, same-process delivery), real ``/rosout``.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from rcl_interfaces.msg import Log
from rclpy.logging import LoggingSeverity
from rclpy.node import Node
from std_msgs.msg import Bool

from helireach_ros.ros import fast_logging
from helireach_ros.ros.added_order_executor import AddedOrderExecutor
from helireach_ros.ros.executors import create_executor

TOPIC = "/helireach_test/order"


def _served_order(context, names_in_add_order: list[str]) -> list[str]:
    """Adds one node per name (each subscribing to TOPIC) in the given order, publishes once, returns who ran first."""
    executor = AddedOrderExecutor(context=context)
    nodes = {name: Node(name, context=context) for name in sorted(names_in_add_order)}  # created in one order
    served: list[str] = []
    for name, node in nodes.items():
        node.create_subscription(Bool, TOPIC, lambda _message, name=name: served.append(name), 10)
    publisher_node = Node("order_publisher", context=context)
    publisher = publisher_node.create_publisher(Bool, TOPIC, 10)
    try:
        for name in names_in_add_order:
            assert executor.add_node(nodes[name])
        assert not executor.add_node(nodes[names_in_add_order[0]])  # twice: refused, the order unchanged
        assert [node.get_name() for node in executor.get_nodes()] == names_in_add_order
        deadline = time.monotonic() + 5.0
        while publisher.get_subscription_count() < len(nodes) and time.monotonic() < deadline:
            time.sleep(0.01)
        publisher.publish(Bool(data=True))
        while len(served) < len(nodes) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        return served
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in [*nodes.values(), publisher_node]:
            node.destroy_node()


@pytest.mark.parametrize(
    "order", [["node_a", "node_b", "node_c", "node_d"], ["node_d", "node_c", "node_b", "node_a"]], ids=str
)
def test_ready_callbacks_are_served_in_the_order_the_nodes_were_added(context, order) -> None:
    # Both orders must hold: rclpy's own set order is one fixed order per process, so it fails one of them.
    assert _served_order(context, order) == order


def test_a_removed_node_leaves_the_order_and_is_not_served(context) -> None:
    executor = create_executor("single_threaded", context)
    assert isinstance(executor, AddedOrderExecutor)
    first, second, third = (Node(name, context=context) for name in ("first", "second", "third"))
    try:
        for node in (first, second, third):
            executor.add_node(node)
        executor.remove_node(second)
        assert executor.get_nodes() == [first, third]
        executor.add_node(second)  # back in, at the end
        assert executor.get_nodes() == [first, third, second]
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in (first, second, third):
            node.destroy_node()


def test_an_executor_built_on_a_context_already_shut_down_raises_and_leaves_no_unraisable_error(monkeypatch) -> None:
    """A stop signal can shut the context down while a node script builds its executor: rclpy's constructor then
    raises before setting ``_sigint_gc``, and its ``__del__`` printed an "Exception ignored ... AttributeError"."""
    import gc
    import sys

    import rclpy
    from rclpy.context import Context

    unraisable: list[BaseException | None] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda report: unraisable.append(report.exc_value))
    stopped = Context()
    rclpy.init(context=stopped)
    stopped.shutdown()
    with pytest.raises(RuntimeError):
        AddedOrderExecutor(context=stopped)
    gc.collect()
    assert unraisable == []


def test_fast_log_lines_reach_rosout_with_their_caller(context) -> None:
    node = Node("fast_logging_test", context=context)
    listener = Node("rosout_listener", context=context)
    received: list[Log] = []
    listener.create_subscription(Log, "/rosout", received.append, 100)
    executor = AddedOrderExecutor(context=context)
    executor.add_node(listener)
    try:
        deadline = time.monotonic() + 5.0
        while listener.count_publishers("/rosout") < 2 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert fast_logging.warning(node.get_logger(), "engine failure #7: planning the landing")
        expected_line = _line_of("engine failure #7")
        assert fast_logging.info(node.get_logger(), "failure #7: SAFE")
        node.get_logger().set_level(LoggingSeverity.WARN)
        assert not fast_logging.info(node.get_logger(), "below the level: not logged")
        assert fast_logging.log_line(node.get_logger(), LoggingSeverity.ERROR, "an error line")
        while len([log for log in received if log.name == "fast_logging_test"]) < 3 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        listener.destroy_node()
    mine = [log for log in received if log.name == "fast_logging_test"]
    assert [(log.level, log.msg) for log in mine] == [
        (Log.WARN, "engine failure #7: planning the landing"),
        (Log.INFO, "failure #7: SAFE"),
        (Log.ERROR, "an error line"),
    ]
    warning = mine[0]
    # the caller, as rclpy's own logger reports it: this test function, this file, the calling line
    assert warning.function == "test_fast_log_lines_reach_rosout_with_their_caller"
    assert Path(warning.file) == Path(__file__).resolve()
    assert warning.line == expected_line


def _line_of(text: str) -> int:
    """The line of this file that logs ``text`` (the fast_logging.warning call above)."""
    for number, line in enumerate(Path(__file__).read_text(encoding="utf-8").splitlines(), start=1):
        if text in line and "fast_logging.warning" in line:
            return number
    raise AssertionError(f"no line logs {text!r}")


def test_the_composed_system_waits_on_no_parameter_event_handlers(no_ros_discovery, tmp_path) -> None:
    from rclpy.context import Context

    from helireach_ros.ros.bringup import build_system
    from helireach_ros.ros.qos import drop_parameter_event_handlers

    system = build_system(log_dir=tmp_path, context=Context())
    try:
        assert [node.get_name() for node in system.executor.get_nodes()] == [
            "helireach_monitor",
            "helireach_planner",
            "helireach_envelope_status",
            "helireach_recorder",
            "helireach_bringup",
        ]  # the failure path first, the recorder and the one-shot readiness announcement last
        for node in system.nodes:
            parameter_events = [p for p in node.publishers if p.topic_name == "/parameter_events"]
            assert len(parameter_events) == 1 and parameter_events[0].event_handlers == []
            handlers = {id(h) for p in node.publishers for h in p.event_handlers}
            handlers |= {id(h) for s in node.subscriptions for h in s.event_handlers}
            assert {id(w) for w in node.waitables} == handlers  # every waitable left is one of its own endpoints'
        fresh = Node("fresh", context=system.context)
        before = len(list(fresh.waitables))
        assert drop_parameter_event_handlers(fresh) == before == 2  # rclpy's default pair
        assert list(fresh.waitables) == [] and drop_parameter_event_handlers(fresh) == 0
        fresh.destroy_node()  # destroying its publisher after the handlers are gone is fine
    finally:
        system.shutdown()  # every node destroyed, no error
