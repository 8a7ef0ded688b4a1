"""The process-wide graph: topics, services and the transports that link it to other processes.

A ``Context`` is what ``rclpy.init()`` creates: it knows every publisher, subscription,
service and client of the nodes in this process, and delivers in-process messages by
reference (zero copy). A transport (``eddiebot.transport``) attached to the context carries
topics and services to other processes; the context asks it to forward only what somebody
outside may want.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from eddiebot.core.errors import TopicTypeMismatchError
from eddiebot.core.time import Clock, SimClock

if TYPE_CHECKING:
    from eddiebot.core.node import Node, Publisher, Service, Subscription


class Transport(Protocol):
    """What the context needs of an inter-process transport."""

    def on_publisher_added(self, pub: Publisher) -> None: ...
    def on_publisher_removed(self, pub: Publisher) -> None: ...
    def on_subscription_added(self, sub: Subscription) -> None: ...
    def on_subscription_removed(self, sub: Subscription) -> None: ...
    def on_service_added(self, srv: Service) -> None: ...
    def on_service_removed(self, srv: Service) -> None: ...
    def on_node_added(self, node: Node) -> None: ...
    def on_node_removed(self, node: Node) -> None: ...
    def publish(self, pub: Publisher, msg: Any) -> None: ...
    def call_service(
        self, name: str, srv_type: Any, request: Any,
        done: Callable[[Any, BaseException | None], None], *, client: Any = None,
    ) -> bool: ...
    def service_is_ready(self, name: str) -> bool: ...
    def graph(self) -> dict[str, Any]: ...
    def close(self) -> None: ...


@dataclass
class TopicEntry:
    """Everything this process knows of one topic."""

    name: str
    type_name: str | None = None
    publishers: list[Publisher] = field(default_factory=list)
    subscriptions: list[Subscription] = field(default_factory=list)


class Context:
    """One process's share of the ROS graph (``rclpy.init`` creates the default one)."""

    def __init__(self, *, use_sim_time: bool = False, domain_id: int | None = None) -> None:
        import os

        self.domain_id = int(os.environ.get("ROS_DOMAIN_ID", "0")) if domain_id is None else domain_id
        self._lock = threading.RLock()
        self.topics: dict[str, TopicEntry] = {}
        self.services: dict[str, Service] = {}
        self.nodes: list[Node] = []
        self.transports: list[Transport] = []
        self.use_sim_time = use_sim_time
        self.sim_clock = SimClock()
        self.system_clock = Clock()
        self._ok = True
        #: Parameter overrides from files and command lines, consulted by every new node.
        self.parameter_sources: list[Any] = []
        #: Objects shared between nodes of this process by name (the simulator puts its
        #: firmware emulator here as ``"emulator"`` for the board node's in-process link).
        self.resources: dict[str, Any] = {}
        #: Called with (node, level, text) for every log line (``/rosout``; see clock_node).
        self.rosout_hook: Callable[[Any, int, str], None] | None = None
        self._safety_stops: list[Callable[[str, bool], None]] = []
        #: Called with a topic name whenever a publisher or subscription of this process
        #: comes or goes on it (QoS matched/incompatible events follow the graph)
        self.graph_listeners: list[Callable[[str], None]] = []

    # -- safety -------------------------------------------------------------------------
    def add_safety_stop(self, stop: Callable[[str, bool], None]) -> None:
        """Register ``stop(reason, from_signal)``: something that can stop motors.

        :meth:`safety_stop` calls it when a callback of any node raises, and the launcher
        calls it on every terminating signal before anything unwinds. With ``from_signal``
        it runs inside a signal handler: it must only do thread-safe work."""
        with self._lock:
            self._safety_stops.append(stop)

    def remove_safety_stop(self, stop: Callable[[str, bool], None]) -> None:
        with self._lock:
            if stop in self._safety_stops:
                self._safety_stops.remove(stop)

    def safety_stop(self, reason: str, *, from_signal: bool = False) -> None:
        """Ask every registered safety stop to stop its motors now (never raises)."""
        for stop in list(self._safety_stops):
            try:
                stop(reason, from_signal)
            except Exception:  # a stop hook must never take the caller down
                pass

    # -- life ---------------------------------------------------------------------------
    def ok(self) -> bool:
        return self._ok

    def shutdown(self) -> None:
        with self._lock:
            if not self._ok:
                return
            self._ok = False
            nodes = list(self.nodes)
        for node in nodes:
            node.destroy_node()
        for t in list(self.transports):
            t.close()
        self.transports.clear()

    def attach_transport(self, transport: Transport) -> None:
        """Link this context to other processes; existing endpoints are announced."""
        with self._lock:
            self.transports.append(transport)
            for node in self.nodes:
                transport.on_node_added(node)
            for entry in self.topics.values():
                for pub in entry.publishers:
                    transport.on_publisher_added(pub)
                for sub in entry.subscriptions:
                    transport.on_subscription_added(sub)
            for srv in self.services.values():
                transport.on_service_added(srv)
            announce = getattr(transport, "on_client_added", None)
            if announce is not None:
                for node in self.nodes:
                    for client in node.clients:
                        announce(client)
            topics = list(self.topics)
        for topic in topics:
            self._graph_changed(topic)

    def _graph_changed(self, topic: str) -> None:
        for listener in list(self.graph_listeners):
            listener(topic)

    # -- registry -----------------------------------------------------------------------
    def _entry(self, topic: str, type_name: str) -> TopicEntry:
        entry = self.topics.get(topic)
        if entry is None:
            entry = self.topics[topic] = TopicEntry(topic, type_name)
        elif entry.type_name is None:
            entry.type_name = type_name
        elif entry.type_name != type_name:
            raise TopicTypeMismatchError(topic, entry.type_name, type_name)
        return entry

    def add_node(self, node: Node) -> None:
        with self._lock:
            self.nodes.append(node)
            for t in self.transports:
                t.on_node_added(node)

    def remove_node(self, node: Node) -> None:
        with self._lock:
            if node in self.nodes:
                self.nodes.remove(node)
            for t in self.transports:
                t.on_node_removed(node)

    def add_publisher(self, pub: Publisher) -> None:
        with self._lock:
            self._entry(pub.topic_name, pub.type_name).publishers.append(pub)
            for t in self.transports:
                t.on_publisher_added(pub)
        self._graph_changed(pub.topic_name)

    def remove_publisher(self, pub: Publisher) -> None:
        with self._lock:
            entry = self.topics.get(pub.topic_name)
            if entry and pub in entry.publishers:
                entry.publishers.remove(pub)
                self._forget_if_empty(entry)
            for t in self.transports:
                t.on_publisher_removed(pub)
        self._graph_changed(pub.topic_name)

    def add_subscription(self, sub: Subscription) -> None:
        with self._lock:
            entry = self._entry(sub.topic_name, sub.type_name)
            entry.subscriptions.append(sub)
            latched = [
                m
                for p in entry.publishers
                if p.qos.transient_local and sub.qos.transient_local
                for m in p.latched
            ]
            for t in self.transports:
                t.on_subscription_added(sub)
        for msg in latched:
            sub.deliver(msg)
        self._graph_changed(sub.topic_name)

    def remove_subscription(self, sub: Subscription) -> None:
        with self._lock:
            entry = self.topics.get(sub.topic_name)
            if entry and sub in entry.subscriptions:
                entry.subscriptions.remove(sub)
                self._forget_if_empty(entry)
            for t in self.transports:
                t.on_subscription_removed(sub)
        self._graph_changed(sub.topic_name)

    def _forget_if_empty(self, entry: TopicEntry) -> None:
        if not entry.publishers and not entry.subscriptions:
            del self.topics[entry.name]

    def add_service(self, srv: Service) -> None:
        with self._lock:
            if srv.srv_name in self.services:
                raise ValueError(f"service {srv.srv_name!r} is already served in this process")
            self.services[srv.srv_name] = srv
            for t in self.transports:
                t.on_service_added(srv)

    def remove_service(self, srv: Service) -> None:
        with self._lock:
            if self.services.get(srv.srv_name) is srv:
                del self.services[srv.srv_name]
            for t in self.transports:
                t.on_service_removed(srv)

    # -- delivery -----------------------------------------------------------------------
    def publish(self, pub: Publisher, msg: Any) -> None:
        """Hand ``msg`` to every local subscription (by reference) and to the transports."""
        entry = self.topics.get(pub.topic_name)
        if entry is not None:
            lifespan = pub.lifespan_ns
            if lifespan is None:
                for sub in entry.subscriptions:
                    sub.deliver(msg)
            else:
                expires = self.system_clock.now_ns() + lifespan
                for sub in entry.subscriptions:
                    sub.deliver(msg, expires_ns=expires)
        for t in self.transports:
            t.publish(pub, msg)

    def deliver_remote(self, topic: str, type_name: str, msg: Any,
                       expires_ns: int | None = None) -> None:
        """A message that arrived from another process (called by a transport thread);
        ``expires_ns``: system time its publisher's lifespan ends."""
        entry = self.topics.get(topic)
        if entry is None:
            return
        if entry.type_name is not None and entry.type_name != type_name:
            raise TopicTypeMismatchError(topic, entry.type_name, type_name)
        for sub in list(entry.subscriptions):
            sub.deliver(msg, expires_ns)

    def local_subscription_count(self, topic: str) -> int:
        entry = self.topics.get(topic)
        return len(entry.subscriptions) if entry else 0


_default_lock = threading.Lock()
_default: Context | None = None


def init(*, use_sim_time: bool = False, context: Context | None = None) -> Context:
    """Create (or adopt) the default context, as ``rclpy.init``."""
    global _default
    with _default_lock:
        if context is not None:
            _default = context
        elif _default is None or not _default.ok():
            _default = Context(use_sim_time=use_sim_time)
        return _default


def get_default_context() -> Context:
    """The default context, created on first use."""
    global _default
    with _default_lock:
        if _default is None or not _default.ok():
            _default = Context()
        return _default


def shutdown(context: Context | None = None) -> None:
    """Shut down ``context`` (default: the default one), destroying its nodes."""
    global _default
    ctx = context or _default
    if ctx is not None:
        ctx.shutdown()
    if ctx is _default:
        _default = None
