"""Named positions in the model's state vector (y, v, Ω, h, z, P), so that no code indexes it by a bare number.

A module of its own, without CasADi, so that light readers (an envelope's nearest plan, a node's readings) can name the
components too. The conventions are :mod:`helireach_ros.core.aircraft.model`'s (SI; y positive down).
"""

from __future__ import annotations

from enum import IntEnum

__all__ = ["StateIndex"]


class StateIndex(IntEnum):
    """The position of each component in the state vector (y, v, Ω, h, z, P): the order of
    :data:`~helireach_ros.core.aircraft.model.STATE_NAMES`."""

    DESCENT_RATE = 0  # y, m/s, positive down
    FORWARD_SPEED = 1  # v, m/s
    ROTOR_SPEED = 2  # Ω, rad/s
    HEIGHT = 3  # h, m
    DISTANCE = 4  # z, m
    ENGINE_POWER = 5  # P, W
