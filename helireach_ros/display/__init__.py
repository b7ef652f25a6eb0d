"""The cockpit display: a ROS node (:mod:`.node`) that turns the helireach topics into JSON sections
(:mod:`.sections`) and an aiohttp web server (:mod:`.server`) that pushes them to the page in
``web/``. May import ``rclpy``, ``aiohttp``, :mod:`helireach_ros.ros` and :mod:`helireach_ros.core`;
nothing else in the package imports it (only the CLI and the demo start it).
"""
