"""What a node owns on topics and clocks: publishers, subscriptions, timers, guard conditions.

A publisher hands messages to local subscriptions by reference (treat received messages as
read-only) and to the context's transports for other processes; a subscription queues them
(bounded by its QoS depth) and gives its executor one unit of work per queued message; a
timer calls back every period of its clock and restarts when that clock jumps back.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from eddiebot.core.callback_groups import CallbackGroup
from eddiebot.core.errors import TopicTypeMismatchError
from eddiebot.core.qos import QoSProfile, duration_ns
from eddiebot.core.time import Clock, Duration, JumpThreshold, TimeJump
from eddiebot.msgs import type_name

if TYPE_CHECKING:
    from eddiebot.core.node import Node
    from eddiebot.core.qos_events import EndpointEvents

__all__ = ["Entity", "GuardCondition", "Publisher", "Subscription", "Timer"]


class Entity:
    """Something that gives an executor work."""

    node: Node
    callback_group: CallbackGroup

    def _notify(self) -> None:
        self.node._notify(self)

    def execute(self) -> None:  # pragma: no cover - interface
        raise NotImplementedError


class Publisher:
    """Publishes messages of one type on one topic."""

    def __init__(self, node: Node, msg_type: Any, topic: str, qos: QoSProfile) -> None:
        self.node = node
        self.msg_type = msg_type
        self.type_name = type_name(msg_type)
        self.topic_name = topic
        self.qos = qos
        self.latched: deque[Any] = deque(maxlen=qos.depth if qos.transient_local else 0)
        self.sequence = 0
        #: QoS lifespan in ns (None: messages never expire)
        self.lifespan_ns = duration_ns(qos.lifespan)
        #: QoS events (deadline, liveliness, matched, incompatible QoS), when asked for
        self.events: EndpointEvents | None = None
        self._destroyed = False

    @property
    def topic(self) -> str:
        return self.topic_name

    def publish(self, msg: Any) -> None:
        """Send ``msg`` to every subscriber (in this process by reference)."""
        if self._destroyed:
            return
        if getattr(msg, "__msgtype__", None) != self.type_name:
            raise TopicTypeMismatchError(
                self.topic_name, self.type_name, getattr(msg, "__msgtype__", type(msg).__name__)
            )
        self.sequence += 1
        if self.qos.transient_local:
            self.latched.append(msg)
        if self.events is not None:
            self.events.on_activity()
        self.node.context.publish(self, msg)

    def assert_liveliness(self) -> None:
        """Count as alive for another lease (MANUAL_BY_TOPIC liveliness) without publishing."""
        if self.events is not None:
            self.events.asserted_in_lease = True
            if not self.events.alive:
                self.events.on_activity()

    def get_subscription_count(self) -> int:
        """Subscriptions in this process plus those the transports know of."""
        n = self.node.context.local_subscription_count(self.topic_name)
        for t in self.node.context.transports:
            n += int(t.graph().get("remote_subscriptions", {}).get(self.topic_name, 0))
        return n

    def destroy(self) -> None:
        if not self._destroyed:
            self._destroyed = True
            if self.events is not None:
                self.events.destroy()
            self.node.context.remove_publisher(self)


class Subscription(Entity):
    """Receives messages of one topic into a bounded queue; the executor calls back."""

    def __init__(
        self,
        node: Node,
        msg_type: Any,
        topic: str,
        callback: Callable[[Any], Any],
        qos: QoSProfile,
        group: CallbackGroup,
        raw: bool = False,
    ) -> None:
        self.node = node
        self.msg_type = msg_type
        self.type_name = type_name(msg_type)
        self.topic_name = topic
        self.callback = callback
        self.qos = qos
        self.callback_group = group
        self.raw = raw
        self._queue: deque[Any] = deque(maxlen=qos.queue_size)
        self._lock = threading.Lock()
        #: times this subscription waits in the executor's ready queue; never more than
        #: the messages it holds, so a full queue adds no work (the executor's ready
        #: queue is bounded by the subscriptions' depths)
        self._scheduled = 0
        self._what = f"topic {topic!r}"
        #: QoS events (deadline, liveliness, matched, incompatible QoS, message lost)
        self.events: EndpointEvents | None = None
        self._destroyed = False

    @property
    def topic(self) -> str:
        return self.topic_name

    def deliver(self, msg: Any, expires_ns: int | None = None) -> None:
        """Queue a message (dropping the oldest when full) and wake the executor.

        ``expires_ns``: system time after which the message is not delivered any more (the
        publisher's QoS lifespan)."""
        if self._destroyed:
            return
        if self.events is not None:
            self.events.on_activity()
        with self._lock:
            self._queue.append(msg if expires_ns is None else _Expiring(msg, expires_ns))
            if self._scheduled >= len(self._queue):
                return  # the oldest was dropped: the work already queued takes the newest
            self._scheduled += 1
        self._notify()

    def take(self) -> Any | None:
        with self._lock:
            item = self._queue.popleft() if self._queue else None
        if type(item) is _Expiring:
            if self.node.context.system_clock.now_ns() > item.expires_ns:
                return None  # outlived the publisher's lifespan
            return item.msg
        return item

    def execute(self) -> None:
        with self._lock:
            if self._scheduled > 0:
                self._scheduled -= 1
            msg = self._queue.popleft() if self._queue else None
        if type(msg) is _Expiring:
            if self.node.context.system_clock.now_ns() > msg.expires_ns:
                return  # outlived the publisher's lifespan
            msg = msg.msg
        if msg is not None:
            self.node._run_callback(self.callback, (msg,), self._what)

    def destroy(self) -> None:
        if not self._destroyed:
            self._destroyed = True
            if self.events is not None:
                self.events.destroy()
            self.node.context.remove_subscription(self)


class _Expiring:
    """A queued message with the system time its lifespan ends."""

    __slots__ = ("expires_ns", "msg")

    def __init__(self, msg: Any, expires_ns: int) -> None:
        self.msg = msg
        self.expires_ns = expires_ns


class Timer(Entity):
    """Calls back every ``period_ns`` of its clock (sim time jumps straight to the next call)."""

    def __init__(
        self,
        node: Node,
        period_ns: int,
        callback: Callable[[], Any],
        group: CallbackGroup,
        clock: Clock,
        oneshot: bool = False,
    ) -> None:
        if period_ns <= 0:
            raise ValueError(f"timer period must be positive, got {period_ns} ns")
        self.node = node
        self.period_ns = int(period_ns)
        self.callback = callback
        self.callback_group = group
        self.clock = clock
        self.oneshot = oneshot
        now = clock.now_ns()
        self.next_call_ns = now + self.period_ns
        self.last_call_ns: int | None = None
        #: when the current period began (creation, reset or last call; rcl's last_call_time)
        self._period_start_ns = now
        self.canceled = False
        self._destroyed = False
        self._jump_handle = clock.create_jump_callback(
            JumpThreshold(Duration(1), Duration(-1)), post_callback=self._on_time_jump)

    @property
    def timer_period_ns(self) -> int:
        return self.period_ns

    def is_ready(self, now_ns: int) -> bool:
        return not self.canceled and now_ns >= self.next_call_ns

    def time_until_next_call(self) -> int | None:
        if self.canceled:
            return None
        return self.next_call_ns - self.clock.now_ns()

    def cancel(self) -> None:
        self.canceled = True

    def reset(self) -> None:
        self.canceled = False
        now = self.clock.now_ns()
        self.next_call_ns = now + self.period_ns
        self._period_start_ns = now
        self.node._timers_changed()

    def _on_time_jump(self, jump: TimeJump) -> None:
        # As rcl: time went back before the current period began (a bag looping, a
        # simulator reset): the next call is one period from the new now, instead of
        # waiting for the clock to catch up with the old schedule.
        now = self.clock.now_ns()
        if jump.delta.nanoseconds < 0 and now < self._period_start_ns:
            self.next_call_ns = now + self.period_ns
            self._period_start_ns = now
            self.node._timers_changed()
        elif jump.delta.nanoseconds > 0 and now >= self.next_call_ns:
            self.node._timers_changed()

    def execute(self) -> None:
        now = self.clock.now_ns()
        if not self.is_ready(now):
            return
        self.last_call_ns = now
        self._period_start_ns = now
        # As rcl: skip whole missed periods instead of bursting to catch up.
        missed = (now - self.next_call_ns) // self.period_ns
        self.next_call_ns += (missed + 1) * self.period_ns
        if self.oneshot:
            self.canceled = True
        self.node._run_callback(self.callback, (), "timer")

    def destroy(self) -> None:
        if not self._destroyed:
            self._destroyed = True
            self.canceled = True
            self._jump_handle.unregister()
            self.node._remove_timer(self)


class GuardCondition(Entity):
    """Wakes the executor from any thread: :meth:`trigger` queues one call of ``callback``
    on the node's executor (rclpy's guard condition). Triggers that arrive before the
    callback ran are folded into one call."""

    def __init__(self, node: Node, callback: Callable[[], Any], group: CallbackGroup) -> None:
        self.node = node
        self.callback = callback
        self.callback_group = group
        self._lock = threading.Lock()
        self._triggered = False
        self._destroyed = False

    def trigger(self) -> None:
        """Thread-safe: run the callback once on the executor."""
        with self._lock:
            if self._triggered or self._destroyed:
                return
            self._triggered = True
        self._notify()

    def execute(self) -> None:
        with self._lock:
            if not self._triggered:
                return
            self._triggered = False
        self.node._run_callback(self.callback, (), "guard condition")

    def destroy(self) -> None:
        with self._lock:
            self._destroyed = True
