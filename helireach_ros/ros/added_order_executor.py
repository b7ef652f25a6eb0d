"""A single-threaded executor that serves its nodes in the order they were added.

rclpy keeps an executor's nodes in a set, so which node's ready callbacks run first after a wait changes from
process to process (it follows the nodes' memory addresses). Measured in the composed system
(``bench/failure_latency.py``): when the status and recorder nodes happened to come before the planner, the
standby trajectory reached a subscriber in the same process 1–4 ms later. With the order fixed, the composed
system's order is its priority (:attr:`~helireach_ros.ros.bringup.HelireachSystem.nodes`): the failure path
first, the recorder last. Only the public ``add_node``/``remove_node``/``get_nodes`` are overridden; rclpy's
wait loop asks ``get_nodes`` for the nodes it serves, in that order.
"""

from __future__ import annotations

import threading

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

__all__ = ["AddedOrderExecutor"]


class AddedOrderExecutor(SingleThreadedExecutor):
    """``SingleThreadedExecutor`` whose ``get_nodes`` (and so its service order) is the order of ``add_node``."""

    # rclpy's Executor.__del__ reads this even when __init__ stopped before setting it (a stop signal that shuts the
    # context down while the executor is built makes its guard condition raise): without the default it printed an
    # "Exception ignored ... AttributeError" traceback on such a stop.
    _sigint_gc = None  # type: ignore[assignment]  # rclpy's attribute, absent until its __init__ sets it

    def __init__(self, *, context: Context | None = None) -> None:
        self._added: list[Node] = []
        self._added_lock = threading.RLock()  # re-entered: add_node sets node.executor, which calls add_node
        super().__init__(context=context)

    def add_node(self, node: Node) -> bool:
        with self._added_lock:
            added = super().add_node(node)
            if added:
                self._added.append(node)
        return added

    def remove_node(self, node: Node) -> None:
        with self._added_lock:
            super().remove_node(node)
            if node in self._added:
                self._added.remove(node)

    def get_nodes(self) -> list[Node]:
        with self._added_lock:
            present = set(super().get_nodes())
            return [node for node in self._added if node in present]
