"""What a helireach MCAP log is made of, without ROS: QoS profiles as rosbag2 stores them, the
records the readers return, the error every reader and writer raises, and rosbag2's constants.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import yaml

__all__ = ["LoggedMessage", "LoggedTopic", "McapLogError", "QosDescription"]


#: Metadata record name rosbag2 reads its bag metadata from (``rosbag2_storage_mcap``).
ROSBAG2_METADATA_NAME = "rosbag2"
#: rosbag2 bag metadata version written by Jazzy (9: QoS enums serialized as strings).
ROSBAG2_METADATA_VERSION = 9

MCAP_MAGIC = b"\x89MCAP0\r\n"
# rmw's RMW_DURATION_INFINITE as rosbag2 serializes it ({sec, nsec}); Fast DDS reports it for the
# deadline, lifespan and liveliness lease of a default publisher.
INFINITE_DURATION = {"sec": 9223372036, "nsec": 854775807}
INT64_MAX = 2**63 - 1
# rmw's policy enums: pre-Jazzy bags (metadata version <= 8) store the integer values.
_RMW_RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
_RMW_DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
_RMW_HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
_DEFAULT_DEPTH = 10  # rosbag2's default history depth when a profile does not carry one


class McapLogError(RuntimeError):
    """A log file cannot be written or read (truncated, corrupt, unknown type...).

    Attributes:
        path: The file concerned, when there is one.
    """

    def __init__(self, message: str, path: str | os.PathLike[str] | None = None) -> None:
        self.path = None if path is None else os.fspath(path)
        super().__init__(f"{self.path}: {message}" if self.path is not None else message)


@dataclass(frozen=True)
class QosDescription:
    """The QoS policies of a topic that matter for matching and latching.

    Attributes:
        reliability: ``"reliable"`` or ``"best_effort"``.
        durability: ``"volatile"`` or ``"transient_local"`` (latched).
        depth: KEEP_LAST history depth (> 0).
    """

    reliability: str = "reliable"
    durability: str = "volatile"
    depth: int = _DEFAULT_DEPTH

    def __post_init__(self) -> None:
        if self.reliability not in ("reliable", "best_effort"):
            raise ValueError(f"reliability must be 'reliable' or 'best_effort', not {self.reliability!r}")
        if self.durability not in ("volatile", "transient_local"):
            raise ValueError(f"durability must be 'volatile' or 'transient_local', not {self.durability!r}")
        if isinstance(self.depth, bool) or not isinstance(self.depth, int) or self.depth < 1:
            raise ValueError(f"depth must be a positive int, not {self.depth!r}")

    @property
    def latched(self) -> bool:
        """Whether late subscribers receive the last messages (TRANSIENT_LOCAL durability)."""
        return self.durability == "transient_local"

    def to_rosbag2_dict(self) -> dict[str, Any]:
        """Return one profile with the keys and value spellings of rosbag2_storage (Jazzy)."""
        return {
            "history": "keep_last",
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": dict(INFINITE_DURATION),
            "lifespan": dict(INFINITE_DURATION),
            "liveliness": "automatic",
            "liveliness_lease_duration": dict(INFINITE_DURATION),
            "avoid_ros_namespace_conventions": False,
        }

    def to_rosbag2_yaml(self) -> str:
        """Return the ``offered_qos_profiles`` YAML list (one profile) as rosbag2 writes it."""
        # yaml-cpp's Dump (used by rosbag2) emits block style without a trailing newline.
        return yaml.safe_dump([self.to_rosbag2_dict()], sort_keys=False, default_flow_style=False).rstrip("\n")

    @classmethod
    def from_rosbag2_yaml(cls, text: str) -> QosDescription:
        """Parse an ``offered_qos_profiles`` value (YAML list) written by rosbag2 or this module.

        The first profile is used (rosbag2 lists one per publisher). Both the Jazzy string enums
        and the older integer enums are accepted. A profile without a usable KEEP_LAST depth (rmw
        does not report the history of a remote publisher) gets rosbag2's default depth of 10.

        Args:
            text: The YAML text; empty means "no profile" and gives the defaults.

        Returns:
            The description of the first profile.

        Raises:
            ValueError: The text is not a list of QoS profiles or names an unknown policy.
        """
        try:
            profiles = yaml.safe_load(text) if text.strip() else []
        except yaml.YAMLError as exc:
            raise ValueError(f"offered_qos_profiles is not valid YAML: {exc}") from exc
        if profiles is None:
            profiles = []
        if not isinstance(profiles, list) or not all(isinstance(p, dict) for p in profiles):
            raise ValueError(f"offered_qos_profiles must be a YAML list of mappings, got {text!r}")
        if not profiles:
            return cls()
        profile = profiles[0]
        history = _policy(profile.get("history", "keep_last"), _RMW_HISTORY)
        depth = profile.get("depth", 0)
        if history != "keep_last" or not isinstance(depth, int) or depth < 1:
            depth = _DEFAULT_DEPTH
        # Collapse rmw's other values onto the two that matter: system default and unknown are
        # RELIABLE/VOLATILE in every Tier-1 rmw; "best available" turns into the stronger policy.
        reliability = _policy(profile.get("reliability", "reliable"), _RMW_RELIABILITY)
        durability = _policy(profile.get("durability", "volatile"), _RMW_DURABILITY)
        return cls(
            reliability="best_effort" if reliability == "best_effort" else "reliable",
            durability="transient_local" if durability in ("transient_local", "best_available") else "volatile",
            depth=depth,
        )


def _policy(value: object, names: Mapping[int, str]) -> str:
    if isinstance(value, int) and not isinstance(value, bool):
        if value not in names:
            raise ValueError(f"unsupported QoS policy value {value}")
        return names[value]
    text = str(value).lower()
    if text not in names.values():
        raise ValueError(f"unsupported QoS policy value {value!r}")
    return text


class LoggedMessage(NamedTuple):
    """One message read back from a log.

    Attributes:
        topic: Topic name.
        type_name: ``pkg/msg/Type``.
        cdr: The serialized message, as rmw delivered it.
        log_time_ns: Receive time (recorder clock), ns since the epoch.
        publish_time_ns: Publish time reported by the middleware, ns since the epoch.
        qos: The QoS the publisher offered.
    """

    topic: str
    type_name: str
    cdr: bytes
    log_time_ns: int
    publish_time_ns: int
    qos: QosDescription


class LoggedTopic(NamedTuple):
    """A topic present in a log.

    Attributes:
        type_name: ``pkg/msg/Type``.
        qos: The QoS the publisher offered.
        message_count: Messages logged on the topic.
    """

    type_name: str
    qos: QosDescription
    message_count: int


# --- message definitions, the way rosbag2's LocalMessageDefinitionSource builds them -------------

# Field types in a .msg file ("foo_msgs/Bar" in "foo_msgs/Bar[] bar"); same pattern as rosbag2.
