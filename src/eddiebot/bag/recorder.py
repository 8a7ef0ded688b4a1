"""Recording: ``RecorderNode``, ``ros2 bag record`` as a node.

It subscribes to topics as they appear (the context's topic registry and the transports'
graphs) and writes each message at its receive time on the node clock (sim time in a
simulation) through a ``BagWriter``. A type nothing here describes is recorded as raw CDR with
an empty schema, as rosbag2 does.
"""

from __future__ import annotations

import datetime as _dt
import re
from pathlib import Path
from typing import Any

from eddiebot.bag.errors import BagError
from eddiebot.bag.writer import BagWriter
from eddiebot.core.node import Node, Publisher, Subscription
from eddiebot.core.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from eddiebot.msgs import get_message, raw_message_type, serialize
from eddiebot.msgs.errors import UnknownTypeError

__all__ = ["RecorderNode"]

_NS = 1_000_000_000


def _graph_topics(graph: Any) -> dict[str, tuple[str, list[QoSProfile]]]:
    """Topic → (type, offered QoS profiles) of remote publishers in a transport's ``graph()``.

    Read from ``graph["cache"].publishers()`` (entities with ``name``, ``type_name`` and
    an rmw_zenoh QoS string ``qos``), as ``eddiebot.transport`` provides it. Also accepted
    under ``"topics"``: a mapping of topic to type name, or a list of ``(topic, type)``.
    """
    out: dict[str, tuple[str, list[QoSProfile]]] = {}
    if not isinstance(graph, dict):
        return out
    cache = graph.get("cache")
    publishers = getattr(cache, "publishers", None)
    if callable(publishers):
        from eddiebot.transport.keys import qos_from_keyexpr

        for entity in publishers():
            name = getattr(entity, "name", "")
            typ = getattr(entity, "type_name", "")
            if not name or not typ:
                continue
            _, profiles = out.setdefault(name, (typ, []))
            text = getattr(entity, "qos", "")
            if text:
                try:
                    q = qos_from_keyexpr(text)
                except Exception:
                    continue
                if q not in profiles:
                    profiles.append(q)
    topics = graph.get("topics")
    if isinstance(topics, dict):
        for name, typ in topics.items():
            if isinstance(typ, str):
                out.setdefault(name, (typ, []))
    elif isinstance(topics, (list, tuple)):
        for item in topics:
            if isinstance(item, (list, tuple)) and len(item) >= 2:
                out.setdefault(str(item[0]), (str(item[1]), []))
    return out


class RecorderNode(Node):
    """``ros2 bag record`` as a node: topics to a rosbag2 MCAP directory.

    Parameters: ``output`` (bag directory; default ``rosbag2_<date>-<time>``), ``topics``
    (names), ``all`` (every topic, including ones that appear later), ``exclude`` (regular
    expressions), ``max_bag_duration`` (s, 0: no split), ``max_bag_size`` (bytes, 0: no
    split), ``polling_interval`` (s, how often new topics are looked for),
    ``flush_interval`` (wall s between flushes to the file). Each message is stamped with
    its receive time on the node clock. The bag is closed by ``destroy_node``.
    """

    def __init__(self, node_name: str = "recorder", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        output = str(self.declare_parameter("output", "").value or "")
        topics = self.declare_parameter("topics", []).value or []
        self._all = bool(self.declare_parameter("all", False).value)
        exclude = self.declare_parameter("exclude", []).value or []
        max_duration = float(self.declare_parameter("max_bag_duration", 0.0).value or 0.0)
        max_size = int(self.declare_parameter("max_bag_size", 0).value or 0)
        polling = float(self.declare_parameter("polling_interval", 0.1).value)
        self._flush_ns = round(float(self.declare_parameter("flush_interval", 1.0).value) * _NS)
        if isinstance(topics, str):
            topics = [topics]
        if isinstance(exclude, str):
            exclude = [exclude]
        self._topics = [self.resolve_topic_name(str(t)) for t in topics]
        self._exclude = [re.compile(str(e)) for e in exclude]
        if not self._all and not self._topics:
            raise BagError("recorder: give topics or set all: true")
        if not output:
            now = _dt.datetime.fromtimestamp(self.context.system_clock.now_ns() / _NS)
            output = f"rosbag2_{now:%Y_%m_%d-%H_%M_%S}"
        self.output = Path(output)
        self.writer = BagWriter(self.output, max_bag_duration=max_duration,
                                max_bag_size=max_size)
        self._subs: dict[str, Subscription] = {}
        self._skipped: set[str] = set()
        self._remote_qos: dict[str, list[QoSProfile]] = {}
        self._last_flush = self.context.system_clock.now_ns()
        self.discover()
        self._poll = self.create_timer(polling, self._on_poll)
        self.get_logger().info(f"recording to {self.output}")

    # -- topics -----------------------------------------------------------------------
    def _wanted(self, topic: str) -> bool:
        if any(rx.search(topic) for rx in self._exclude):
            return False
        return self._all or topic in self._topics

    def _offered_qos(self, topic: str) -> list[QoSProfile]:
        entry = self.context.topics.get(topic)
        pubs: list[Publisher] = list(entry.publishers) if entry is not None else []
        profiles: list[QoSProfile] = []
        for q in [p.qos for p in pubs] + self._remote_qos.get(topic, []):
            if q not in profiles:
                profiles.append(q)
        return profiles

    def discover(self) -> None:
        """Subscribe to wanted topics not yet recorded (local registry and transports)."""
        found: dict[str, str] = {}
        for name, entry in list(self.context.topics.items()):
            if entry.type_name and entry.publishers:
                found[name] = entry.type_name
        for t in list(self.context.transports):
            try:
                remote = _graph_topics(t.graph())
            except Exception as exc:
                self.get_logger().warning(f"transport graph unavailable: {exc}", once=True)
                continue
            for name, (typ, profiles) in remote.items():
                found.setdefault(name, typ)
                known = self._remote_qos.setdefault(name, [])
                known.extend(q for q in profiles if q not in known)
        # Named topics with a known type are subscribed even before anyone publishes.
        for name in self._topics:
            known_entry = self.context.topics.get(name)
            if name not in found and known_entry is not None and known_entry.type_name:
                found[name] = known_entry.type_name
        for name, typ in sorted(found.items()):
            if name in self._subs or name in self._skipped or not self._wanted(name):
                continue
            self._subscribe(name, typ)

    def _remote_hash(self, topic: str, typ: str) -> str | None:
        """The RIHS01 hash the publishers of ``topic`` announce for ``typ`` (None: none yet)."""
        for t in list(self.context.transports):
            try:
                cache = t.graph().get("cache")
            except Exception:
                continue
            for e in cache.publishers(topic) if cache is not None else []:
                if e.type_name == typ and e.type_hash.startswith("RIHS01_"):
                    return str(e.type_hash)
        return None

    def _subscribe(self, topic: str, typ: str) -> None:
        msgdef: str | None = None
        rihs01: str | None = None
        try:
            cls = get_message(typ)
        except UnknownTypeError as exc:
            # nothing describes it here: record its CDR as it comes, with an empty schema
            # (as rosbag2 does for a type whose definition it cannot find)
            rihs01 = self._remote_hash(topic, typ)
            if rihs01 is None:
                return  # no publisher has announced it yet: look again at the next poll
            cls = raw_message_type(typ, rihs01)
            msgdef = ""
            self.get_logger().warning(f"recording {topic} undecoded, with no definition: {exc}")
        offered = self._offered_qos(topic)
        latched = any(q.transient_local for q in offered)
        best_effort = bool(offered) and all(
            q.reliability == ReliabilityPolicy.BEST_EFFORT for q in offered
        )
        sub_qos = QoSProfile(
            depth=1000,
            history=HistoryPolicy.KEEP_ALL,
            reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )
        self.writer.add_topic(topic, cls.__msgtype__, qos=offered or [sub_qos], msgdef=msgdef,
                              rihs01=rihs01)

        def on_message(msg: Any, topic: str = topic, typ: str = cls.__msgtype__) -> None:
            self._record(topic, typ, msg)

        self._subs[topic] = self.create_subscription(cls, topic, on_message, sub_qos, raw=True)
        self.get_logger().info(f"recording {topic} [{typ}]")

    # -- data -------------------------------------------------------------------------
    def _record(self, topic: str, typ: str, msg: Any) -> None:
        if self.writer.closed:
            return
        stamp = self.get_clock().now_ns()
        data = bytes(msg) if isinstance(msg, (bytes, bytearray, memoryview)) else serialize(msg, typ)
        self.writer.write(topic, data, stamp)
        wall = self.context.system_clock.now_ns()
        if wall - self._last_flush >= self._flush_ns:
            self._last_flush = wall
            self.writer.flush()

    def _on_poll(self) -> None:
        self.discover()
        wall = self.context.system_clock.now_ns()
        if wall - self._last_flush >= self._flush_ns and not self.writer.closed:
            self._last_flush = wall
            self.writer.flush()

    @property
    def recorded_topics(self) -> list[str]:
        return sorted(self._subs)

    def destroy_node(self) -> None:
        super().destroy_node()
        self.writer.close()
