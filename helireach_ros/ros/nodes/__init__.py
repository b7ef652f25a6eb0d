"""ROS 2 nodes of helireach_ros (each module has a ``main`` entry point)."""
