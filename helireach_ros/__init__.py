"""helireach_ros: can a helicopter still land safely after an engine failure, and how?

The numerical core (airframe, model, collocation, transcriptions, planner, verification, envelope)
imports no ROS; the ROS 2 nodes live in :mod:`helireach_ros.nodes`.
"""

__version__ = "0.1.0"
