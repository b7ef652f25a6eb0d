"""The nodes' ROS-free policies: failure episodes and supervision, safety status, live reachability, inputs."""
