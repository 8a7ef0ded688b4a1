"""Playback: ``Player``, ``ros2 bag play`` as a node.

A timer on the node clock republishes a bag with its original timing (× ``rate``): on a
simulated clock playback is instant and deterministic. Transient-local topics are
republished latched; ``/clock`` is published on request; a damaged bag plays its readable
prefix and says where it broke.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from eddiebot.bag.errors import BagError
from eddiebot.bag.reader import BagReader
from eddiebot.bag.records import BagConnection, BagMessage, BagProblem, ensure_type
from eddiebot.core.node import Node, Publisher, Timer
from eddiebot.core.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from eddiebot.msgs import get_message

__all__ = ["Player"]

_NS = 1_000_000_000
_LOOP_GAP_NS = 1_000_000


class Player(Node):
    """``ros2 bag play`` as a node, paced by a timer on the node clock.

    Each message is published at ``anchor + (t - t_start) / rate`` on the node clock, where
    ``t_start`` is the bag's first timestamp plus ``start_offset`` (s). On a simulated clock
    that is behind the bag's start, the clock is moved to the bag's start first, so messages
    come out at their recorded times (``use_bag_time``); the executor then jumps from one
    message to the next, so playback is instant and deterministic. Topics offered
    transient-local in the bag are republished latched. With ``publish_clock``, ``/clock``
    carries the bag time before each message and every ``1 / clock_frequency`` s.
    """

    def __init__(
        self,
        bag: str | Path,
        node_name: str = "player",
        *,
        rate: float = 1.0,
        loop: bool = False,
        start_offset: float = 0.0,
        topics: Sequence[str] | None = None,
        publish_clock: bool = False,
        clock_frequency: float = 40.0,
        delay: float = 0.0,
        use_bag_time: bool = True,
        shutdown_when_done: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__(node_name, **kwargs)
        if rate <= 0:
            raise BagError(f"play rate must be > 0, got {rate}")
        self.bag = Path(bag)
        self.rate = float(rate)
        self.loop = bool(loop)
        self.start_offset_ns = round(start_offset * _NS)
        self.topics = list(topics) if topics else None
        self.publish_clock = publish_clock
        self.shutdown_when_done = shutdown_when_done
        self.problems: list[BagProblem] = []
        self.notes: list[str] = []
        self.published = 0
        self.loops = 0
        self.done = False
        self._publishers: dict[str, Publisher] = {}
        self._failed_topics: set[str] = set()
        self._reader: BagReader | None = None
        self._iter: Iterator[BagMessage] | None = None
        self._next: BagMessage | None = None
        self._anchor_bag = 0
        self._anchor_play = 0
        self._clock_pub: Publisher | None = None
        if publish_clock:
            from eddiebot.msgs.rosgraph_msgs import Clock as ClockMsg

            self._clock_msg = ClockMsg
            self._clock_pub = self.create_publisher(ClockMsg, "/clock", QoSProfile(depth=1))
            if clock_frequency > 0:
                self.create_timer(1.0 / clock_frequency, self._on_clock_timer)
        self._open(first=True)
        assert self._reader is not None
        for conn in self._reader.connections:  # indexed bags: every topic is known up front
            if self.topics is None or conn.topic in self.topics:
                self._publisher(conn)
        now = self.get_clock().now_ns()
        clock = self.get_clock()
        if use_bag_time and clock is self.context.sim_clock and now < self._anchor_bag:
            self.context.sim_clock.set_ns(self._anchor_bag)
            now = self._anchor_bag
        self._anchor_play = now + round(delay * _NS)
        self._timer: Timer = self.create_timer(1.0, self._on_timer)
        self._schedule()

    # -- reading ----------------------------------------------------------------------
    def _open(self, first: bool) -> None:
        if self._reader is not None:
            self._reader.close()
        self._reader = BagReader(self.bag)
        if first:
            self.notes.extend(self._reader.notes)
        self._iter = self._reader.messages(self.topics)
        self._next = self._pull()
        if self._next is not None:
            self._anchor_bag = self._next.timestamp + self.start_offset_ns
            if self.start_offset_ns > 0:
                while self._next is not None and self._next.timestamp < self._anchor_bag:
                    self._next = self._pull()

    def _pull(self) -> BagMessage | None:
        assert self._iter is not None
        msg = next(self._iter, None)
        if msg is None and self._reader is not None:
            for p in self._reader.problems:
                if p not in self.problems:
                    self.problems.append(p)
                    self.get_logger().warning(f"bag damaged: {p}; played the readable prefix")
        return msg

    def _play_time(self, msg: BagMessage) -> int:
        return self._anchor_play + round((msg.timestamp - self._anchor_bag) / self.rate)

    def bag_time(self, now_ns: int | None = None) -> int:
        """The bag time (ns) that corresponds to node-clock time ``now_ns``."""
        now = self.get_clock().now_ns() if now_ns is None else now_ns
        return self._anchor_bag + round((now - self._anchor_play) * self.rate)

    # -- timing -----------------------------------------------------------------------
    def _schedule(self) -> None:
        timer = self._timer
        if self._next is None:
            timer.cancel()
            self._finish()
            return
        timer.canceled = False
        timer.next_call_ns = self._play_time(self._next)
        self._timers_changed()

    def _on_timer(self) -> None:
        now = self.get_clock().now_ns()
        clock_sent = False
        while self._next is not None and self._play_time(self._next) <= now:
            msg = self._next
            if not clock_sent and self._clock_pub is not None:
                self._publish_clock(now)
                clock_sent = True
            self._publish(msg)
            self._next = self._pull()
        if self._next is None and self.loop and self.published:
            self.loops += 1
            self._open(first=False)
            self._anchor_play = now + _LOOP_GAP_NS
        self._schedule()

    def _publisher(self, conn: BagConnection) -> Publisher | None:
        topic = conn.topic
        pub = self._publishers.get(topic)
        if pub is not None or topic in self._failed_topics:
            return pub
        try:
            ensure_type(conn)
            cls = get_message(conn.type_name)
        except Exception as exc:
            self._failed_topics.add(topic)
            self.get_logger().warning(f"cannot play {topic} [{conn.type_name}]: {exc}")
            return None
        qos = conn.qos[0] if conn.qos else QoSProfile()
        if conn.transient_local:
            qos = QoSProfile(depth=max(q.depth for q in conn.qos),
                             durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        pub = self._publishers[topic] = self.create_publisher(cls, topic, qos)
        return pub

    def _publish(self, msg: BagMessage) -> None:
        pub = self._publisher(msg.connection)
        if pub is None:
            return
        try:
            obj = msg.decode()
        except Exception as exc:
            self.get_logger().warning(f"message on {msg.topic} cannot be decoded: {exc}", once=True)
            return
        pub.publish(obj)
        self.published += 1

    def _publish_clock(self, now: int) -> None:
        if self._clock_pub is None:
            return
        from eddiebot.core.time import ns_to_stamp

        self._clock_pub.publish(self._clock_msg(clock=ns_to_stamp(self.bag_time(now))))

    def _on_clock_timer(self) -> None:
        if not self.done:
            self._publish_clock(self.get_clock().now_ns())

    def _finish(self) -> None:
        if self.done:
            return
        self.done = True
        self.get_logger().info(f"played {self.published} messages from {self.bag}")
        executor = self.executor
        if self.shutdown_when_done and executor is not None:
            # After the callbacks the last messages queued (they were enqueued first).
            executor.create_task(lambda: executor.shutdown())

    def destroy_node(self) -> None:
        super().destroy_node()
        if self._reader is not None:
            self._reader.close()
            self._reader = None
