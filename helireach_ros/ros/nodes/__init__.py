"""ROS 2 nodes, one per module: monitor, envelope status, planner, simulated vehicle, recorder.

Each node file translates messages and parameters into :mod:`helireach_ros.core` calls and back, and
has a ``main(args=None)`` console entry point (``setup.py``). May import what :mod:`helireach_ros.ros`
may import.
"""
