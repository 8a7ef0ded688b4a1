"""The node graph API (rclpy's ``Node.get_topic_names_and_types`` and friends).

Answers come from two places: this process's context (its nodes and their publishers,
subscriptions, services and clients) and every attached transport's graph cache (the other
processes, from their liveliness tokens). Names are resolved against the asking node as
rclpy does (``count_publishers("scan")`` in namespace ``/robot`` counts ``/robot/scan``).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from eddiebot.core._xxh3 import xxh3_128
from eddiebot.core.qos import QoSProfile
from eddiebot.msgs import type_hash

if TYPE_CHECKING:
    from eddiebot.core.context import Context

__all__ = ["GraphQueries", "TopicEndpointInfo", "TopicEndpointTypeEnum"]


class TopicEndpointTypeEnum(enum.IntEnum):
    """rclpy's ``TopicEndpointTypeEnum``."""

    INVALID = 0
    PUBLISHER = 1
    SUBSCRIPTION = 2


@dataclass(frozen=True)
class TopicEndpointInfo:
    """One publisher or subscription of a topic (rclpy's ``TopicEndpointInfo``)."""

    node_name: str
    node_namespace: str
    topic_type: str
    topic_type_hash: str
    endpoint_type: TopicEndpointTypeEnum
    endpoint_gid: bytes
    qos_profile: QoSProfile


def _remote_caches(context: Context) -> list[Any]:
    caches = []
    for t in context.transports:
        try:
            cache = t.graph().get("cache")
        except Exception:  # a transport closing under us
            continue
        if cache is not None:
            caches.append(cache)
    return caches


def _local_gid(context: Context, owner: Any) -> bytes:
    """The GID the transport announced for ``owner``; without a transport, a process-local
    one (unique while the entity lives)."""
    for t in context.transports:
        lookup = getattr(t, "entity_gid_of", None)
        gid = lookup(owner) if lookup is not None else None
        if gid is not None:
            return bytes(gid)

    low, high = xxh3_128(f"local/{id(context)}/{id(owner)}".encode())
    return low.to_bytes(8, "little") + high.to_bytes(8, "little")


def _type_hash(type_name: str) -> str:
    try:
        return str(type_hash(type_name))
    except KeyError:
        return "TypeHashNotSupported"  # rmw_zenoh's word for a type without a hash


class GraphQueries:
    """Graph queries of a node; mixed into ``Node`` (needs ``context`` and name resolution)."""

    context: Context

    def resolve_topic_name(self, name: str, *, only_expand: bool = False) -> str:  # pragma: no cover
        raise NotImplementedError

    # -- nodes ----------------------------------------------------------------------------
    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        """(name, namespace) of every node on the graph, sorted."""
        found = {(n.get_name(), n.get_namespace()) for n in list(self.context.nodes)}
        for cache in _remote_caches(self.context):
            found.update((e.node_name, e.namespace) for e in cache.nodes())
        return sorted(found, key=lambda nn: (nn[1], nn[0]))

    def get_node_names(self) -> list[str]:
        return [name for name, _ in self.get_node_names_and_namespaces()]

    def get_fully_qualified_node_names(self) -> list[str]:
        return [f"{ns.rstrip('/')}/{name}" for name, ns in self.get_node_names_and_namespaces()]

    # -- topics and services --------------------------------------------------------------
    def get_topic_names_and_types(self, no_demangle: bool = False) -> list[tuple[str, list[str]]]:
        """Every topic with a publisher or subscription anywhere, with its types, sorted."""
        del no_demangle  # names are never mangled here
        found: dict[str, set[str]] = {}
        for entry in list(self.context.topics.values()):
            if entry.type_name and (entry.publishers or entry.subscriptions):
                found.setdefault(entry.name, set()).add(entry.type_name)
        for cache in _remote_caches(self.context):
            for topic, types in cache.topic_types().items():
                found.setdefault(topic, set()).update(types)
        return [(t, sorted(found[t])) for t in sorted(found)]

    def get_service_names_and_types(self) -> list[tuple[str, list[str]]]:
        found: dict[str, set[str]] = {}
        for srv in list(self.context.services.values()):
            found.setdefault(srv.srv_name, set()).add(srv.srv_type.name)
        for cache in _remote_caches(self.context):
            for name, types in cache.service_types().items():
                found.setdefault(name, set()).update(types)
        return [(s, sorted(found[s])) for s in sorted(found)]

    def get_publisher_names_and_types_by_node(
        self, node_name: str, node_namespace: str
    ) -> list[tuple[str, list[str]]]:
        return self._by_node(node_name, node_namespace, "MP")

    def get_subscriber_names_and_types_by_node(
        self, node_name: str, node_namespace: str
    ) -> list[tuple[str, list[str]]]:
        return self._by_node(node_name, node_namespace, "MS")

    def get_service_names_and_types_by_node(
        self, node_name: str, node_namespace: str
    ) -> list[tuple[str, list[str]]]:
        return self._by_node(node_name, node_namespace, "SS")

    def get_client_names_and_types_by_node(
        self, node_name: str, node_namespace: str
    ) -> list[tuple[str, list[str]]]:
        return self._by_node(node_name, node_namespace, "SC")

    def _by_node(self, name: str, namespace: str, kind: str) -> list[tuple[str, list[str]]]:
        found: dict[str, set[str]] = {}
        ns = namespace or "/"
        for node in list(self.context.nodes):
            if node.get_name() != name or node.get_namespace() != ns:
                continue
            entities: list[tuple[str, str]] = {
                "MP": [(p.topic_name, p.type_name) for p in node.publishers],
                "MS": [(s.topic_name, s.type_name) for s in node.subscriptions],
                "SS": [(s.srv_name, s.srv_type.name) for s in node.services],
                "SC": [(c.srv_name, c.srv_type.name) for c in node.clients],
            }[kind]
            for topic, type_name in entities:
                found.setdefault(topic, set()).add(type_name)
        for cache in _remote_caches(self.context):
            for e in cache.entities(kind):
                if e.node_name == name and e.namespace == ns:
                    found.setdefault(e.name, set()).add(e.type_name)
        return [(t, sorted(found[t])) for t in sorted(found)]

    # -- counts ---------------------------------------------------------------------------
    def count_publishers(self, topic_name: str) -> int:
        return len(self.get_publishers_info_by_topic(topic_name))

    def count_subscribers(self, topic_name: str) -> int:
        return len(self.get_subscriptions_info_by_topic(topic_name))

    def count_services(self, service_name: str) -> int:
        name = self.resolve_topic_name(service_name)
        n = 1 if name in self.context.services else 0
        return n + sum(len(c.services(name)) for c in _remote_caches(self.context))

    def count_clients(self, service_name: str) -> int:
        name = self.resolve_topic_name(service_name)
        n = sum(1 for node in list(self.context.nodes) for c in node.clients if c.srv_name == name)
        return n + sum(len(c.clients(name)) for c in _remote_caches(self.context))

    # -- endpoint details -----------------------------------------------------------------
    def get_publishers_info_by_topic(
        self, topic_name: str, no_mangle: bool = False
    ) -> list[TopicEndpointInfo]:
        """Every publisher of ``topic_name`` (this process's and the others')."""
        return self._endpoints(topic_name, no_mangle, TopicEndpointTypeEnum.PUBLISHER)

    def get_subscriptions_info_by_topic(
        self, topic_name: str, no_mangle: bool = False
    ) -> list[TopicEndpointInfo]:
        return self._endpoints(topic_name, no_mangle, TopicEndpointTypeEnum.SUBSCRIPTION)

    def _endpoints(self, topic_name: str, no_mangle: bool,
                   kind: TopicEndpointTypeEnum) -> list[TopicEndpointInfo]:
        topic = topic_name if no_mangle else self.resolve_topic_name(topic_name)
        out: list[TopicEndpointInfo] = []
        entry = self.context.topics.get(topic)
        if entry is not None:
            local: list[Any] = list(entry.publishers if kind == TopicEndpointTypeEnum.PUBLISHER
                                    else entry.subscriptions)
            for e in local:
                out.append(TopicEndpointInfo(
                    e.node.get_name(), e.node.get_namespace(), e.type_name,
                    _type_hash(e.type_name), kind, _local_gid(self.context, e), e.qos))
        token_kind = "MP" if kind == TopicEndpointTypeEnum.PUBLISHER else "MS"
        for cache in _remote_caches(self.context):
            for r in cache.entities(token_kind, topic):
                out.append(TopicEndpointInfo(
                    r.node_name, r.namespace, r.type_name, r.type_hash, kind, r.gid,
                    r.qos_profile))
        return out
