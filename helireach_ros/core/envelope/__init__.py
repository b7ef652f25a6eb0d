"""H-V envelopes: the file format and conservative queries (:mod:`.data`), their parallel computation
(:mod:`.compute`; grid specifications in :mod:`.grid`, the local-process and Dask executors in
:mod:`.workers`, progress display in :mod:`.progress`), and figures (:mod:`.plot`). ROS-free, like all
of :mod:`helireach_ros.core`.
"""
