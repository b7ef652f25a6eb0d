"""Run logs as MCAP files in rosbag2's layout, without ROS: QoS descriptions and record types
(:mod:`.records`), message schemas read from the installed interface files (:mod:`.schemas`), the
crash-safe writer (:mod:`.writer`), the readers, tolerant of truncated files (:mod:`.reader`), and the
recovery of a killed recorder's file into a finished one (:mod:`.recover`).
ROS-free, like all of :mod:`helireach_ros.core` (the ROS recorder node wraps the writer).
"""

from helireach_ros.core.mcap_log.reader import (
    LogOverview,
    read_log,
    read_log_metadata,
    read_log_overview,
    read_log_topics,
)
from helireach_ros.core.mcap_log.records import LoggedMessage, LoggedTopic, McapLogError, QosDescription
from helireach_ros.core.mcap_log.recover import (
    RecoveryReport,
    default_recovered_path,
    is_finished_log,
    log_damage,
    recover_log,
)
from helireach_ros.core.mcap_log.schemas import message_definition, type_description_hash
from helireach_ros.core.mcap_log.writer import McapLogWriter

__all__ = [
    "LogOverview",
    "LoggedMessage",
    "LoggedTopic",
    "McapLogError",
    "McapLogWriter",
    "QosDescription",
    "RecoveryReport",
    "default_recovered_path",
    "is_finished_log",
    "log_damage",
    "message_definition",
    "read_log",
    "read_log_metadata",
    "read_log_overview",
    "read_log_topics",
    "recover_log",
    "type_description_hash",
]
