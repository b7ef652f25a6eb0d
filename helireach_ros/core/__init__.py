"""The ROS-free core: model, transcriptions, planner, verification, envelopes, simulation, logs, policies.

Everything a landing decision needs lives here and runs as a plain Python library (and behind the
``helireach`` CLI): the airframe and its units, the paper's model, the collocation transcriptions, the
NLP planner and its independent CVODES replay, H-V envelopes (data model, computation, plots), the
simulated vehicle and the lock-step closed loop, the MCAP log writer/reader, and the policies the nodes
apply (re-planning, fallbacks). Modules here may import numpy, CasADi, yaml, matplotlib, mcap and Dask,
and each other; never ``rclpy``, ``aiohttp``, or anything under :mod:`helireach_ros.ros`,
:mod:`helireach_ros.display` or :mod:`helireach_ros.cli` (``test/test_layout.py`` checks it). A new
function that needs no ROS belongs here.
"""
