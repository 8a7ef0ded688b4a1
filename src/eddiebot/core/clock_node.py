"""Sharing simulated time and log lines with other processes: ``/clock`` and ``/rosout``.

``ClockPublisher`` publishes rosgraph_msgs/Clock on ``/clock`` whenever the executor that
owns the sim clock moves it, at most once per ``clock_period`` of sim time (Gazebo's
default 100 Hz) — but a move that no timer caused (the end of ``spin_until``/``spin_for``,
where the owner pauses) is always published, so followers never lag the owner at rest.

``ClockFollower`` sets this process's sim clock from ``/clock`` (``use_sim_time`` in a
process that does not own the simulation). ``enable_rosout(context)`` makes every node's
logger publish rcl_interfaces/Log on ``/rosout``, as rcl does.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from eddiebot.core.qos import DurabilityPolicy, QoSProfile
from eddiebot.core.time import ns_to_stamp, stamp_to_ns

if TYPE_CHECKING:
    from eddiebot.core.context import Context
    from eddiebot.core.executors import Executor
    from eddiebot.core.node import Node

__all__ = ["ClockFollower", "ClockPublisher", "disable_rosout", "enable_rosout"]

CLOCK_QOS = QoSProfile(depth=1)
#: rcl's /rosout QoS: deep and transient-local so a late viewer sees recent lines.
ROSOUT_QOS = QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class ClockPublisher:
    """Publishes the sim time an executor drives on ``/clock``."""

    def __init__(self, node: Node, executor: Executor, clock_period: float = 0.01) -> None:
        from eddiebot.msgs.rosgraph_msgs import Clock

        self.node = node
        self.executor = executor
        self.clock_period_ns = round(clock_period * 1e9)
        self._msg_type = Clock
        self.pub = node.create_publisher(Clock, "/clock", CLOCK_QOS)
        self.last_published_ns: int | None = None
        self.pending_ns: int | None = None
        self._lock = threading.Lock()
        executor.on_sim_time_advanced.append(self._on_advanced)
        self.publish(executor.context.sim_clock.now_ns())

    def publish(self, time_ns: int) -> None:
        """Publish ``time_ns`` unless a later time already went out: executor threads report
        their advances concurrently, and a stale one published after a newer one would be a
        jump back in time for every follower (which clears their tf buffers)."""
        with self._lock:
            last = self.last_published_ns
            if last is not None and time_ns < last:
                self.pending_ns = None
                return
            self.pub.publish(self._msg_type(clock=ns_to_stamp(time_ns)))
            self.last_published_ns = time_ns
            self.pending_ns = None

    def flush(self) -> None:
        """Publish a throttled time now (call when the simulation pauses)."""
        if self.pending_ns is not None:
            self.publish(self.pending_ns)

    def _on_advanced(self, time_ns: int) -> None:
        last = self.last_published_ns
        if last is None or time_ns - last >= self.clock_period_ns or not self._timer_due(time_ns):
            self.publish(time_ns)
        else:
            self.pending_ns = time_ns

    def _timer_due(self, time_ns: int) -> bool:
        """Did a sim timer cause this move (one falls due exactly now)?"""
        sim = self.executor.context.sim_clock
        return any(
            t.clock is sim and not t.canceled and t.next_call_ns <= time_ns
            for n in self.executor.get_nodes()
            for t in n.timers
        )

    def destroy(self) -> None:
        if self._on_advanced in self.executor.on_sim_time_advanced:
            self.executor.on_sim_time_advanced.remove(self._on_advanced)
        self.node.destroy_publisher(self.pub)


class ClockFollower:
    """Sets the context's sim clock from ``/clock`` messages."""

    def __init__(self, node: Node) -> None:
        from eddiebot.msgs.rosgraph_msgs import Clock

        self.node = node
        self.sim_clock = node.context.sim_clock
        self.received = 0
        self.sub = node.create_subscription(Clock, "/clock", self._on_clock, CLOCK_QOS)

    def _on_clock(self, msg: Any) -> None:
        ns = stamp_to_ns(msg.clock)
        self.received += 1
        if ns < self.sim_clock.now_ns():
            self.node.get_logger().warning(
                f"/clock jumped back to {ns / 1e9:.3f} s (from {self.sim_clock.now_ns() / 1e9:.3f} s)")
            self.sim_clock.reset(ns)
        else:
            self.sim_clock.set_ns(ns)

    def destroy(self) -> None:
        self.node.destroy_subscription(self.sub)


def _rosout_hook(node: Node, level: int, text: str) -> None:
    from eddiebot.msgs.rcl_interfaces import Log

    if node._destroyed:
        return
    pub = node._rosout_pub
    if pub is None:
        pub = node._rosout_pub = node.create_publisher(Log, "/rosout", ROSOUT_QOS)
    pub.publish(Log(
        stamp=node.now().to_msg(),
        level=max(10, min(50, int(level))),
        name=node.get_logger().name,
        msg=text,
    ))


def enable_rosout(context: Context) -> None:
    """Every node of ``context`` publishes its log lines on ``/rosout``."""
    context.rosout_hook = _rosout_hook  # type: ignore[attr-defined]


def disable_rosout(context: Context) -> None:
    context.rosout_hook = None  # type: ignore[attr-defined]
