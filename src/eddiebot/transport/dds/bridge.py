"""The bridge: routes chosen from both graphs at every discovery pass, the DDS graph shown on
ours as liveliness tokens, ours shown on DDS through ``ros_discovery_info``."""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from eddiebot.core.qos import QoSProfile
from eddiebot.msgs import normalize_type_name
from eddiebot.transport.dds.types import (
    dds_type,
    known,
    merge_publisher_qos,
    qos_from_dds,
    ros_topic_name,
    service_dds_type,
    service_names,
    type_hash_of,
    user_data_fields,
)
from eddiebot.transport.errors import TransportError
from eddiebot.transport.keys import ros_type_name, service_type_hash

if TYPE_CHECKING:
    from eddiebot.core.context import Context
    from eddiebot.transport.dds.discovery import DdsEndpoint, DdsNode
    from eddiebot.transport.dds.zenoh_side import TokenSpec
    from eddiebot.transport.zenoh import ZenohTransport

__all__ = ["DIRECTIONS", "DdsBridge", "DdsBridgeConfig", "Live", "Route", "delete_entity"]

log = logging.getLogger("eddiebot.transport.dds")

#: Route directions: topics ``to_dds`` / ``from_dds``; ``service``: served on our graph for
#: DDS clients; ``dds_service``: served on DDS (rmw_cyclonedds) for our clients;
#: ``unreachable_service``: served on DDS only by implementations the bridge cannot call.
DIRECTIONS = ("to_dds", "from_dds", "service", "dds_service", "unreachable_service")
#: The owner id of endpoints that belong to no known DDS node: the bridge's own node.
_BRIDGE = "bridge"


@dataclass
class DdsBridgeConfig:
    """What the bridge joins and which topics it carries.

    ``allow`` / ``deny``: regular expressions searched in the ROS topic or service name
    (``/odom``); a name is bridged when ``allow`` matches (or is None) and ``deny`` does not.
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
    """One bridged (name, type) in one of :data:`DIRECTIONS`; ``vendor`` names the DDS
    implementation of an unreachable service's servers."""

    topic: str
    type_name: str
    direction: str
    qos: QoSProfile
    vendor: str = ""


@dataclass
class Live:
    """An open route: how to close it, what it carried, and the GUIDs of the bridge's DDS
    readers and writers that serve it (listed under nodes in ``ros_discovery_info``)."""

    route: Route
    close: Callable[[], None] = lambda: None
    stats: dict[str, int] = field(default_factory=lambda: {"samples": 0})
    readers: list[bytes] = field(default_factory=list)
    writers: list[bytes] = field(default_factory=list)
    pending: Any = None


class DdsBridge:
    """Mirrors topics and services between ``context``'s graph (through its Zenoh
    ``transport``) and a DDS domain; :meth:`start` runs discovery in a thread,
    :meth:`close` undoes everything."""

    def __init__(self, context: Context, transport: ZenohTransport,
                 config: DdsBridgeConfig | None = None) -> None:
        try:
            from cyclonedds.domain import Domain, DomainParticipant
            from cyclonedds.pub import Publisher
            from cyclonedds.qos import Policy, Qos
            from cyclonedds.sub import Subscriber
        except ImportError as exc:  # pragma: no cover - a dependency of the package
            raise TransportError(f"the DDS bridge needs cyclonedds: {exc}") from exc
        from eddiebot.core.node import Node
        from eddiebot.transport.dds.discovery import DdsDiscovery
        from eddiebot.transport.dds.types import cyclone_config
        from eddiebot.transport.dds.zenoh_side import GraphTokens, ZenohSide

        self.context = context
        self.transport = transport
        self.config = config or DdsBridgeConfig()
        self._lock = threading.RLock()
        self.closed = False
        self._routes: dict[tuple[str, str, str], Live] = {}
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._topics: dict[tuple[str, str], Any] = {}
        self.node = Node(self.config.node_name, context=context, start_parameter_services=False)
        self.zenoh = ZenohSide(transport)
        self.tokens = GraphTokens(transport)
        node_id = getattr(transport, "_node_id", None)
        if callable(node_id):
            self.tokens.alias(_BRIDGE, int(node_id(self.node)))
        self.discovery: Any = None
        try:
            try:
                self._domain = Domain(self.config.domain_id, cyclone_config(self.config.network))
            except Exception as exc:
                raise TransportError(
                    f"cannot join DDS domain {self.config.domain_id}: {exc}") from exc
            self.participant = DomainParticipant(
                self.config.domain_id, qos=Qos(Policy.Userdata(b"enclave=/;")))
            self.dds_publisher = Publisher(self.participant)
            self.dds_subscriber = Subscriber(self.participant)
            self.discovery = DdsDiscovery(self.participant, self.dds_publisher,
                                          self.dds_subscriber)
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
                if self.closed:
                    return
                log.exception("DDS bridge discovery pass failed")
            self._stop.wait(self.config.poll_period_s)

    def close(self) -> None:
        """Close every route and leave both graphs; also after a Ctrl-C half-way through
        (each route is closed even if closing another one is interrupted)."""
        if self.closed:
            return
        self.closed = True
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        with self._lock:
            lives = list(self._routes.values())
            self._routes.clear()
        try:
            for live in lives:
                _quietly(live.close)
            _quietly(self.tokens.close)
        finally:
            self.node.destroy_node()
        # Cyclone's entities go with their Python objects; drop the participant last
        self._topics.clear()
        for name in ("discovery", "dds_publisher", "dds_subscriber", "participant", "_domain"):
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
        """Samples (or calls) carried per (name, direction)."""
        with self._lock:
            return {(k[0], k[2]): live.stats["samples"] for k, live in self._routes.items()}

    def step(self) -> None:
        """One discovery pass: open the routes both graphs now call for, close the others,
        and bring each graph's view of the other up to date."""
        if self.closed:
            return
        self.discovery.poll()
        wanted = self._wanted_routes()
        with self._lock:
            current = dict(self._routes)
        for key, live in current.items():
            if wanted.get(key) is None or (
                    key[2] == "unreachable_service" and wanted[key].vendor != live.route.vendor):
                log.info("unbridged %s [%s] (%s; %s)", key[0], key[1], key[2], live.stats)
                with self._lock:
                    self._routes.pop(key, None)
                _quietly(live.close)
            elif live.pending is not None:
                live.pending.expire(time.monotonic())
        for key, route in wanted.items():
            with self._lock:
                if key in self._routes or self.closed:
                    continue
            if not self._open(key, route):
                return
        self._mirror_graph()

    def _open(self, key: tuple[str, str, str], route: Route) -> bool:
        from eddiebot.transport.dds.services import (
            open_dds_service,
            open_service,
            open_unreachable_service,
        )
        from eddiebot.transport.dds.topics import open_from_dds, open_to_dds

        opener = {"to_dds": open_to_dds, "from_dds": open_from_dds, "service": open_service,
                  "dds_service": open_dds_service,
                  "unreachable_service": open_unreachable_service}[route.direction]
        try:
            live = opener(self, route)
        except Exception as exc:
            log.warning("cannot bridge %s [%s] %s: %s", route.topic, route.type_name,
                        route.direction, exc)
            return True
        with self._lock:
            closed = self.closed
            if not closed:
                self._routes[key] = live
        if closed:
            _quietly(live.close)
            return False
        log.info("bridged %s [%s] %s (%s, %s, %s %d)", route.topic, route.type_name,
                 route.direction, route.qos.reliability.name.lower(),
                 route.qos.durability.name.lower(), route.qos.history.name.lower(),
                 route.qos.depth)
        return True

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
            if self.config.admits(e.name) and known(e.type_name):
                ours.setdefault((e.name, e.type_name), []).append(_qos_of(e))
        for (topic, ros_type), profiles in ours.items():
            wanted[(topic, ros_type, "to_dds")] = Route(topic, ros_type, "to_dds",
                                                        merge_publisher_qos(profiles))
        # DDS side: publications of other participants
        theirs: dict[tuple[str, str], list[QoSProfile]] = {}
        for ep in self.discovery.publications():
            name = ros_topic_name(ep.topic)
            if name is None or not self.config.admits(name):
                continue
            ros_type = ros_type_name(ep.type_name)
            if "/" not in ros_type or not known(ros_type):
                continue
            theirs.setdefault((name, normalize_type_name(ros_type)), []).append(
                qos_from_dds(ep.qos))
        for (topic, ros_type), profiles in theirs.items():
            wanted[(topic, ros_type, "from_dds")] = Route(topic, ros_type, "from_dds",
                                                          merge_publisher_qos(profiles))
        # services served in our graph, for ROS 2 clients on DDS
        for e in self.transport.cache.services():
            if self.config.admits(e.name) and known(e.type_name + "_Request"):
                wanted[(e.name, e.type_name, "service")] = Route(
                    e.name, e.type_name, "service", QoSProfile(depth=10))
        # services served on DDS (their request readers), for our clients
        servers: dict[tuple[str, str], set[str]] = {}
        for ep in self.discovery.subscriptions():
            names = service_names(ep.topic, ep.type_name)
            if names is None or names[2] != "request" or not self.config.admits(names[0]):
                continue
            if known(names[1] + "_Request") and known(names[1] + "_Response"):
                servers.setdefault((names[0], names[1]), set()).add(ep.vendor)
        for (name, srv_type), vendors in servers.items():
            if "Cyclone DDS" in vendors:
                wanted[(name, srv_type, "dds_service")] = Route(
                    name, srv_type, "dds_service", QoSProfile(depth=10))
            else:
                wanted[(name, srv_type, "unreachable_service")] = Route(
                    name, srv_type, "unreachable_service", QoSProfile(depth=10),
                    vendor=" and ".join(sorted(vendors)))
        return wanted

    # -- each graph's view of the other ---------------------------------------------------
    def _mirror_graph(self) -> None:
        """DDS nodes and endpoints → our liveliness tokens; our nodes with the bridge's DDS
        endpoints that stand in for them → the bridge's ``ros_discovery_info``."""
        nodes = self.discovery.nodes()
        owner: dict[tuple[str, bytes], DdsNode] = {}
        wanted: dict[TokenSpec, str] = {}
        for n in nodes:
            wanted[(n.owner_id, "NN", n.namespace, n.name, "", "", None, "")] = n.owner_id
            owner.update({("w", g): n for g in n.writers})
            owner.update({("r", g): n for g in n.readers})
        for side, endpoints in (("w", self.discovery.publications()),
                                ("r", self.discovery.subscriptions())):
            for ep in endpoints:
                spec = self._token_spec(ep, side, owner.get((side, ep.guid)))
                if spec is not None:
                    wanted[spec[0]] = spec[1]
        self.tokens.update(wanted)
        self.discovery.announce(self._our_nodes())

    def _token_spec(self, ep: DdsEndpoint, side: str,
                    node: DdsNode | None) -> tuple[TokenSpec, str] | None:
        ns, name, node_owner = (node.namespace, node.name, node.owner_id) if node is not None \
            else (self.node.get_namespace(), self.node.get_name(), _BRIDGE)
        hash_ = user_data_fields(ep.qos).get("typehash", "")
        topic = ros_topic_name(ep.topic)
        if topic is not None:
            ros_type = ros_type_name(ep.type_name)
            kind = "MP" if side == "w" else "MS"
            hash_ = hash_ or (type_hash_of(ros_type) if known(ros_type) else "")
            qos: QoSProfile | None = qos_from_dds(ep.qos)
        else:
            names = service_names(ep.topic, ep.type_name)
            if names is None or names[2] != "request":
                return None  # a service's reply topic: its request topic stands for it
            topic, ros_type = names[0], names[1]
            kind = "SC" if side == "w" else "SS"
            if known(ros_type + "_Request") and known(ros_type + "_Response"):
                hash_ = service_type_hash(ros_type)
            qos = None
        if "/" not in ros_type or not hash_ or not self.config.admits(topic):
            return None
        return (ep.guid.hex(), kind, ns, name, topic, ros_type, qos, hash_), node_owner

    def _our_nodes(self) -> list[tuple[str, str, list[bytes], list[bytes]]]:
        """Our graph's nodes (and the bridge's), each with the GIDs of the bridge's DDS
        readers and writers that carry its topics and services."""
        cache = self.transport.cache
        me = (self.node.get_namespace(), self.node.get_name())
        gids: dict[tuple[str, str], tuple[list[bytes], list[bytes]]] = {me: ([], [])}
        for n in cache.nodes():
            gids.setdefault((n.namespace, n.node_name), ([], []))
        kinds = {"to_dds": "MP", "from_dds": "MS", "service": "SS", "dds_service": "SC"}
        with self._lock:
            lives = list(self._routes.values())
        for live in lives:
            kind = kinds.get(live.route.direction)
            if kind is None:
                continue
            owners = {(e.namespace, e.node_name) for e in cache.entities(kind, live.route.topic)
                      if e.type_name == live.route.type_name} or {me}
            for o in owners:
                readers, writers = gids.setdefault(o, ([], []))
                readers.extend(live.readers)
                writers.extend(live.writers)
        return [(ns, name, r, w) for (ns, name), (r, w) in gids.items()]

    # -- DDS entities -------------------------------------------------------------------
    def topic(self, topic: str, type_name: str, dds_name: str | None = None) -> Any:
        """The bridge's DDS topic of a ROS topic (or, given ``dds_name``, of a service's
        request or reply type, with rmw_cyclonedds's correlation header)."""
        from cyclonedds.topic import Topic

        from eddiebot.transport.dds.types import dds_topic_name

        name = dds_name or dds_topic_name(topic)
        key = (name, type_name)
        if key not in self._topics:
            cls = dds_type(type_name) if dds_name is None else service_dds_type(type_name)
            self._topics[key] = Topic(self.participant, name, cls)
        return self._topics[key]

    def user_data(self, type_name: str) -> bytes:
        return f"typehash={type_hash_of(type_name)};".encode()


def _qos_of(entity: Any) -> QoSProfile:
    from eddiebot.transport.keys import qos_from_keyexpr

    return qos_from_keyexpr(entity.qos)


def delete_entity(entity: Any) -> None:
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
