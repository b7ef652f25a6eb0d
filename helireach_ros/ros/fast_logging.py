"""Log lines on the failure path without rclpy's per-call source lookup.

rclpy's ``RcutilsLogger.log`` identifies its caller with ``inspect.getframeinfo``, which fetches the caller's
source line (``linecache``) on every call: measured here ~0.36 ms per line, against ~4 µs for the rcutils call that
writes it (console, log file and ``/rosout``). The failure callbacks of the monitor and the planner log two or three
lines each, and every one of them held the single-threaded executor, so the standby trajectory's subscribers in
the composed system waited ~1–2 ms behind log lines (``bench/failure_latency.py``). The known remedy
(rai-opensource/synchros2#84) is to identify the caller from its frame alone; :func:`log_line` does that and makes
the same rcutils call rclpy makes, so the line, its severity, logger name, function, file and line number are
what ``logger.info(...)`` would have written. Filters (``throttle_duration_sec``, ``once``, ...) are not
supported: lines that need them keep using the logger's own methods.

If this rclpy lacks the private rcutils binding, :func:`log_line` falls back to the logger's ``log`` (slower,
same line).
"""

from __future__ import annotations

import os
import sys
from typing import Any

from rclpy.logging import LoggingSeverity

__all__ = ["info", "log_line", "warning"]

try:  # the binding rclpy's own RcutilsLogger.log calls (rclpy/impl/rcutils_logger.py)
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    _RCUTILS_LOG = _rclpy.rclpy_logging_rcutils_log
    _ENABLED_FOR = _rclpy.rclpy_logging_logger_is_enabled_for
except (ImportError, AttributeError):  # pragma: no cover - another rclpy
    _RCUTILS_LOG = _ENABLED_FOR = None


def log_line(logger: Any, severity: LoggingSeverity, message: str, _depth: int = 1) -> bool:
    """Logs ``message`` at ``severity`` on ``logger`` (an rclpy logger, e.g. ``node.get_logger()``).

    Returns whether the line was logged (False: the severity is below the logger's level).
    """
    if _RCUTILS_LOG is None:
        return bool(logger.log(message, severity))
    if not _ENABLED_FOR(logger.name, severity):
        return False
    caller = sys._getframe(_depth)  # the frame alone: no source lookup
    code = caller.f_code
    _RCUTILS_LOG(severity, logger.name, message, code.co_name, os.path.abspath(code.co_filename), caller.f_lineno)
    return True


def info(logger: Any, message: str) -> bool:
    """:func:`log_line` at INFO."""
    return log_line(logger, LoggingSeverity.INFO, message, _depth=2)


def warning(logger: Any, message: str) -> bool:
    """:func:`log_line` at WARN."""
    return log_line(logger, LoggingSeverity.WARN, message, _depth=2)
