"""What a bag holds, as values: its topics (connections), messages, damage and summary."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from eddiebot.core.qos import QoSProfile
from eddiebot.msgs import TYPESTORE, deserialize, load_type

__all__ = [
    "BagConnection",
    "BagInfo",
    "BagMessage",
    "BagProblem",
    "ServiceSummary",
    "TopicSummary",
    "ensure_type",
    "is_service_event_topic",
    "split_services",
]

#: The topic a service's events go to (rcl's RCL_SERVICE_INTROSPECTION_TOPIC_POSTFIX).
SERVICE_EVENT_SUFFIX = "/_service_event"


@dataclass(frozen=True)
class BagConnection:
    """One topic of a bag: type, definition (as stored), hash and offered QoS."""

    topic: str
    type_name: str
    msgdef: str = ""
    msgdef_format: str = "ros2msg"
    type_hash: str = ""
    qos: tuple[QoSProfile, ...] = ()
    serialization_format: str = "cdr"

    @property
    def transient_local(self) -> bool:
        return any(q.transient_local for q in self.qos)


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: CDR bytes received at ``timestamp`` (ns)."""

    connection: BagConnection
    timestamp: int
    data: bytes

    @property
    def topic(self) -> str:
        return self.connection.topic

    def decode(self) -> Any:
        """The message object (types the store lacks are registered from the bag)."""
        ensure_type(self.connection)
        return deserialize(self.data, self.connection.type_name)


@dataclass(frozen=True)
class BagProblem:
    """Where and why reading a bag stopped or skipped data."""

    file: Path
    offset: int | None
    message_index: int
    reason: str

    def __str__(self) -> str:
        where = f"byte {self.offset}" if self.offset is not None else "position unknown"
        return f"{self.file}: {where}, after message #{self.message_index}: {self.reason}"


def ensure_type(conn: BagConnection) -> None:
    """Register ``conn``'s type from the bag's own definition if our store lacks it."""
    if conn.type_name in TYPESTORE.types:
        return
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    if not conn.msgdef:  # an empty schema: perhaps an interface file describes it
        load_type(conn.type_name)
        return
    if conn.msgdef_format in ("ros2idl", "omgidl"):
        types = get_types_from_idl(conn.msgdef)
    else:
        types = get_types_from_msg(conn.msgdef, conn.type_name)
    TYPESTORE.register(types)


@dataclass
class TopicSummary:
    """One line of ``bag info``: a topic, its type and how many messages it has."""

    name: str
    type_name: str
    count: int
    serialization_format: str = "cdr"
    qos: tuple[QoSProfile, ...] = ()


@dataclass
class ServiceSummary:
    """One service line of ``bag info``: a service recorded as its event topic."""

    name: str
    type_name: str
    event_count: int
    serialization_format: str = "cdr"


def is_service_event_topic(name: str, type_name: str) -> bool:
    """Whether ``name`` of ``type_name`` carries a service's events (rosbag2's test: the name
    ends in ``/_service_event`` and the type is ``<pkg>/srv/<Service>_Event``)."""
    return (len(name) > len(SERVICE_EVENT_SUFFIX) and name.endswith(SERVICE_EVENT_SUFFIX)
            and "/srv/" in type_name and len(type_name) > len("_Event")
            and type_name.endswith("_Event"))


def split_services(
    topics: list[TopicSummary],
) -> tuple[list[TopicSummary], list[ServiceSummary]]:
    """Topics without the service event topics, and those as services (name and type of the
    service, as ``ros2 bag info`` lists them)."""
    plain: list[TopicSummary] = []
    services: list[ServiceSummary] = []
    for t in topics:
        if is_service_event_topic(t.name, t.type_name):
            services.append(ServiceSummary(t.name[:-len(SERVICE_EVENT_SUFFIX)],
                                           t.type_name[:-len("_Event")], t.count,
                                           t.serialization_format))
        else:
            plain.append(t)
    return plain, services


@dataclass
class BagInfo:
    """What ``bag_info`` found: files, storage, size, time span, topics, damage."""

    path: Path
    files: list[Path]
    storage: str
    size_bytes: int
    message_count: int
    start_ns: int
    end_ns: int
    topics: list[TopicSummary]
    problems: list[BagProblem] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: services recorded as their event topics (``ros2 bag record --services``)
    services: list[ServiceSummary] = field(default_factory=list)
    #: the ROS distribution that wrote the bag ("" when the bag does not say)
    ros_distro: str = ""

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns)

    @property
    def topic_message_count(self) -> int:
        """Messages on topics, without service events (what ``ros2 bag info`` counts)."""
        return self.message_count - sum(s.event_count for s in self.services)

    @property
    def complete(self) -> bool:
        return not self.problems
