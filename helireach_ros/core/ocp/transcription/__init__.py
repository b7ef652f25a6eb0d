"""NLP transcriptions of the landing problem: the common interface and terminal cost (:mod:`.base`),
the paper's time-freeze LGR scheme (:mod:`.paper`) and the default replay-verified Radau scheme
(:mod:`.verified`). ROS-free, like all of :mod:`helireach_ros.core`.
"""
