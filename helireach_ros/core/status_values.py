"""How the package's ``DiagnosticStatus`` contracts write and read their values: one rule per type.

Every value of a status topic (``msg_docs/``) is a string. Producers write with :func:`format_value`: booleans as
``true``/``false``, floats with round-trip precision (``repr``), everything else with ``str``. Consumers read flags with
:func:`parse_bool`, which accepts exactly what :func:`format_value` writes: a flag that is not ``true`` or ``false`` is
unknown (None), never guessed, so a flag cannot be written one way and read another.
ROS-free: the nodes, the display and the tests use the same functions, mostly through the typed contract of each
topic (:mod:`helireach_ros.core.status_contracts`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["FALSE", "TRUE", "format_value", "parse_bool"]

TRUE = "true"
FALSE = "false"


def format_value(value: Any) -> str:
    """A status value as its string: floats with round-trip precision, booleans as ``true``/``false``."""
    if isinstance(value, bool | np.bool_):
        return TRUE if value else FALSE
    if isinstance(value, float | np.floating):
        return repr(float(value))
    return str(value)


def parse_bool(text: str | None) -> bool | None:
    """``true`` → True, ``false`` → False, anything else (missing, ``1``, ``yes``, ``True``) → None: unknown."""
    if text == TRUE:
        return True
    if text == FALSE:
        return False
    return None
