"""The Zenoh key space, laid out as ROS 2's own Zenoh middleware (rmw_zenoh) lays it out.

Everything that names a key lives here, so the layout is one module away from rmw_zenoh's:

- data and service keys: ``<domain>/<name without leading slash>/<dds type>/<type hash>``,
  e.g. ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...``;
- liveliness tokens: ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/
  <namespace>/<node>[/<topic>/<dds type>/<type hash>/<qos>]`` with ``/`` in names mangled
  to ``%`` and kinds ``NN`` (node), ``MP``/``MS`` (publisher/subscription), ``SS``/``SC``
  (service server/client);
- the per-sample attachment: sequence number (int64 LE), source timestamp (int64 ns LE),
  GID length (one byte, 16) and the 16-byte GID.
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass
from typing import Any

from eddiebot.core._xxh3 import xxh3_128
from eddiebot.core.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
    duration_ns,
)
from eddiebot.core.time import Duration
from eddiebot.core.type_description import describe, rihs01, service_fielddefs
from eddiebot.msgs import TYPESTORE, UnknownTypeError, load_type, normalize_type_name, type_hash

__all__ = [
    "ADMIN_SPACE",
    "ATTACHMENT",
    "UNKNOWN_TYPE_HASH",
    "GraphEntity",
    "dds_type_name",
    "decode_attachment",
    "encode_attachment",
    "entity_gid",
    "liveliness_key",
    "liveliness_prefix",
    "mangle",
    "message_type_hash",
    "node_liveliness_key",
    "parse_liveliness_key",
    "qos_from_keyexpr",
    "qos_to_keyexpr",
    "ros_type_name",
    "service_hash_from",
    "service_type_hash",
    "topic_key",
    "topic_wildcard_key",
    "unmangle",
]

ADMIN_SPACE = "@ros2_lv"
#: int64 sequence, int64 timestamp (ns since the epoch), uint8 GID length, 16-byte GID.
ATTACHMENT = struct.Struct("<qqB16s")

# rmw_zenoh's defaults: a field equal to its default is left empty in the QoS key.
_DEFAULT_RELIABILITY = int(ReliabilityPolicy.RELIABLE)
_DEFAULT_DURABILITY = int(DurabilityPolicy.VOLATILE)
_DEFAULT_HISTORY = int(HistoryPolicy.KEEP_LAST)
_DEFAULT_DEPTH = 42
_DEFAULT_LIVELINESS = int(LivelinessPolicy.AUTOMATIC)


def mangle(name: str) -> str:
    """``/`` → ``%`` (liveliness tokens carry names as one key chunk)."""
    return name.replace("/", "%") if name else "%"


def unmangle(chunk: str) -> str:
    return chunk.replace("%", "/")


def dds_type_name(ros_type: str) -> str:
    """``std_msgs/msg/String`` → ``std_msgs::msg::dds_::String_``."""
    pkg, kind, name = normalize_type_name(ros_type).split("/", 2)
    return f"{pkg}::{kind}::dds_::{name}_"


def ros_type_name(dds_type: str) -> str:
    """``std_msgs::msg::dds_::String_`` → ``std_msgs/msg/String`` (other forms unchanged)."""
    parts = dds_type.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
    return dds_type


@functools.cache
def service_type_hash(srv_type: str) -> str:
    """RIHS01 hash of a service (or action sub-service) type, built as REP-2016 describes.

    The description holds ``request_message``, ``response_message`` and ``event_message``
    (``service_msgs/ServiceEventInfo info``, ``Request[<=1] request``, ``Response[<=1]
    response``); it equals rosidl's (checked on example_interfaces/srv/AddTwoInts). A service
    we do not ship is read from the interface search path (``EDDIE_INTERFACE_PATH``); one
    nothing describes raises ``UnknownTypeError``: no hash is made up for it.
    """
    load_type(srv_type, "service")
    return service_hash_from(TYPESTORE.fielddefs, srv_type)


def service_hash_from(fielddefs: Any, srv_type: str) -> str:
    """:func:`service_type_hash` over the given field definitions (``pkg/srv/X_Request`` ...).

    Raises ``UnknownTypeError`` when they do not describe the service completely.
    """
    try:
        return rihs01(describe(service_fielddefs(fielddefs, srv_type), srv_type))
    except KeyError as exc:
        raise UnknownTypeError(srv_type, "service", f"its definition uses {exc}, which is not "
                               "described") from None


#: Hashes of message types computed so far (a type that cannot be described is not kept:
#: its definition may turn up on the search path later).
_MSG_HASHES: dict[str, str] = {}

#: The hash chunk of an entity whose type no definition here describes (rmw_zenoh's word
#: for a type without a hash).
UNKNOWN_TYPE_HASH = "TypeHashNotSupported"


def message_type_hash(ros_type: str) -> str:
    """The RIHS01 hash of a message type from its definition; ``UNKNOWN_TYPE_HASH`` when
    nothing describes it."""
    h = _MSG_HASHES.get(ros_type)
    if h is None:
        try:
            h = _MSG_HASHES[ros_type] = type_hash(ros_type)
        except KeyError:
            return UNKNOWN_TYPE_HASH
    return h


_msg_hash = message_type_hash


def topic_key(domain: int, name: str, ros_type: str, *, service: bool = False,
              type_hash: str | None = None) -> str:
    """The data key of a topic, or the queryable key of a service (``type_hash``: a hash
    learnt from the graph for a type no definition here describes)."""
    h = type_hash or (service_type_hash(ros_type) if service else _msg_hash(ros_type))
    return f"{domain}/{name.strip('/')}/{dds_type_name(ros_type)}/{h}"


def topic_wildcard_key(domain: int, name: str) -> str:
    """Every type published on ``name`` (so a mismatched type is seen and reported)."""
    return f"{domain}/{name.strip('/')}/*/*"


_INF_SEC, _INF_NSEC = 9223372036, 854775807


def _duration_to_keyexpr(d: Duration) -> str:
    """``sec,nsec`` with rmw_zenoh's rule: a part equal to the infinite default is empty."""
    ns = duration_ns(d)
    sec, nsec = (_INF_SEC, _INF_NSEC) if ns is None else divmod(ns, 1_000_000_000)
    return f"{'' if sec == _INF_SEC else sec},{'' if nsec == _INF_NSEC else nsec}"


def _duration_from_keyexpr(sec: str, nsec: str) -> Duration:
    s = int(sec) if sec else _INF_SEC
    n = int(nsec) if nsec else _INF_NSEC
    if (s, n) == (_INF_SEC, _INF_NSEC):
        return Duration(0)  # not set: infinite
    return Duration(s * 1_000_000_000 + n)


def qos_to_keyexpr(qos: QoSProfile) -> str:
    """rmw_zenoh's compact QoS chunk, e.g. ``::,10:,:,:,,`` (empty = rmw_zenoh default):
    ``reliability:durability:history,depth:deadline s,ns:lifespan s,ns:liveliness,lease s,ns``."""
    rel = "" if int(qos.reliability) in (0, _DEFAULT_RELIABILITY) else str(int(qos.reliability))
    dur = "" if int(qos.durability) in (0, _DEFAULT_DURABILITY) else str(int(qos.durability))
    hist = "" if int(qos.history) in (0, _DEFAULT_HISTORY) else str(int(qos.history))
    depth = "" if qos.depth == _DEFAULT_DEPTH else str(qos.depth)
    live = "" if int(qos.liveliness) in (0, _DEFAULT_LIVELINESS) else str(int(qos.liveliness))
    return (f"{rel}:{dur}:{hist},{depth}:{_duration_to_keyexpr(qos.deadline)}:"
            f"{_duration_to_keyexpr(qos.lifespan)}:{live},"
            f"{_duration_to_keyexpr(qos.liveliness_lease_duration)}")


def qos_from_keyexpr(text: str) -> QoSProfile:
    """Inverse of :func:`qos_to_keyexpr` (a malformed chunk gives the default profile)."""
    try:
        parts = text.split(":")
        hist, depth = parts[2].split(",")[:2]
        history = HistoryPolicy(int(hist)) if hist else HistoryPolicy.KEEP_LAST
        deadline = lifespan = lease = Duration(0)
        liveliness = LivelinessPolicy.SYSTEM_DEFAULT
        if len(parts) >= 6:
            deadline = _duration_from_keyexpr(*parts[3].split(",")[:2])
            lifespan = _duration_from_keyexpr(*parts[4].split(",")[:2])
            live, lease_s, lease_ns = parts[5].split(",")[:3]
            liveliness = LivelinessPolicy(int(live)) if live else LivelinessPolicy.SYSTEM_DEFAULT
            lease = _duration_from_keyexpr(lease_s, lease_ns)
        return QoSProfile(
            depth=int(depth) if depth else _DEFAULT_DEPTH,
            reliability=ReliabilityPolicy(int(parts[0])) if parts[0] else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy(int(parts[1])) if parts[1] else DurabilityPolicy.VOLATILE,
            history=history,
            deadline=deadline,
            lifespan=lifespan,
            liveliness=liveliness,
            liveliness_lease_duration=lease,
        )
    except (ValueError, IndexError, TypeError):
        return QoSProfile()


def liveliness_prefix(domain: int) -> str:
    return f"{ADMIN_SPACE}/{domain}/**"


def node_liveliness_key(domain: int, zid: str, node_id: int, namespace: str, name: str) -> str:
    return f"{ADMIN_SPACE}/{domain}/{zid}/{node_id}/{node_id}/NN/%/{mangle(namespace)}/{name}"


def liveliness_key(
    domain: int,
    zid: str,
    node_id: int,
    entity_id: int,
    kind: str,
    namespace: str,
    node_name: str,
    name: str,
    ros_type: str,
    qos: QoSProfile | None = None,
    type_hash: str | None = None,
) -> str:
    """Token of a publisher (MP), subscription (MS), service (SS) or client (SC)."""
    service = kind in ("SS", "SC")
    h = type_hash or (service_type_hash(ros_type) if service else _msg_hash(ros_type))
    return (
        f"{ADMIN_SPACE}/{domain}/{zid}/{node_id}/{entity_id}/{kind}/%/{mangle(namespace)}/"
        f"{node_name}/{mangle(name)}/{dds_type_name(ros_type)}/{h}/"
        f"{qos_to_keyexpr(qos or QoSProfile())}"
    )


@dataclass(frozen=True)
class GraphEntity:
    """One entity announced by a liveliness token."""

    key: str
    domain: int
    zid: str
    node_id: str
    entity_id: str
    kind: str  # NN, MP, MS, SS, SC
    namespace: str
    node_name: str
    name: str = ""  # topic or service (fully qualified)
    type_name: str = ""  # ROS form, e.g. std_msgs/msg/String
    type_hash: str = ""
    qos: str = ""

    @property
    def node(self) -> str:
        """Fully qualified node name."""
        return f"{self.namespace.rstrip('/')}/{self.node_name}"

    @property
    def gid(self) -> bytes:
        return entity_gid(self.key)

    @property
    def qos_profile(self) -> QoSProfile:
        return qos_from_keyexpr(self.qos)


def parse_liveliness_key(key: str) -> GraphEntity | None:
    """The entity a token announces, or None when the key is not one of ours/rmw_zenoh's."""
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE:
        return None
    try:
        domain = int(parts[1])
    except ValueError:
        return None
    kind = parts[5]
    base: dict[str, Any] = {
        "key": key, "domain": domain, "zid": parts[2], "node_id": parts[3],
        "entity_id": parts[4], "kind": kind, "namespace": unmangle(parts[7]) or "/",
        "node_name": parts[8],
    }
    if kind == "NN":
        return GraphEntity(**base)
    if kind not in ("MP", "MS", "SS", "SC") or len(parts) < 12:
        return None
    return GraphEntity(
        **base,
        name=unmangle(parts[9]),
        type_name=ros_type_name(parts[10]),
        type_hash=parts[11],
        qos=parts[12] if len(parts) > 12 else "",
    )


def entity_gid(key: str) -> bytes:
    """The entity's 16-byte GID as rmw_zenoh makes it: XXH3-128 of its liveliness key, the
    low 64 bits then the high 64 bits, each little-endian."""
    low, high = xxh3_128(key.encode())
    return low.to_bytes(8, "little") + high.to_bytes(8, "little")


def encode_attachment(sequence: int, timestamp_ns: int, gid: bytes) -> bytes:
    return ATTACHMENT.pack(sequence, timestamp_ns, 16, gid)


def decode_attachment(data: bytes) -> tuple[int, int, bytes] | None:
    """(sequence, source timestamp ns, GID) or None if the attachment is not in that form."""
    if len(data) < ATTACHMENT.size:
        return None
    seq, ts, n, gid = ATTACHMENT.unpack_from(data)
    return seq, ts, gid[:n]
