"""The ROS 2 layer: thin translation between messages and core calls.

The topic contract and message conversions (:mod:`.messages`, documented in ``msg_docs/``), parameter
declaration and validation (:mod:`.parameters`), executors and the node runner (:mod:`.executors`), the
composed system (:mod:`.bringup`), log replay (:mod:`.replay`), and one node per file in :mod:`.nodes`.
Modules here may import ``rclpy``, the standard message packages and :mod:`helireach_ros.core`; never
:mod:`helireach_ros.display` or :mod:`helireach_ros.cli`. Policy that can be tested without ROS belongs
in the core, not here.
"""
