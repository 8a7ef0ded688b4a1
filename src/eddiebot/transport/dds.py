"""A bridge between our graph and a DDS domain, as a ROS 2 node on ``rmw_cyclonedds`` sees it.

``DdsBridge(context, transport, config)`` joins a DDS domain with Cyclone DDS (the
``cyclonedds`` package, whose wheel carries the C library) and mirrors topics both ways:

- names and types as ROS 2 puts them on DDS: ``/odom`` is the DDS topic ``rt/odom`` of type
  ``nav_msgs::msg::dds_::Odometry_``; the DDS type is generated from the ROS definition
  (rosbags' field definitions), so its XTypes type information is the ROS message's;
- payloads pass as raw CDR, never re-serialized: our samples' bytes (rosbags' CDR, with its
  4-byte encapsulation header) are the DDS samples' serialized data, and the other way round;
  the Python layer of ``cyclonedds`` is used to make entities, its C layer (``ddspy_write``,
  ``ddspy_take``) to move bytes;
- QoS (reliability, durability, history, depth) mapped from and to ``QoSProfile``; endpoints
  carry ``typehash=RIHS01_<hex>;`` and the participant ``enclave=/;`` in USER_DATA, as the
  Jazzy rmw does;
- routes follow the graph: a publisher on our side (liveliness tokens) gets a DDS writer, a
  DDS publication on ``rt/...`` (the built-in DCPSPublication topic) a Zenoh publisher with
  its token; a route goes when its last publisher goes;
- no loops: the bridge's DDS readers ignore the bridge's own writers (``IgnoreLocal``), its
  Zenoh subscribers ignore its own Zenoh publishers (``Locality.REMOTE``), and neither side's
  discovery counts the bridge's own endpoints; one route per (topic, type, direction).

Network: loopback only unless ``network="lan"`` (``EDDIE_NETWORK=lan``), as Jazzy's
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` does for Cyclone (the loopback interface, SPDP
multicast on it and unicast to localhost). A ROS 2 node on the same machine therefore meets a
loopback bridge when it runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (or
``CYCLONEDDS_URI`` naming the loopback interface); with its default range use ``lan``.

Services: a service served in our graph is offered to ROS 2 clients on ``rmw_cyclonedds``
(``rq/<name>Request`` / ``rr/<name>Reply``, types ``<pkg>::srv::dds_::<T>_Request_`` /
``_Response_``, the client's ``{uint64 guid; int64 seq}`` between the encapsulation header
and the body, carried back in the reply). Not yet: services served on DDS for our clients.
Fast DDS peers put that correlation in RTPS inline QoS instead, so cross-vendor services
cannot work; their topics do.
"""

from __future__ import annotations

import functools
import logging
import re
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from eddiebot.core.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from eddiebot.msgs import TYPESTORE, normalize_type_name
from eddiebot.transport.errors import TransportError
from eddiebot.transport.keys import (
    dds_type_name,
    encode_attachment,
    entity_gid,
    liveliness_key,
    qos_from_keyexpr,
    ros_type_name,
    topic_key,
)

if TYPE_CHECKING:
    from eddiebot.core.context import Context
    from eddiebot.transport.zenoh import ZenohTransport

__all__ = [
    "DdsBridge",
    "DdsBridgeConfig",
    "Route",
    "cyclone_config",
    "dds_qos",
    "dds_topic_name",
    "idl_type",
    "qos_from_dds",
    "ros_topic_name",
]

log = logging.getLogger("eddiebot.transport.dds")

#: The prefix rmw_cyclonedds / rmw_fastrtps give topics on DDS (``rq``/``rr`` are services).
TOPIC_PREFIX = "rt"
#: A reliable writer waits at most this long for room in its history (then the sample is
#: dropped): long enough to pass a reader's back-pressure on to our publishers, short enough
#: that a stalled DDS reader does not hold the bridge's Zenoh callbacks for good.
_MAX_BLOCKING_NS = 1_000_000_000
#: Samples taken per call from a DDS reader.
_TAKE_BATCH = 64


def dds_topic_name(topic: str) -> str:
    """``/odom`` → ``rt/odom`` (the fully qualified name without its leading slash)."""
    return f"{TOPIC_PREFIX}/{topic.lstrip('/')}"


def ros_topic_name(dds_topic: str) -> str | None:
    """``rt/odom`` → ``/odom``; None for a DDS topic that is not a ROS topic."""
    prefix = TOPIC_PREFIX + "/"
    if not dds_topic.startswith(prefix) or len(dds_topic) == len(prefix):
        return None
    return "/" + dds_topic[len(prefix):]


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
def dds_qos(qos: QoSProfile, user_data: bytes | None = None) -> Any:
    """A ``cyclonedds.qos.Qos`` for an endpoint with ROS QoS ``qos`` (XCDR1 data, as ROS 2;
    local endpoints of the same participant ignored, so the bridge never hears itself)."""
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
    if user_data:
        policies.append(Policy.Userdata(user_data))
    return Qos(*policies)


def qos_from_dds(qos: Any) -> QoSProfile:
    """The ROS QoS of a discovered DDS endpoint (its ``Qos``); DDS defaults where unset."""
    from cyclonedds.qos import Policy

    rel = qos[Policy.Reliability] if qos is not None else None
    dur = qos[Policy.Durability] if qos is not None else None
    hist = qos[Policy.History] if qos is not None else None
    keep_all = hist == Policy.History.KeepAll
    depth = int(getattr(hist, "depth", 1) or 1)
    return QoSProfile(
        depth=depth if not keep_all else max(depth, 1),
        reliability=ReliabilityPolicy.BEST_EFFORT if rel == Policy.Reliability.BestEffort
        else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if dur == Policy.Durability.TransientLocal else DurabilityPolicy.VOLATILE,
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
    )


def _merge_publisher_qos(profiles: list[QoSProfile]) -> QoSProfile:
    """What one bridged writer offers for several publishers of a topic: transient-local
    if any is, best-effort if any is (a reliable writer fed by a best-effort source would
    still block), the deepest history, keep-all if any is (a keep-all reliable writer
    waits for its readers, which slows the publisher down through Zenoh instead of
    overwriting samples no reader has yet)."""
    if not profiles:
        return QoSProfile()
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL
        if any(p.history == HistoryPolicy.KEEP_ALL for p in profiles) else HistoryPolicy.KEEP_LAST,
        depth=max(p.depth for p in profiles),
        reliability=ReliabilityPolicy.BEST_EFFORT
        if any(p.reliability == ReliabilityPolicy.BEST_EFFORT for p in profiles)
        else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if any(p.transient_local for p in profiles) else DurabilityPolicy.VOLATILE,
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
def _dds_type(ros_type: str) -> Any:
    """:func:`idl_type`, its type information computed. Cyclone normalizes every sample
    against its type as it is written and received (bools to 0/1, lengths checked), so a
    type that only bears the right name could not carry the data: a type rosbags cannot
    describe is not bridged."""
    cls = idl_type(ros_type)
    cls.__idl__.populate()
    cls.__idl__.fill_type_data()
    return cls


@functools.cache
def _service_dds_type(ros_type: str) -> Any:
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


def _known(ros_type: str) -> bool:
    try:
        return normalize_type_name(ros_type) in TYPESTORE.fielddefs
    except Exception:
        return False


def _type_hash(ros_type: str) -> str:
    from eddiebot.msgs import type_hash

    try:
        return str(type_hash(ros_type))
    except Exception:
        return ""


def _padded(cdr: bytes) -> bytes:
    """CDR padded to 4 bytes, the padding counted in the encapsulation options (XTypes
    7.6.3.1.2), as Cyclone's own serializer leaves it."""
    pad = -len(cdr) % 4
    if not pad or len(cdr) < 4:
        return cdr
    return cdr[:3] + bytes([(cdr[3] & ~3) | pad]) + cdr[4:] + b"\0" * pad


# -- configuration --------------------------------------------------------------------------
@dataclass
class DdsBridgeConfig:
    """What the bridge joins and which topics it carries.

    ``allow`` / ``deny``: regular expressions searched in the ROS topic name (``/odom``);
    a topic is bridged when ``allow`` matches (or is None) and ``deny`` does not.
    ``topics``: when not None, only these topics (``name`` → ROS type), bridged from the
    start whatever discovery says — the way round built-in topics that a DDS build lacks.
    """

    domain_id: int = 0
    network: str = "loopback"
    allow: str | None = None
    deny: str | None = None
    topics: dict[str, str] | None = None
    node_name: str = "eddie_bridge_dds"
    #: Seconds between discovery passes over both graphs.
    poll_period_s: float = 0.1

    def admits(self, topic: str) -> bool:
        if self.allow is not None and re.search(self.allow, topic) is None:
            return False
        return self.deny is None or re.search(self.deny, topic) is None


@dataclass(frozen=True)
class Route:
    """One bridged (topic, type) in one direction: ``to_dds`` or ``from_dds``."""

    topic: str
    type_name: str
    direction: str
    qos: QoSProfile


@dataclass
class _Live:
    route: Route
    close: Callable[[], None]
    stats: dict[str, int] = field(default_factory=lambda: {"samples": 0})


# -- the bridge -----------------------------------------------------------------------------
class DdsBridge:
    """Mirrors topics between ``context``'s graph (through its Zenoh ``transport``) and a DDS
    domain; :meth:`start` runs discovery in a thread, :meth:`close` undoes everything."""

    def __init__(self, context: Context, transport: ZenohTransport,
                 config: DdsBridgeConfig | None = None) -> None:
        try:
            from cyclonedds.builtin import (
                BuiltinDataReader,
                BuiltinTopicDcpsPublication,
            )
            from cyclonedds.domain import Domain, DomainParticipant
            from cyclonedds.pub import Publisher
            from cyclonedds.qos import Policy, Qos
            from cyclonedds.sub import Subscriber
        except ImportError as exc:  # pragma: no cover - a dependency of the package
            raise TransportError(f"the DDS bridge needs cyclonedds: {exc}") from exc
        from eddiebot.core.node import Node

        self.context = context
        self.transport = transport
        self.config = config or DdsBridgeConfig()
        self._lock = threading.RLock()
        self._closed = False
        self._routes: dict[tuple[str, str, str], _Live] = {}
        self._dds_pubs: dict[str, Any] = {}  # DCPSPublication key → endpoint
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._topics: dict[tuple[str, str], Any] = {}
        self.node = Node(self.config.node_name, context=context, start_parameter_services=False)
        self._zenoh = _ZenohSide(transport, self.node)
        try:
            try:
                self._domain = Domain(self.config.domain_id, cyclone_config(self.config.network))
            except Exception as exc:
                raise TransportError(
                    f"cannot join DDS domain {self.config.domain_id}: {exc}") from exc
            self.participant = DomainParticipant(
                self.config.domain_id, qos=Qos(Policy.Userdata(b"enclave=/;")))
            self._publisher = Publisher(self.participant)
            self._subscriber = Subscriber(self.participant)
            self._own_key = str(self.participant.guid)
            self._pub_reader = BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)
        except BaseException:  # Ctrl-C half-way included: leave nothing declared
            self.close()
            raise

    # -- life ---------------------------------------------------------------------------
    def start(self) -> DdsBridge:
        """Run discovery passes in a thread (a Ctrl-C in the caller's thread never stops
        one half-way, with a route declared but not yet recorded)."""
        self._thread = threading.Thread(target=self._run, name="eddie-dds-bridge", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.step()
            except Exception:
                if self._closed:
                    return
                log.exception("DDS bridge discovery pass failed")
            self._stop.wait(self.config.poll_period_s)

    def close(self) -> None:
        """Close every route and leave both graphs; also after a Ctrl-C half-way through
        (each route is closed even if closing another one is interrupted)."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        with self._lock:
            lives = list(self._routes.values())
            self._routes.clear()
        try:
            for live in lives:
                _quietly(live.close)
        finally:
            self.node.destroy_node()
        # Cyclone's entities go with their Python objects; drop the participant first
        self._topics.clear()
        for name in ("_pub_reader", "_publisher", "_subscriber", "participant", "_domain"):
            setattr(self, name, None)

    def __enter__(self) -> DdsBridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- routes -------------------------------------------------------------------------
    def routes(self) -> list[Route]:
        with self._lock:
            return [live.route for live in self._routes.values()]

    def counts(self) -> dict[tuple[str, str], int]:
        """Samples carried per (topic, direction)."""
        with self._lock:
            return {(k[0], k[2]): live.stats["samples"] for k, live in self._routes.items()}

    def step(self) -> None:
        """One discovery pass: open the routes both graphs now call for, close the others."""
        if self._closed:
            return
        wanted = self._wanted_routes()
        with self._lock:
            current = dict(self._routes)
        for key, live in current.items():
            if key not in wanted:
                log.info("unbridged %s [%s] (%s; %s)", key[0], key[1], key[2], live.stats)
                with self._lock:
                    self._routes.pop(key, None)
                _quietly(live.close)
        for key, route in wanted.items():
            if key in current or self._closed:
                continue
            opener = {"to_dds": self._open_to_dds, "from_dds": self._open_from_dds,
                      "service": self._open_service}[route.direction]
            try:
                live = opener(route)
            except Exception as exc:
                log.warning("cannot bridge %s [%s] %s: %s", route.topic, route.type_name,
                            route.direction, exc)
                continue
            with self._lock:
                closed = self._closed
                if not closed:
                    self._routes[key] = live
            if closed:
                _quietly(live.close)
                return
            log.info("bridged %s [%s] %s (%s, %s, %s %d)", route.topic, route.type_name,
                     route.direction, route.qos.reliability.name.lower(),
                     route.qos.durability.name.lower(), route.qos.history.name.lower(),
                     route.qos.depth)

    def _wanted_routes(self) -> dict[tuple[str, str, str], Route]:
        wanted: dict[tuple[str, str, str], Route] = {}
        if self.config.topics is not None:
            for topic, type_name in self.config.topics.items():
                ros_type = normalize_type_name(type_name)
                for direction in ("to_dds", "from_dds"):
                    wanted[(topic, ros_type, direction)] = Route(topic, ros_type, direction,
                                                                 QoSProfile())
            return wanted
        # our side: remote publishers (the bridge's own tokens never reach its cache)
        ours: dict[tuple[str, str], list[QoSProfile]] = {}
        for e in self.transport.cache.publishers():
            if self.config.admits(e.name) and _known(e.type_name):
                ours.setdefault((e.name, e.type_name), []).append(qos_from_keyexpr(e.qos))
        for (topic, ros_type), profiles in ours.items():
            wanted[(topic, ros_type, "to_dds")] = Route(topic, ros_type, "to_dds",
                                                        _merge_publisher_qos(profiles))
        # DDS side: publications of other participants
        theirs: dict[tuple[str, str], list[QoSProfile]] = {}
        for ep in self._dds_publications():
            name = ros_topic_name(ep.topic_name or "")
            if name is None or not self.config.admits(name):
                continue
            dds_type = ros_type_name(ep.type_name or "")
            if "/" not in dds_type or not _known(dds_type):
                continue
            theirs.setdefault((name, normalize_type_name(dds_type)), []).append(
                qos_from_dds(ep.qos))
        for (topic, ros_type), profiles in theirs.items():
            wanted[(topic, ros_type, "from_dds")] = Route(topic, ros_type, "from_dds",
                                                          _merge_publisher_qos(profiles))
        # services served in our graph, for ROS 2 clients on DDS
        for e in self.transport.cache.services():
            if self.config.admits(e.name) and _known(e.type_name + "_Request"):
                wanted[(e.name, e.type_name, "service")] = Route(
                    e.name, e.type_name, "service", QoSProfile(depth=10))
        return wanted

    def _dds_publications(self) -> list[Any]:
        from cyclonedds.core import InstanceState

        for sample in self._pub_reader.take(N=256):
            key = str(sample.key)
            if sample.sample_info.instance_state == InstanceState.Alive:
                if str(sample.participant_key) != self._own_key:
                    self._dds_pubs[key] = sample
            else:
                self._dds_pubs.pop(key, None)
        return list(self._dds_pubs.values())

    def _topic(self, topic: str, type_name: str, dds_name: str | None = None) -> Any:
        from cyclonedds.topic import Topic

        name = dds_name or dds_topic_name(topic)
        key = (name, type_name)
        if key not in self._topics:
            cls = _dds_type(type_name) if dds_name is None else _service_dds_type(type_name)
            self._topics[key] = Topic(self.participant, name, cls)
        return self._topics[key]

    def _user_data(self, type_name: str) -> bytes:
        return f"typehash={_type_hash(type_name)};".encode()

    def _open_to_dds(self, route: Route) -> _Live:
        """Our publishers → a DDS writer, fed by a Zenoh subscriber."""
        from cyclonedds._clayer import ddspy_write
        from cyclonedds.pub import DataWriter

        writer = DataWriter(self._publisher, self._topic(route.topic, route.type_name),
                            qos=dds_qos(route.qos, self._user_data(route.type_name)))
        ref = writer._ref
        live = _Live(route, lambda: None)

        def on_sample(cdr: bytes) -> None:
            if self._closed:
                return
            ret = ddspy_write(ref, _padded(cdr))
            if ret < 0:
                live.stats["failed"] = live.stats.get("failed", 0) + 1
                log.debug("DDS write on %s failed (%d)", route.topic, ret)
            else:
                live.stats["samples"] += 1

        zsub = self._zenoh.subscribe(route.topic, route.type_name, route.qos, on_sample)

        def close() -> None:
            zsub.close()
            _delete(writer)

        live.close = close
        return live

    def _open_from_dds(self, route: Route) -> _Live:
        """DDS publications → a DDS reader whose samples a Zenoh publisher sends on."""
        from cyclonedds._clayer import ddspy_take
        from cyclonedds.core import InstanceState, Listener, SampleState, ViewState
        from cyclonedds.sub import DataReader

        zpub = self._zenoh.publish(route.topic, route.type_name, route.qos)
        live = _Live(route, lambda: None)
        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        state: dict[str, Any] = {"ref": None}

        def pump(_reader: Any = None) -> None:
            ref = state["ref"]
            if ref is None or self._closed:
                return
            while True:
                got = ddspy_take(ref, mask, _TAKE_BATCH)
                if isinstance(got, int) or not got:
                    return
                for data, info in got:
                    if info.valid_data:
                        zpub.put(bytes(data), info.source_timestamp)
                        live.stats["samples"] += 1
                if len(got) < _TAKE_BATCH:
                    return

        reader = DataReader(self._subscriber, self._topic(route.topic, route.type_name),
                            qos=dds_qos(route.qos, self._user_data(route.type_name)),
                            listener=Listener(on_data_available=pump))
        state["ref"] = reader._ref
        pump()  # samples that arrived before the listener's first call

        def close() -> None:
            state["ref"] = None
            _delete(reader)
            zpub.close()

        live.close = close
        return live


    def _open_service(self, route: Route) -> _Live:
        """A service of our graph for ROS 2 clients on rmw_cyclonedds: requests on
        ``rq/<name>Request``, replies on ``rr/<name>Reply``, each CDR body preceded (after
        the encapsulation header) by the client's ``{uint64 guid; int64 seq}``, which the
        reply carries back. (rmw_fastrtps correlates in RTPS inline QoS instead, so Fast DDS
        clients cannot be served this way.)"""
        from cyclonedds._clayer import ddspy_take, ddspy_write
        from cyclonedds.core import InstanceState, Listener, SampleState, ViewState
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader

        from eddiebot.transport.keys import service_type_hash

        name = route.topic.lstrip("/")
        user_data = f"typehash={service_type_hash(route.type_name)};".encode()
        qos = dds_qos(route.qos, user_data)
        writer = DataWriter(self._publisher, self._topic(
            route.topic, route.type_name + "_Response", f"rr/{name}Reply"), qos=qos)
        writer_ref = writer._ref
        live = _Live(route, lambda: None)
        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        state: dict[str, Any] = {"ref": None}
        call = self._zenoh.caller(route.topic, route.type_name)

        def answer(correlation: bytes, reply: bytes) -> None:
            if self._closed or len(reply) < 4:
                return
            if ddspy_write(writer_ref, _padded(reply[:4] + correlation + reply[4:])) < 0:
                log.warning("could not send a reply of %s to its DDS client", route.topic)
            else:
                live.stats["samples"] += 1

        def on_request(_reader: Any = None) -> None:
            ref = state["ref"]
            if ref is None or self._closed:
                return
            for data, info in ddspy_take(ref, mask, _TAKE_BATCH):
                raw = bytes(data)
                if not info.valid_data or len(raw) < 20:
                    continue
                correlation = raw[4:20]
                call(raw[:4] + raw[20:], functools.partial(answer, correlation))

        reader = DataReader(self._subscriber, self._topic(
            route.topic, route.type_name + "_Request", f"rq/{name}Request"), qos=qos,
            listener=Listener(on_data_available=on_request))
        state["ref"] = reader._ref
        on_request()

        def close() -> None:
            state["ref"] = None
            _delete(reader)
            _delete(writer)

        live.close = close
        return live


# -- the Zenoh side of routes ----------------------------------------------------------------
class _ZenohSide:
    """Raw-CDR publishers and subscribers on the transport's session, announced with
    liveliness tokens under the bridge's node, exactly as the transport lays them out.

    The transport's own publishers serialize messages; the bridge passes bytes through, so it
    declares its Zenoh endpoints itself (same keys, QoS, attachment and tokens).
    """

    #: Entity ids of the bridge's endpoints: far above the transport's counter.
    _FIRST_ID = 1 << 40

    def __init__(self, transport: ZenohTransport, node: Any) -> None:
        self.transport = transport
        self.session = transport.session
        self.node = node
        node_id = getattr(transport, "_node_id", None)
        self.node_id = int(node_id(node)) if callable(node_id) else 0
        self._next = self._FIRST_ID
        self._lock = threading.Lock()
        self._open: list[Any] = []

    def _entity(self, kind: str, topic: str, type_name: str, qos: QoSProfile) -> tuple[Any, str]:
        with self._lock:
            eid, self._next = self._next, self._next + 1
        key = liveliness_key(self.transport.domain, self.transport.zid, self.node_id, eid, kind,
                             self.node.get_namespace(), self.node.get_name(), topic, type_name,
                             qos)
        return self.session.liveliness().declare_token(key), key

    def publish(self, topic: str, type_name: str, qos: QoSProfile) -> _ZenohPublisher:
        import zenoh

        key = topic_key(self.transport.domain, topic, type_name)
        reliable = qos.reliability != ReliabilityPolicy.BEST_EFFORT
        rel = zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT
        cc = zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
        if qos.transient_local:
            import zenoh.ext as zext

            zpub = zext.declare_advanced_publisher(
                self.session, key, congestion_control=cc, reliability=rel,
                cache=zext.CacheConfig(max_samples=max(1, qos.depth)),
                publisher_detection=True, allowed_destination=zenoh.Locality.REMOTE,
            )
        else:
            zpub = self.session.declare_publisher(
                key, congestion_control=cc, reliability=rel,
                allowed_destination=zenoh.Locality.REMOTE,
            )
        token, lkey = self._entity("MP", topic, type_name, qos)
        return _ZenohPublisher(zpub, token, entity_gid(lkey), self.transport)

    def subscribe(self, topic: str, type_name: str, qos: QoSProfile,
                  on_sample: Callable[[bytes], None]) -> _ZenohSubscriber:
        import zenoh

        key = topic_key(self.transport.domain, topic, type_name)

        def handler(sample: Any) -> None:
            try:
                on_sample(sample.payload.to_bytes())
            except Exception:
                log.exception("dropping a sample of %s on its way to DDS", topic)

        if qos.transient_local:
            import zenoh.ext as zext

            zsub = zext.declare_advanced_subscriber(
                self.session, key, handler, allowed_origin=zenoh.Locality.REMOTE,
                history=zext.HistoryConfig(detect_late_publishers=True,
                                           max_samples=max(1, qos.depth)),
            )
        else:
            zsub = self.session.declare_subscriber(key, handler,
                                                   allowed_origin=zenoh.Locality.REMOTE)
        token, _ = self._entity("MS", topic, type_name, qos)
        return _ZenohSubscriber(zsub, token)


    def caller(self, name: str, srv_type: str) -> Callable[[bytes, Callable[[bytes], None]], None]:
        """``call(request_cdr, on_reply)``: a raw call of the service ``name`` (a Zenoh get
        on its queryable); ``on_reply`` gets the response's CDR, nothing on an error."""
        import zenoh

        key = topic_key(self.transport.domain, name, srv_type, service=True)
        gid = entity_gid(f"{self.transport.zid}/dds-bridge/{name}")
        clock = self.transport.context.system_clock
        seq = [0]

        def call(request: bytes, on_reply: Callable[[bytes], None]) -> None:
            seq[0] += 1

            def handle(reply: Any) -> None:
                try:
                    if reply.ok is not None:
                        on_reply(reply.ok.payload.to_bytes())
                    else:
                        log.warning("service %s answered a DDS client with an error: %s",
                                    name, reply.err.payload.to_string())
                except Exception:
                    log.exception("passing a reply of %s to DDS", name)

            self.session.get(key, handle, payload=request,
                             attachment=encode_attachment(seq[0], clock.now_ns(), gid),
                             target=zenoh.QueryTarget.ALL_COMPLETE, timeout=60.0)

        return call


class _ZenohPublisher:
    def __init__(self, zpub: Any, token: Any, gid: bytes, transport: ZenohTransport) -> None:
        self._zpub, self._token, self._gid = zpub, token, gid
        self._clock = transport.context.system_clock
        self._seq = 0

    def put(self, cdr: bytes, source_timestamp_ns: int | None = None) -> None:
        self._seq += 1
        ts = source_timestamp_ns if source_timestamp_ns and source_timestamp_ns > 0 \
            else self._clock.now_ns()
        try:
            self._zpub.put(cdr, attachment=encode_attachment(self._seq, ts, self._gid))
        except Exception as exc:
            log.debug("zenoh put failed: %s", exc)

    def close(self) -> None:
        _undeclare(self._token)
        _undeclare(self._zpub)


class _ZenohSubscriber:
    def __init__(self, zsub: Any, token: Any) -> None:
        self._zsub, self._token = zsub, token

    def close(self) -> None:
        _undeclare(self._token)
        _undeclare(self._zsub)


def _undeclare(handle: Any) -> None:
    try:
        handle.undeclare()
    except Exception:
        pass


def _delete(entity: Any) -> None:
    """Delete a Cyclone entity now rather than at garbage collection."""
    try:
        entity.__del__()  # idempotent: it leaves the entity registry first
    except Exception:
        pass


def _quietly(fn: Callable[[], None]) -> None:
    try:
        fn()
    except Exception as exc:
        log.debug("closing a route: %s", exc)

