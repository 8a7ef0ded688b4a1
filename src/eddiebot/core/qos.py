"""Quality of service, with rclpy's names.

Deadline, lifespan and liveliness lease durations are ``Duration`` values; a zero duration
means "not set", which ROS 2 (and rmw_zenoh) take as infinite. ``qos_check_compatible``
answers whether a publisher's offer meets a subscription's request, as rclpy's does.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from eddiebot.core.time import Duration


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


class LivelinessPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_TOPIC = 3


class QoSPolicyKind(enum.IntEnum):
    """Which policy made a pair incompatible (rclpy's ``QoSPolicyKind``)."""

    INVALID = 1 << 0
    DURABILITY = 1 << 1
    DEADLINE = 1 << 2
    LIVELINESS = 1 << 3
    RELIABILITY = 1 << 4
    HISTORY = 1 << 5
    LIFESPAN = 1 << 6
    DEPTH = 1 << 7
    LIVELINESS_LEASE_DURATION = 1 << 8
    AVOID_ROS_NAMESPACE_CONVENTIONS = 1 << 9


class QoSCompatibility(enum.IntEnum):
    OK = 0
    WARNING = 1
    ERROR = 2


QoSReliabilityPolicy = ReliabilityPolicy
QoSDurabilityPolicy = DurabilityPolicy
QoSHistoryPolicy = HistoryPolicy
QoSLivelinessPolicy = LivelinessPolicy

#: rmw's "infinite" duration (RMW_DURATION_INFINITE: 9223372036 s 854775807 ns)
INFINITE_NS = 9223372036 * 1_000_000_000 + 854775807


def duration_ns(d: Duration | None) -> int | None:
    """Nanoseconds of a QoS duration; None when it is not set (0) or infinite."""
    if d is None or d.nanoseconds <= 0 or d.nanoseconds >= INFINITE_NS:
        return None
    return d.nanoseconds


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
    #: a publisher publishes, a subscription receives, at least once per deadline
    deadline: Duration = field(default_factory=Duration)
    #: a message older than this (since it was published) is not delivered
    lifespan: Duration = field(default_factory=Duration)
    liveliness: LivelinessPolicy = LivelinessPolicy.SYSTEM_DEFAULT
    #: a MANUAL_BY_TOPIC publisher that neither publishes nor asserts its liveliness for
    #: this long is not alive
    liveliness_lease_duration: Duration = field(default_factory=Duration)
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self) -> None:
        if self.history == HistoryPolicy.KEEP_LAST and self.depth < 1:
            raise ValueError(f"QoS depth must be >= 1 with KEEP_LAST, got {self.depth}")
        for name in ("deadline", "lifespan", "liveliness_lease_duration"):
            value = getattr(self, name)
            if not isinstance(value, Duration):
                raise TypeError(f"QoS {name} must be a Duration, got {type(value).__name__}")
            if value.nanoseconds < 0:
                raise ValueError(f"QoS {name} must not be negative, got {value}")

    @property
    def transient_local(self) -> bool:
        return self.durability == DurabilityPolicy.TRANSIENT_LOCAL

    @property
    def queue_size(self) -> int | None:
        """Bound of a subscriber's queue (None: unbounded, KEEP_ALL)."""
        return None if self.history == HistoryPolicy.KEEP_ALL else self.depth


def _manual(qos: QoSProfile) -> bool:
    return qos.liveliness == LivelinessPolicy.MANUAL_BY_TOPIC


def qos_check_compatible(
    publisher_qos: QoSProfile, subscription_qos: QoSProfile
) -> tuple[QoSCompatibility, str, QoSPolicyKind | None]:
    """Does the publisher's offer meet the subscription's request? (compatibility, reason,
    the first incompatible policy) as rmw's ``qos_profile_check_compatible`` decides."""
    def error(policy: QoSPolicyKind, reason: str) -> tuple[QoSCompatibility, str, QoSPolicyKind]:
        return QoSCompatibility.ERROR, reason, policy

    if (publisher_qos.reliability == ReliabilityPolicy.BEST_EFFORT
            and subscription_qos.reliability == ReliabilityPolicy.RELIABLE):
        return error(QoSPolicyKind.RELIABILITY,
                     "best effort publisher and reliable subscription")
    if (publisher_qos.durability == DurabilityPolicy.VOLATILE
            and subscription_qos.durability == DurabilityPolicy.TRANSIENT_LOCAL):
        return error(QoSPolicyKind.DURABILITY,
                     "volatile publisher and transient local subscription")
    pub_deadline, sub_deadline = duration_ns(publisher_qos.deadline), duration_ns(subscription_qos.deadline)
    if sub_deadline is not None and (pub_deadline is None or pub_deadline > sub_deadline):
        return error(QoSPolicyKind.DEADLINE, "subscription deadline is less than publisher deadline")
    if not _manual(publisher_qos) and _manual(subscription_qos):
        return error(QoSPolicyKind.LIVELINESS,
                     "publisher's liveliness is automatic and subscription's is manual by topic")
    pub_lease = duration_ns(publisher_qos.liveliness_lease_duration)
    sub_lease = duration_ns(subscription_qos.liveliness_lease_duration)
    if sub_lease is not None and (pub_lease is None or pub_lease > sub_lease):
        return error(QoSPolicyKind.LIVELINESS_LEASE_DURATION,
                     "subscription liveliness lease duration is less than publisher's")
    return QoSCompatibility.OK, "", None


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
