"""Names, types and QoS as ROS 2 puts them on DDS (rmw_cyclonedds / rmw_fastrtps).

``/odom`` is the DDS topic ``rt/odom`` of type ``nav_msgs::msg::dds_::Odometry_``; the DDS
type is generated from the ROS definition (rosbags' field definitions), so its XTypes type
information is the ROS message's. A service's request and reply types carry rmw_cyclonedds's
``{uint64 guid; int64 seq}`` correlation before the fields.
"""

from __future__ import annotations

import functools
from typing import Any

from eddiebot.core.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
    duration_ns,
)
from eddiebot.core.time import Duration
from eddiebot.msgs import TYPESTORE, normalize_type_name
from eddiebot.transport.keys import dds_type_name

__all__ = [
    "REQUEST_HEADER_SIZE",
    "TAKE_BATCH",
    "TOPIC_PREFIX",
    "cyclone_config",
    "dds_qos",
    "dds_topic_name",
    "dds_type",
    "idl_type",
    "known",
    "merge_publisher_qos",
    "padded",
    "qos_from_dds",
    "ros_topic_name",
    "service_dds_type",
    "service_names",
    "type_hash_of",
    "user_data_fields",
    "vendor_of",
]

#: The prefix rmw_cyclonedds / rmw_fastrtps give topics on DDS (``rq``/``rr`` are services).
TOPIC_PREFIX = "rt"
#: A reliable writer waits at most this long for room in its history (then the sample is
#: dropped): long enough to pass a reader's back-pressure on to our publishers, short enough
#: that a stalled DDS reader does not hold the bridge's Zenoh callbacks for good.
_MAX_BLOCKING_NS = 1_000_000_000
#: Samples taken per call from a DDS reader.
TAKE_BATCH = 64
#: DDS's infinite duration (``DDS_INFINITY``, also rmw's ``RMW_DURATION_INFINITE``).
_DDS_INFINITY = (1 << 63) - 1
#: ``{uint64 guid; int64 seq}``: rmw_cyclonedds's request correlation, after the CDR
#: encapsulation header of every request and reply.
REQUEST_HEADER_SIZE = 16
#: RTPS vendor ids (the first two bytes of a GUID prefix, as both vendors fill them).
_VENDORS = {b"\x01\x10": "Cyclone DDS", b"\x01\x0f": "Fast DDS", b"\x01\x01": "RTI Connext DDS",
            b"\x01\x12": "GurumDDS", b"\x01\x02": "OpenSplice"}


def dds_topic_name(topic: str) -> str:
    """``/odom`` → ``rt/odom`` (the fully qualified name without its leading slash)."""
    return f"{TOPIC_PREFIX}/{topic.lstrip('/')}"


def ros_topic_name(dds_topic: str) -> str | None:
    """``rt/odom`` → ``/odom``; None for a DDS topic that is not a ROS topic."""
    prefix = TOPIC_PREFIX + "/"
    if not dds_topic.startswith(prefix) or len(dds_topic) == len(prefix):
        return None
    return "/" + dds_topic[len(prefix):]


def service_names(dds_topic: str, dds_type: str) -> tuple[str, str, str] | None:
    """``rq/add_two_intsRequest`` of type ``example_interfaces::srv::dds_::AddTwoInts_Request_``
    → (``/add_two_ints``, ``example_interfaces/srv/AddTwoInts``, ``request``); ``rr/…Reply``
    → ``reply``; None for a topic that is not a ROS service's."""
    from eddiebot.transport.keys import ros_type_name

    for prefix, suffix, part, type_suffix in (("rq/", "Request", "request", "_Request"),
                                              ("rr/", "Reply", "reply", "_Response")):
        if dds_topic.startswith(prefix) and dds_topic.endswith(suffix):
            name = dds_topic[len(prefix):-len(suffix)]
            ros_type = ros_type_name(dds_type)
            if not name or "/" not in ros_type or not ros_type.endswith(type_suffix):
                return None
            return "/" + name, ros_type[:-len(type_suffix)], part
    return None


def vendor_of(guid: Any) -> str:
    """The DDS implementation of an entity, from its GUID (a ``uuid.UUID`` or 16 bytes)."""
    raw = guid.bytes if hasattr(guid, "bytes") else bytes(guid)
    return _VENDORS.get(raw[:2], f"vendor {raw[:2].hex('.')}")


def user_data_fields(qos: Any) -> dict[str, str]:
    """``key=value;`` pairs of an endpoint's or participant's USER_DATA, as rmw puts them
    (``typehash=RIHS01_…;``, ``enclave=/;``)."""
    from cyclonedds.qos import Policy

    try:
        data = qos[Policy.Userdata].data if qos is not None else b""
    except Exception:
        return {}
    out: dict[str, str] = {}
    for item in bytes(data or b"").decode("utf-8", "replace").split(";"):
        key, sep, value = item.partition("=")
        if sep and key:
            out[key.strip()] = value.strip()
    return out


def cyclone_config(network: str = "loopback") -> str:
    """The Cyclone DDS configuration XML of the bridge's domain.

    ``loopback``: the loopback interface only, participants found by SPDP multicast on it and
    by unicast to localhost (lo carries no multicast flag on Linux; Cyclone uses it anyway
    when told to, and the unicast peers cover kernels that do not deliver it). ``lan``:
    Cyclone's own choice of interface and multicast, as a ROS 2 node's default.
    """
    if network == "lan":
        general = ""
        discovery = ""
    else:
        general = ("<General><Interfaces><NetworkInterface address=\"127.0.0.1\" "
                   "multicast=\"true\"/></Interfaces><AllowMulticast>spdp</AllowMulticast>"
                   "</General>")
        discovery = ("<Discovery><ParticipantIndex>auto</ParticipantIndex>"
                     "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
                     "<Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery>")
    return f"<CycloneDDS><Domain id=\"any\">{general}{discovery}</Domain></CycloneDDS>"


# -- QoS ----------------------------------------------------------------------------------
def dds_qos(qos: QoSProfile, user_data: bytes | None = None, *, reader: bool = False) -> Any:
    """A ``cyclonedds.qos.Qos`` for an endpoint with ROS QoS ``qos`` (XCDR1 data, as ROS 2;
    local endpoints of the same participant ignored, so the bridge never hears itself).

    Deadline, lifespan and liveliness map as rmw_cyclonedds maps them (an unset duration is
    DDS's infinity, ``SYSTEM_DEFAULT`` liveliness is left to Cyclone, i.e. automatic). A
    ``reader`` requests neither deadline nor liveliness (the weakest request, which every
    writer meets: the bridge passes on whatever its writers offer) and has no lifespan,
    a writer-only policy.
    """
    from cyclonedds.qos import Policy, Qos

    policies: list[Any] = [
        Policy.Reliability.BestEffort if qos.reliability == ReliabilityPolicy.BEST_EFFORT
        else Policy.Reliability.Reliable(max_blocking_time=_MAX_BLOCKING_NS),
        Policy.Durability.TransientLocal if qos.transient_local else Policy.Durability.Volatile,
        Policy.History.KeepAll if qos.history == HistoryPolicy.KEEP_ALL
        else Policy.History.KeepLast(max(1, qos.depth)),
        Policy.DataRepresentation(use_cdrv0_representation=True),
        Policy.IgnoreLocal.Participant,
    ]
    if not reader:
        deadline, lifespan = duration_ns(qos.deadline), duration_ns(qos.lifespan)
        lease = duration_ns(qos.liveliness_lease_duration) or _DDS_INFINITY
        if deadline is not None:
            policies.append(Policy.Deadline(deadline))
        if lifespan is not None:
            policies.append(Policy.Lifespan(lifespan))
        if qos.liveliness == LivelinessPolicy.MANUAL_BY_TOPIC:
            policies.append(Policy.Liveliness.ManualByTopic(lease))
        elif qos.liveliness == LivelinessPolicy.AUTOMATIC or lease != _DDS_INFINITY:
            policies.append(Policy.Liveliness.Automatic(lease))
    if user_data:
        policies.append(Policy.Userdata(user_data))
    return Qos(*policies)


def _duration_from_dds(ns: Any) -> Duration:
    """A DDS duration (ns; DDS's infinity or a negative value: not set) as a QoS duration."""
    value = int(ns or 0)
    return Duration(nanoseconds=value) if 0 < value < _DDS_INFINITY else Duration()


def qos_from_dds(qos: Any) -> QoSProfile:
    """The ROS QoS of a discovered DDS endpoint (its ``Qos``); DDS defaults where unset.
    Liveliness ``MANUAL_BY_PARTICIPANT``, which ROS 2 does not offer, reads as automatic."""
    from cyclonedds.qos import Policy

    def get(policy: Any) -> Any:
        return qos[policy] if qos is not None else None

    rel, dur, hist = get(Policy.Reliability), get(Policy.Durability), get(Policy.History)
    deadline, lifespan, live = get(Policy.Deadline), get(Policy.Lifespan), get(Policy.Liveliness)
    keep_all = hist == Policy.History.KeepAll
    depth = int(getattr(hist, "depth", 1) or 1)
    liveliness = LivelinessPolicy.SYSTEM_DEFAULT
    if live is not None:
        liveliness = LivelinessPolicy.MANUAL_BY_TOPIC \
            if isinstance(live, Policy.Liveliness.ManualByTopic) else LivelinessPolicy.AUTOMATIC
    return QoSProfile(
        depth=depth if not keep_all else max(depth, 1),
        reliability=ReliabilityPolicy.BEST_EFFORT if rel == Policy.Reliability.BestEffort
        else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if dur == Policy.Durability.TransientLocal else DurabilityPolicy.VOLATILE,
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        deadline=_duration_from_dds(getattr(deadline, "deadline", 0)),
        lifespan=_duration_from_dds(getattr(lifespan, "lifespan", 0)),
        liveliness=liveliness,
        liveliness_lease_duration=_duration_from_dds(getattr(live, "lease_duration", 0)),
    )


def merge_publisher_qos(profiles: list[QoSProfile]) -> QoSProfile:
    """What one bridged writer offers for several publishers of a topic: transient-local
    if any is, best-effort if any is (a reliable writer fed by a best-effort source would
    still block), the deepest history, keep-all if any is (a keep-all reliable writer
    waits for its readers, which slows the publisher down through Zenoh instead of
    overwriting samples no reader has yet).

    Deadline: the shortest one set (their union publishes at least that often); lifespan:
    the longest, and none if any publisher has none (no sample is dropped earlier than its
    publisher says); liveliness: manual by topic only if every publisher is, with the
    shortest lease set. One publisher's QoS is passed on as it is."""
    if not profiles:
        return QoSProfile()
    if len(set(profiles)) == 1:
        return profiles[0]

    def shortest(values: list[int | None]) -> Duration:
        set_ = [v for v in values if v is not None]
        return Duration(nanoseconds=min(set_)) if set_ else Duration()

    lifespans = [duration_ns(p.lifespan) for p in profiles]
    manual = all(p.liveliness == LivelinessPolicy.MANUAL_BY_TOPIC for p in profiles)
    any_live = any(p.liveliness != LivelinessPolicy.SYSTEM_DEFAULT for p in profiles)
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL
        if any(p.history == HistoryPolicy.KEEP_ALL for p in profiles) else HistoryPolicy.KEEP_LAST,
        depth=max(p.depth for p in profiles),
        reliability=ReliabilityPolicy.BEST_EFFORT
        if any(p.reliability == ReliabilityPolicy.BEST_EFFORT for p in profiles)
        else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if any(p.transient_local for p in profiles) else DurabilityPolicy.VOLATILE,
        deadline=shortest([duration_ns(p.deadline) for p in profiles]),
        lifespan=Duration() if None in lifespans
        else Duration(nanoseconds=max(v for v in lifespans if v is not None)),
        liveliness=LivelinessPolicy.MANUAL_BY_TOPIC if manual
        else LivelinessPolicy.AUTOMATIC if any_live else LivelinessPolicy.SYSTEM_DEFAULT,
        liveliness_lease_duration=shortest(
            [duration_ns(p.liveliness_lease_duration) for p in profiles]),
    )


# -- types --------------------------------------------------------------------------------
def _idl_base(name: str, bound: int) -> Any:
    from cyclonedds.idl import types

    t: Any = types  # its generic aliases are subscripted at run time

    if name in ("string", "wstring"):
        return t.bounded_str[bound] if bound else str
    table: dict[str, Any] = {
        "bool": bool, "byte": t.byte, "char": t.uint8, "int8": t.int8, "uint8": t.uint8,
        "int16": t.int16, "uint16": t.uint16, "int32": t.int32, "uint32": t.uint32,
        "int64": t.int64, "uint64": t.uint64, "float32": t.float32, "float64": t.float64,
    }
    return table[name]


def _idl_field(desc: tuple[Any, Any]) -> Any:
    from cyclonedds.idl import types
    from rosbags.interfaces import Nodetype

    t: Any = types

    kind, detail = desc
    if kind == Nodetype.BASE:
        return _idl_base(detail[0], detail[1])
    if kind == Nodetype.NAME:
        return idl_type(detail)
    inner, size = detail
    element = _idl_field(inner)
    if kind == Nodetype.ARRAY:
        return t.array[element, size]
    return t.sequence[element, size] if size else t.sequence[element]


@functools.cache
def idl_type(ros_type: str) -> Any:
    """An ``IdlStruct`` class named as ROS 2 names the type on DDS, with the ROS fields (so
    its XTypes type information is the message's); keyless, final, XCDR1 as rosidl's."""
    from cyclonedds.idl import make_idl_struct

    name = normalize_type_name(ros_type)
    _consts, fields = TYPESTORE.fielddefs[name]
    members = {fname: _idl_field(desc) for fname, desc in fields}
    return make_idl_struct(name.rsplit("/", 1)[-1] + "_", dds_type_name(name), members)


@functools.cache
def dds_type(ros_type: str) -> Any:
    """:func:`idl_type`, its type information computed. Cyclone normalizes every sample
    against its type as it is written and received (bools to 0/1, lengths checked), so a
    type that only bears the right name could not carry the data: a type neither shipped
    nor described by an interface file on the search path (:func:`known`) is not bridged."""
    cls = idl_type(ros_type)
    cls.__idl__.populate()
    cls.__idl__.fill_type_data()
    return cls


@functools.cache
def service_dds_type(ros_type: str) -> Any:
    """The DDS type of a request or reply as rmw_cyclonedds puts it on the wire: the
    client's ``{uint64 guid; int64 seq}`` before the fields (Cyclone normalizes samples
    against their type, so the correlation must be part of it)."""
    from cyclonedds.idl import make_idl_struct
    from cyclonedds.idl import types as t

    name = normalize_type_name(ros_type)
    _consts, fields = TYPESTORE.fielddefs[name]
    members: dict[str, Any] = {"rmw_request_guid": t.uint64, "rmw_request_seq": t.int64}
    for fname, desc in fields:
        members[fname] = _idl_field(desc)
    cls = make_idl_struct(name.rsplit("/", 1)[-1] + "_", dds_type_name(name), members)
    cls.__idl__.populate()
    cls.__idl__.fill_type_data()
    return cls


def known(ros_type: str) -> bool:
    """Whether the bridge can carry ``ros_type``: a type we ship, or one an interface file
    on the search path (``EDDIE_INTERFACE_PATH``, ``AMENT_PREFIX_PATH``) describes (loaded
    on first sight; a miss is remembered until the search path changes)."""
    from eddiebot.msgs import load_type

    try:
        name = normalize_type_name(ros_type)
        if name not in TYPESTORE.fielddefs:
            load_type(name)
        return name in TYPESTORE.fielddefs
    except Exception:
        return False


def type_hash_of(ros_type: str) -> str:
    from eddiebot.msgs import type_hash

    try:
        return str(type_hash(ros_type))
    except Exception:
        return ""


def padded(cdr: bytes) -> bytes:
    """CDR padded to 4 bytes, the padding counted in the encapsulation options (XTypes
    7.6.3.1.2), as Cyclone's own serializer leaves it."""
    pad = -len(cdr) % 4
    if not pad or len(cdr) < 4:
        return cdr
    return cdr[:3] + bytes([(cdr[3] & ~3) | pad]) + cdr[4:] + b"\0" * pad
