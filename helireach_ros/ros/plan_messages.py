"""A plan's trajectory and path messages, built once (e.g. ahead of the failure, for the standby plan).

On a failure the planner publishes the standby plan from its executor callback; building its messages there
(a ``JointTrajectory`` of ~20 points and a ``nav_msgs/Path`` of ~60 poses, ~1.5 ms of Python) held up every
callback behind it, the trajectory's subscribers included. The planner builds them instead when the live
verdict that becomes the standby arrives, on the solver pool's thread, and the failure callback only publishes
them (:class:`PlanMessages`, checked against the plan, stamp and frames it is published for). They are serialized
(CDR) then too: publishing the bytes skips rclpy's Python-to-C conversion of every pose in the callback (the
path alone took ~0.8 ms of it in the composed system).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from nav_msgs.msg import Path
from rclpy.serialization import serialize_message
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.ros import messages as rm

__all__ = ["PlanMessages", "plan_messages"]


@dataclass(frozen=True)
class PlanMessages:
    """The ``/helireach/landing_trajectory`` and ``/helireach/landing_path`` messages of one plan.

    Attributes:
        plan: the plan they were built from (compared by identity).
        stamp_ns: the stamp of the state the plan starts from (both headers).
        frame: the vehicle frame of the trajectory. world_frame: the frame of the path.
        trajectory: the controls (:func:`~helireach_ros.ros.messages.trajectory_message`).
        path: the predicted positions (:func:`~helireach_ros.ros.messages.path_message`).
        trajectory_cdr, path_cdr: the same two messages serialized, for ``publisher.publish`` as they are.
    """

    plan: Any
    stamp_ns: int
    frame: str
    world_frame: str
    trajectory: JointTrajectory
    path: Path
    trajectory_cdr: bytes
    path_cdr: bytes

    def matches(self, plan: Any, stamp_ns: int, frame: str, world_frame: str) -> bool:
        """Whether these are the messages of ``plan`` published with this stamp and these frames."""
        return (
            self.plan is plan and self.stamp_ns == stamp_ns and self.frame == frame and self.world_frame == world_frame
        )


def plan_messages(plan: Any, stamp_ns: int, frame: str, world_frame: str) -> PlanMessages:
    """Builds a converged plan's trajectory (pitch in ``frame``) and path (in ``world_frame``), stamped ``stamp_ns``."""
    trajectory = rm.trajectory_message(plan, stamp_ns, frame)
    path = rm.path_message(plan.times, plan.states, stamp_ns, world_frame, plan.controls[1])
    return PlanMessages(
        plan, stamp_ns, frame, world_frame, trajectory, path, serialize_message(trajectory), serialize_message(path)
    )
