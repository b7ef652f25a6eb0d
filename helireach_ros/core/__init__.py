"""The ROS-free core: one package per concept, in layers that import only downwards.

Everything a landing decision needs lives here and runs as a plain Python library (and behind the ``helireach``
CLI). From the bottom: the shared top-level modules (units, resources, array_codec, status_values);
:mod:`.aircraft` (airframe, model, inflow) and :mod:`.mcap_log`; :mod:`.ocp` (transcriptions, settings, compiled
NLP, linear solver); :mod:`.evidence` (replay, flyability, verdicts); :mod:`.planning` (planner, fallback) and
:mod:`.flight` (simulated vehicle, uncertainty set); :mod:`.envelope` and :mod:`.estimation`; :mod:`.policies` (the
nodes' decisions); :mod:`.robustness` (closed loop, robust verification); :mod:`.workers` (solver pool, the planner's
back-end). Modules here may import numpy, CasADi, yaml, matplotlib, mcap and Dask, their own package and lower layers;
never ``rclpy``, ``aiohttp``, or anything under :mod:`helireach_ros.ros`, :mod:`helireach_ros.display` or
:mod:`helireach_ros.cli` (``test/test_layout.py`` checks both). A new function that needs no ROS belongs here.
"""
