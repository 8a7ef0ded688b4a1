"""Twist multiplexer (twist_mux's role): velocity sources by priority, with timeouts and locks.

Parameters as twist_mux's YAML::

    topics:
      navigation: {topic: cmd_vel_safe,   timeout: 0.5, priority: 10}
      teleop:     {topic: cmd_vel_teleop, timeout: 0.5, priority: 100}
    locks:
      e_stop:     {topic: e_stop, timeout: 0.0, priority: 255}   # std_msgs/Bool

The highest-priority source whose last command is younger than its timeout drives
``cmd_vel``; a lock that is set (Bool true, or silent longer than its timeout when the
timeout is positive) mutes every source of lower or equal priority. Unlike twist_mux,
when the selected source goes stale the mux publishes one zero Twist at once, so the robot
stops without waiting for the base's own stale-command timeout.

While a source keeps sending but a higher-priority one holds the mux (navigation's
commands under a teleop that has not gone quiet), the node logs once which source holds it
(``navigation overridden by teleop (cmd_vel_teleop) ...``); the line is logged again only
after that source has driven again or the holder changed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from eddiebot.core.node import Node
from eddiebot.core.parameters import ParameterDescriptor
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.std_msgs import Bool

__all__ = ["MuxInput", "TwistMux", "TwistMuxNode"]

#: read once at start; `param set` is refused rather than silently ignored
_RO = ParameterDescriptor(read_only=True)

DEFAULT_TOPICS = {
    "navigation": ("cmd_vel_safe", 0.5, 10),
    "teleop": ("cmd_vel_teleop", 0.5, 100),
}
DEFAULT_LOCKS = {"e_stop": ("e_stop", 0.0, 255)}


@dataclass
class MuxInput:
    name: str
    topic: str
    timeout_ns: int
    priority: int
    last_ns: int | None = None
    value: Any = None  # last Twist, or the lock's bool


class TwistMux:
    """Selection logic (pure): who drives at time ``now_ns``."""

    def __init__(self, sources: list[MuxInput], locks: list[MuxInput]) -> None:
        self.sources = sorted(sources, key=lambda s: -s.priority)
        self.locks = locks

    def _lock_priority(self, now_ns: int) -> int:
        top = -1
        for lock in self.locks:
            stale = (
                lock.timeout_ns > 0
                and (lock.last_ns is None or now_ns - lock.last_ns > lock.timeout_ns)
            )
            if stale or bool(lock.value):
                top = max(top, lock.priority)
        return top

    def select(self, now_ns: int) -> MuxInput | None:
        locked = self._lock_priority(now_ns)
        for src in self.sources:
            if src.priority <= locked:
                return None
            if src.last_ns is not None and now_ns - src.last_ns <= src.timeout_ns:
                return src
        return None


class TwistMuxNode(Node):
    default_node_name = "twist_mux"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        sources = self._inputs("topics", DEFAULT_TOPICS)
        locks = self._inputs("locks", DEFAULT_LOCKS)
        self.mux = TwistMux(sources, locks)
        self.active: MuxInput | None = None
        #: source name → the source that overrode it, logged once per episode
        self._overridden: dict[str, str] = {}
        self.pub = self.create_publisher(Twist, "cmd_vel", 10)
        for src in sources:
            self.create_subscription(Twist, src.topic, self._make_cb(src), 10)
        for lock in locks:
            self.create_subscription(Bool, lock.topic, self._make_lock_cb(lock), 10)
        period = float(self.declare_parameter("check_period", 0.05, _RO).value)
        self.create_timer(period, self._check)

    def _inputs(self, group: str, defaults: dict[str, tuple[str, float, int]]) -> list[MuxInput]:
        names = sorted({o.name.split(".")[1] for o in self._overrides.values()
                        if o.name.startswith(f"{group}.") and o.name.count(".") == 2})
        table = {n: defaults.get(n, ("", 0.5, 0)) for n in names} if names else defaults
        out = []
        for name, (topic, timeout, priority) in table.items():
            t = self.declare_parameter(f"{group}.{name}.topic", topic, _RO).value
            to = float(self.declare_parameter(f"{group}.{name}.timeout", float(timeout), _RO).value)
            pr = int(self.declare_parameter(f"{group}.{name}.priority", int(priority), _RO).value)
            if not t:
                raise ValueError(f"{self.fully_qualified_name}: {group}.{name}.topic is required")
            out.append(MuxInput(name, t, round(to * 1e9), pr))
        return out

    def _make_cb(self, src: MuxInput) -> Any:
        def cb(msg: Any) -> None:
            src.last_ns = self.get_clock().now_ns()
            src.value = msg
            chosen = self.mux.select(src.last_ns)
            self._switch(chosen)
            if chosen is src:
                self._overridden.pop(src.name, None)
                self.pub.publish(msg)
            else:
                self._note_override(src, chosen)

        return cb

    def _note_override(self, src: MuxInput, holder: MuxInput | None) -> None:
        """Log once that ``src``'s commands are dropped, and who holds the mux."""
        if holder is None:
            who = "a lock (" + ", ".join(
                f"{lock.name} on {lock.topic}" for lock in self.mux.locks) + ")"
        else:
            who = f"{holder.name} ({holder.topic}, priority {holder.priority})"
        if self._overridden.get(src.name) == who:
            return
        self._overridden[src.name] = who
        if holder is None:
            self.get_logger().warning(f"{src.name} ({src.topic}) is muted by {who}")
            return
        self.get_logger().warning(
            f"{src.name} ({src.topic}) overridden by {who}: its commands are dropped until "
            f"{holder.name} has been quiet for {holder.timeout_ns / 1e9:g} s")

    def _make_lock_cb(self, lock: MuxInput) -> Any:
        def cb(msg: Any) -> None:
            lock.last_ns = self.get_clock().now_ns()
            lock.value = bool(msg.data)
            self._check()

        return cb

    def _switch(self, chosen: MuxInput | None) -> None:
        if chosen is not self.active:
            if self.active is not None and chosen is None:
                self.pub.publish(Twist())  # the driving source went stale or a lock engaged
            name = chosen.name if chosen else "none"
            self.get_logger().info(f"velocity source: {name}")
            self.active = chosen

    def _check(self) -> None:
        self._switch(self.mux.select(self.get_clock().now_ns()))
