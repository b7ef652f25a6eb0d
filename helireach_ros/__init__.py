"""helireach_ros: can a helicopter still land safely after an engine failure, and how?

Subpackages: :mod:`helireach_ros.core` (the ROS-free library: model, planner, verification, envelopes,
simulation, logs), :mod:`helireach_ros.ros` (topic contract, nodes, bringup, replay),
:mod:`helireach_ros.display` (the cockpit page) and :mod:`helireach_ros.cli` (the ``helireach`` command).
"""

__all__ = ["__version__"]

__version__ = "0.1.0"
