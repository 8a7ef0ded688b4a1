"""Quality of service, with rclpy's names."""

from __future__ import annotations

import enum
from dataclasses import dataclass


class ReliabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class HistoryPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


QoSReliabilityPolicy = ReliabilityPolicy
QoSDurabilityPolicy = DurabilityPolicy
QoSHistoryPolicy = HistoryPolicy


@dataclass(frozen=True)
class QoSProfile:
    """Depth, reliability, durability and history, as ROS 2's QoS profile.

    ``KEEP_LAST`` with ``depth`` drops the oldest message when a subscriber's queue is full;
    ``TRANSIENT_LOCAL`` publishers keep their last ``depth`` messages for late joiners.
    """

    depth: int = 10
    reliability: ReliabilityPolicy = ReliabilityPolicy.RELIABLE
    durability: DurabilityPolicy = DurabilityPolicy.VOLATILE
    history: HistoryPolicy = HistoryPolicy.KEEP_LAST

    def __post_init__(self) -> None:
        if self.history == HistoryPolicy.KEEP_LAST and self.depth < 1:
            raise ValueError(f"QoS depth must be >= 1 with KEEP_LAST, got {self.depth}")

    @property
    def transient_local(self) -> bool:
        return self.durability == DurabilityPolicy.TRANSIENT_LOCAL

    @property
    def queue_size(self) -> int | None:
        """Bound of a subscriber's queue (None: unbounded, KEEP_ALL)."""
        return None if self.history == HistoryPolicy.KEEP_ALL else self.depth


def as_qos(qos: QoSProfile | int) -> QoSProfile:
    """Accept a bare depth, as rclpy does."""
    if isinstance(qos, QoSProfile):
        return qos
    if isinstance(qos, int) and not isinstance(qos, bool):
        return QoSProfile(depth=qos)
    raise TypeError(f"expected a QoSProfile or an int depth, got {type(qos).__name__}")


qos_profile_system_default = QoSProfile()
qos_profile_sensor_data = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
qos_profile_services_default = QoSProfile(depth=10)
qos_profile_parameters = QoSProfile(depth=1000)
#: /map, /tf_static, /robot_description: late subscribers get the last message.
qos_profile_latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
