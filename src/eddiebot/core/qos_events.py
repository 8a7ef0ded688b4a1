"""QoS events of publishers and subscriptions, with rclpy's names.

``create_publisher(..., event_callbacks=PublisherEventCallbacks(...))`` and
``create_subscription(..., event_callbacks=SubscriptionEventCallbacks(...))`` take
callbacks that run on the node's executor with rclpy's info records:

- **matched**: the number of compatible endpoints on the other side changed (local ones
  and, through the transports' graph caches, those of other processes);
- **incompatible_qos**: an endpoint whose QoS cannot meet ours appeared (the policy is
  named; without a callback a warning is logged, as rclpy's default callback does). The
  pair is reported, not cut off: Zenoh delivers regardless, as under rmw_zenoh;
- **deadline**: a subscription received (a publisher sent) nothing for a whole
  ``deadline`` period of the node's clock;
- **liveliness**: a MANUAL_BY_TOPIC publisher that neither published nor called
  ``assert_liveliness()`` for a lease is *lost*; a subscription is told when the number of
  alive publishers changes;
- **message_lost**: samples from another process never arrived (a gap in a publisher's
  sequence numbers, as rmw_zenoh detects it).

Like rmw's status reads, events that arrive before the callback ran are folded into one
call whose ``*_change`` fields say how much changed since the previous call.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from eddiebot.core.qos import (
    LivelinessPolicy,
    QoSCompatibility,
    QoSPolicyKind,
    QoSProfile,
    duration_ns,
    qos_check_compatible,
)

if TYPE_CHECKING:
    from eddiebot.core.context import Context
    from eddiebot.core.node import CallbackGroup, Node, Timer

__all__ = [
    "PublisherEventCallbacks",
    "QoSLivelinessChangedInfo",
    "QoSLivelinessLostInfo",
    "QoSMessageLostInfo",
    "QoSOfferedDeadlineMissedInfo",
    "QoSOfferedIncompatibleQoSInfo",
    "QoSPublisherMatchedInfo",
    "QoSRequestedDeadlineMissedInfo",
    "QoSRequestedIncompatibleQoSInfo",
    "QoSSubscriptionMatchedInfo",
    "SubscriptionEventCallbacks",
]

log = logging.getLogger("eddiebot.qos")


@dataclass(frozen=True)
class QoSRequestedDeadlineMissedInfo:
    total_count: int
    total_count_change: int


@dataclass(frozen=True)
class QoSOfferedDeadlineMissedInfo:
    total_count: int
    total_count_change: int


@dataclass(frozen=True)
class QoSLivelinessLostInfo:
    total_count: int
    total_count_change: int


@dataclass(frozen=True)
class QoSMessageLostInfo:
    total_count: int
    total_count_change: int


@dataclass(frozen=True)
class QoSLivelinessChangedInfo:
    alive_count: int
    not_alive_count: int
    alive_count_change: int
    not_alive_count_change: int


@dataclass(frozen=True)
class QoSRequestedIncompatibleQoSInfo:
    total_count: int
    total_count_change: int
    last_policy_kind: QoSPolicyKind


@dataclass(frozen=True)
class QoSOfferedIncompatibleQoSInfo:
    total_count: int
    total_count_change: int
    last_policy_kind: QoSPolicyKind


@dataclass(frozen=True)
class QoSSubscriptionMatchedInfo:
    total_count: int
    total_count_change: int
    current_count: int
    current_count_change: int


@dataclass(frozen=True)
class QoSPublisherMatchedInfo:
    total_count: int
    total_count_change: int
    current_count: int
    current_count_change: int


_Callback = Callable[[Any], Any] | None


@dataclass
class SubscriptionEventCallbacks:
    deadline: _Callback = None
    incompatible_qos: _Callback = None
    liveliness: _Callback = None
    message_lost: _Callback = None
    matched: _Callback = None
    use_default_callbacks: bool = True


@dataclass
class PublisherEventCallbacks:
    deadline: _Callback = None
    incompatible_qos: _Callback = None
    liveliness: _Callback = None
    matched: _Callback = None
    use_default_callbacks: bool = True


class _Event:
    """One event kind of one endpoint: counters, and a callback run on the executor."""

    def __init__(self, node: Node, group: CallbackGroup, callback: Callable[[Any], Any],
                 make: Callable[[dict[str, int], dict[str, int], Any], Any], what: str) -> None:
        self.node = node
        self.callback_group = group
        self.callback = callback
        self._make = make
        self._what = what
        self._lock = threading.Lock()
        self.counts: dict[str, int] = {}
        self._read: dict[str, int] = {}  # counts at the previous callback
        self._extra: Any = None
        self._pending = False

    def update(self, extra: Any = None, **counts: int) -> None:
        """Set counters (thread-safe) and schedule the callback."""
        with self._lock:
            self.counts.update(counts)
            if extra is not None:
                self._extra = extra
            if self._pending:
                return
            self._pending = True
        self.node._notify(self)

    def execute(self) -> None:
        with self._lock:
            if not self._pending:
                return
            self._pending = False
            info = self._make(dict(self.counts), dict(self._read), self._extra)
            self._read = dict(self.counts)
        self.node._run_callback(self.callback, (info,), self._what)


def _count_info(cls: Any) -> Callable[[dict[str, int], dict[str, int], Any], Any]:
    def make(now: dict[str, int], before: dict[str, int], _extra: Any) -> Any:
        total = now.get("total", 0)
        return cls(total, total - before.get("total", 0))
    return make


def _incompatible_info(cls: Any) -> Callable[[dict[str, int], dict[str, int], Any], Any]:
    def make(now: dict[str, int], before: dict[str, int], extra: Any) -> Any:
        total = now.get("total", 0)
        return cls(total, total - before.get("total", 0), extra or QoSPolicyKind.INVALID)
    return make


def _matched_info(cls: Any) -> Callable[[dict[str, int], dict[str, int], Any], Any]:
    def make(now: dict[str, int], before: dict[str, int], _extra: Any) -> Any:
        total, current = now.get("total", 0), now.get("current", 0)
        return cls(total, total - before.get("total", 0), current,
                   current - before.get("current", 0))
    return make


def _liveliness_changed(now: dict[str, int], before: dict[str, int], _extra: Any) -> Any:
    alive, dead = now.get("alive", 0), now.get("not_alive", 0)
    return QoSLivelinessChangedInfo(alive, dead, alive - before.get("alive", 0),
                                    dead - before.get("not_alive", 0))


@dataclass(frozen=True)
class _Peer:
    key: str
    qos: QoSProfile
    alive: bool


class EndpointEvents:
    """The QoS events of one publisher or subscription (made by ``Node``)."""

    def __init__(self, endpoint: Any, callbacks: SubscriptionEventCallbacks | PublisherEventCallbacks,
                 *, publisher: bool, group: CallbackGroup | None = None) -> None:
        self.endpoint = endpoint
        self.publisher = publisher
        node: Node = endpoint.node
        self.node = node
        group = group or getattr(endpoint, "callback_group", None) or node._default_group
        side = "publisher" if publisher else "subscription"
        what = f"{side} {endpoint.topic_name!r} QoS event"
        self.matched: _Event | None = None
        self.incompatible: _Event | None = None
        self.deadline: _Event | None = None
        self.liveliness: _Event | None = None
        self.message_lost: _Event | None = None
        if callbacks.matched is not None:
            self.matched = _Event(node, group, callbacks.matched, _matched_info(
                QoSPublisherMatchedInfo if publisher else QoSSubscriptionMatchedInfo), what)
        incompatible_cb = callbacks.incompatible_qos
        if incompatible_cb is None and callbacks.use_default_callbacks:
            incompatible_cb = self._warn_incompatible
        if incompatible_cb is not None:
            self.incompatible = _Event(node, group, incompatible_cb, _incompatible_info(
                QoSOfferedIncompatibleQoSInfo if publisher else QoSRequestedIncompatibleQoSInfo),
                what)
        if callbacks.deadline is not None:
            self.deadline = _Event(node, group, callbacks.deadline, _count_info(
                QoSOfferedDeadlineMissedInfo if publisher else QoSRequestedDeadlineMissedInfo),
                what)
        if callbacks.liveliness is not None:
            self.liveliness = _Event(node, group, callbacks.liveliness, _count_info(
                QoSLivelinessLostInfo) if publisher else _liveliness_changed, what)
        if isinstance(callbacks, SubscriptionEventCallbacks) and callbacks.message_lost is not None:
            self.message_lost = _Event(node, group, callbacks.message_lost,
                                       _count_info(QoSMessageLostInfo), what)
        self._lock = threading.Lock()
        self._matched: set[str] = set()
        self._matched_total = 0
        self._incompatible_seen: set[str] = set()
        self._incompatible_total = 0
        self._alive: set[str] = set()
        self._not_alive: set[str] = set()
        self._lost_total = 0
        self._timers: list[Timer] = []
        #: activity (publish or receive) in the current deadline period / liveliness lease
        self.active_in_deadline = False
        self.asserted_in_lease = False  # the first lease starts now
        self.alive = True  # a MANUAL_BY_TOPIC publisher's own liveliness
        self._deadline_missed = 0
        self._liveliness_lost = 0
        qos: QoSProfile = endpoint.qos
        deadline_ns = duration_ns(qos.deadline)
        if deadline_ns is not None and self.deadline is not None:
            self._timers.append(node.create_timer(deadline_ns / 1e9, self._check_deadline,
                                                  callback_group=group))
        lease_ns = duration_ns(qos.liveliness_lease_duration)
        if publisher and lease_ns is not None and qos.liveliness == LivelinessPolicy.MANUAL_BY_TOPIC:
            self._timers.append(node.create_timer(lease_ns / 1e9, self._check_lease,
                                                  callback_group=group))
        _monitor(node.context).add(self)

    # -- activity -----------------------------------------------------------------------
    def on_activity(self) -> None:
        """A publish (publisher) or a received message (subscription)."""
        self.active_in_deadline = True
        if self.publisher:
            self.asserted_in_lease = True
            if not self.alive:
                self.alive = True
                _monitor(self.node.context).topic_changed(self.endpoint.topic_name)

    def on_messages_lost(self, count: int) -> None:
        if self.message_lost is None or count <= 0:
            return
        with self._lock:
            self._lost_total += count
            total = self._lost_total
        self.message_lost.update(total=total)

    def _check_deadline(self) -> None:
        if self.active_in_deadline:
            self.active_in_deadline = False
            return
        self._deadline_missed += 1
        if self.deadline is not None:
            self.deadline.update(total=self._deadline_missed)

    def _check_lease(self) -> None:
        if self.asserted_in_lease:
            self.asserted_in_lease = False
            return
        if self.alive:
            self.alive = False
            self._liveliness_lost += 1
            if self.liveliness is not None:
                self.liveliness.update(total=self._liveliness_lost)
            _monitor(self.node.context).topic_changed(self.endpoint.topic_name)

    # -- matching -----------------------------------------------------------------------
    def refresh(self, peers: list[_Peer]) -> None:
        """Re-evaluate the endpoints on the other side of the topic."""
        mine: QoSProfile = self.endpoint.qos
        compatible: set[str] = set()
        alive: set[str] = set()
        newly_incompatible: list[tuple[str, QoSPolicyKind, str]] = []
        for peer in peers:
            pub_qos, sub_qos = (mine, peer.qos) if self.publisher else (peer.qos, mine)
            verdict, reason, policy = qos_check_compatible(pub_qos, sub_qos)
            if verdict == QoSCompatibility.ERROR:
                if peer.key not in self._incompatible_seen:
                    newly_incompatible.append((peer.key, policy or QoSPolicyKind.INVALID, reason))
                continue
            compatible.add(peer.key)
            if peer.alive:
                alive.add(peer.key)
        with self._lock:
            gained = compatible - self._matched
            changed = compatible != self._matched
            self._matched_total += len(gained)
            self._matched = compatible
            matched_total = self._matched_total
            for key, _policy, _reason in newly_incompatible:
                self._incompatible_seen.add(key)
            self._incompatible_total += len(newly_incompatible)
            incompatible_total = self._incompatible_total
            not_alive = (self._not_alive | (self._alive - alive)) & compatible - alive
            live_changed = alive != self._alive or not_alive != self._not_alive
            self._alive, self._not_alive = alive, not_alive
        if changed and self.matched is not None:
            self.matched.update(total=matched_total, current=len(compatible))
        if newly_incompatible and self.incompatible is not None:
            self.incompatible.update(newly_incompatible[-1][1], total=incompatible_total)
            self._last_reason = newly_incompatible[-1][2]
        if live_changed and not self.publisher and self.liveliness is not None:
            self.liveliness.update(alive=len(alive), not_alive=len(not_alive))

    def _warn_incompatible(self, info: Any) -> None:
        side = "publisher" if self.publisher else "subscription"
        other = "subscription" if self.publisher else "publisher"
        log.warning(
            "node %s: %s on %s: a %s's QoS is incompatible (%s: %s)",
            self.node.fully_qualified_name, side, self.endpoint.topic_name, other,
            info.last_policy_kind.name, getattr(self, "_last_reason", ""))

    def destroy(self) -> None:
        for t in self._timers:
            self.node.destroy_timer(t)
        self._timers.clear()
        _monitor(self.node.context).remove(self)


class _Monitor:
    """Per context: re-evaluates the event-watching endpoints of a topic when its graph
    changes, here (context) or elsewhere (the transports' graph caches)."""

    def __init__(self, context: Context) -> None:
        self.context = context
        self._lock = threading.RLock()
        self._by_topic: dict[str, list[EndpointEvents]] = {}
        self._watched: set[int] = set()
        context.graph_listeners.append(self.topic_changed)

    def add(self, events: EndpointEvents) -> None:
        with self._lock:
            self._by_topic.setdefault(events.endpoint.topic_name, []).append(events)
        self._watch_caches()
        self.topic_changed(events.endpoint.topic_name)

    def remove(self, events: EndpointEvents) -> None:
        with self._lock:
            lst = self._by_topic.get(events.endpoint.topic_name, [])
            if events in lst:
                lst.remove(events)

    def _watch_caches(self) -> None:
        for t in list(self.context.transports):
            try:
                cache = t.graph().get("cache")
            except Exception:
                continue
            if cache is None or id(cache) in self._watched:
                continue
            self._watched.add(id(cache))
            cache.listeners.append(self._on_remote)

    def _on_remote(self, entity: Any, _alive: bool) -> None:
        if getattr(entity, "kind", "") in ("MP", "MS"):
            self.topic_changed(entity.name)

    def topic_changed(self, topic: str) -> None:
        with self._lock:
            watchers = list(self._by_topic.get(topic, ()))
        if not watchers:
            return
        self._watch_caches()
        entry = self.context.topics.get(topic)
        local_pubs = list(entry.publishers) if entry else []
        local_subs = list(entry.subscriptions) if entry else []
        remote_pubs: list[_Peer] = []
        remote_subs: list[_Peer] = []
        for t in list(self.context.transports):
            try:
                cache = t.graph().get("cache")
            except Exception:
                continue
            if cache is None:
                continue
            remote_pubs += [_Peer(e.key, e.qos_profile, True) for e in cache.publishers(topic)]
            remote_subs += [_Peer(e.key, e.qos_profile, True) for e in cache.subscriptions(topic)]
        for w in watchers:
            if w.publisher:
                peers = [_Peer(f"local/{id(s)}", s.qos, True) for s in local_subs] + remote_subs
            else:
                peers = [_Peer(f"local/{id(p)}", p.qos, _publisher_alive(p)) for p in local_pubs]
                peers += remote_pubs
            w.refresh(peers)


def _publisher_alive(pub: Any) -> bool:
    events = getattr(pub, "events", None)
    return events.alive if events is not None else True


def _monitor(context: Context) -> _Monitor:
    monitor = context.resources.get("_qos_event_monitor")
    if monitor is None:
        monitor = context.resources["_qos_event_monitor"] = _Monitor(context)
    return monitor  # type: ignore[no-any-return]
