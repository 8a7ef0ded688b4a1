"""``Node`` and its entities: publishers, subscriptions, timers, services and clients.

Names and behaviour follow rclpy. Callbacks run on the executor the node is added to;
a publisher hands messages to local subscriptions by reference (treat received messages
as read-only) and to the context's transports for other processes.
"""

from __future__ import annotations

import enum
import inspect
import logging
import threading
from collections import deque
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from eddiebot.core.context import Context, get_default_context
from eddiebot.core.errors import (
    InvalidParameterTypeError,
    InvalidParameterValueError,
    ParameterAlreadyDeclaredError,
    ParameterNotDeclaredError,
    ServiceCallTimeoutError,
    ServiceUnavailableError,
    TopicTypeMismatchError,
)
from eddiebot.core.graph import GraphQueries
from eddiebot.core.names import apply_remaps, normalize_namespace, resolve_name, validate_node_name
from eddiebot.core.parameters import (
    Parameter,
    ParameterDescriptor,
    ParameterOverride,
    ParameterType,
    SetParametersResult,
    coerce,
    node_matches,
)
from eddiebot.core.qos import LivelinessPolicy, QoSProfile, as_qos, duration_ns
from eddiebot.core.qos_events import PublisherEventCallbacks, SubscriptionEventCallbacks
from eddiebot.core.task import Future
from eddiebot.core.time import Clock, Duration, JumpThreshold, Time, TimeJump
from eddiebot.msgs import ServiceType, type_name

if TYPE_CHECKING:
    from eddiebot.core.executors import Executor
    from eddiebot.core.qos_events import EndpointEvents
    from eddiebot.core.rate import Rate

__all__ = [
    "CallbackGroup",
    "Client",
    "GuardCondition",
    "MutuallyExclusiveCallbackGroup",
    "Node",
    "Publisher",
    "ReentrantCallbackGroup",
    "Service",
    "Subscription",
    "Timer",
]


class CallbackGroup:
    """Callbacks of one group obey the group's concurrency rule in a multi-threaded executor."""

    reentrant = False

    def __init__(self) -> None:
        self.lock = threading.Lock()


class MutuallyExclusiveCallbackGroup(CallbackGroup):
    """At most one callback of the group runs at a time (the default)."""


class ReentrantCallbackGroup(CallbackGroup):
    """Callbacks of the group may run in parallel."""

    reentrant = True


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
        msg = self.take()
        if msg is not None:
            self.node._run_callback(self.callback, (msg,), f"topic {self.topic_name!r}")

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


class Service(Entity):
    """Answers requests with ``callback(request, response) -> response``."""

    def __init__(
        self,
        node: Node,
        srv_type: ServiceType,
        name: str,
        callback: Callable[[Any, Any], Any],
        group: CallbackGroup,
    ) -> None:
        self.node = node
        self.srv_type = srv_type
        self.srv_name = name
        self.callback = callback
        self.callback_group = group
        self._queue: deque[tuple[Any, Callable[[Any, BaseException | None], None]]] = deque()
        self._lock = threading.Lock()
        self._destroyed = False

    @property
    def service_name(self) -> str:
        return self.srv_name

    def handle(self, request: Any) -> Any:
        """Run the callback now and return the response (raises what the callback raises)."""
        if getattr(request, "__msgtype__", None) != self.srv_type.Request.__msgtype__:
            raise TopicTypeMismatchError(
                self.srv_name,
                self.srv_type.Request.__msgtype__,
                getattr(request, "__msgtype__", type(request).__name__),
            )
        response = self.callback(request, self.srv_type.Response())
        if response is None:
            raise TypeError(f"service {self.srv_name!r} callback returned None, not a response")
        return response

    def handle_async(self, request: Any, done: Callable[[Any, BaseException | None], None]) -> None:
        """Answer through ``done(response, error)``; a subclass may answer later (actions).

        A callback that raises is logged with the node and service name and answered with
        the error (our clients raise it at once; a ROS client, which has no error reply,
        times out as it would against rclpy); the server goes on serving."""
        try:
            response = self.handle(request)
        except Exception as exc:
            self.log_failure(exc)
            done(None, exc)
            return
        done(response, None)

    def log_failure(self, exc: BaseException) -> None:
        """One log line for a callback that raised: node, service, exception."""
        self.node.get_logger().error(
            f"node {self.node.fully_qualified_name}: service {self.srv_name} callback raised "
            f"{type(exc).__name__}: {exc}; the call fails, the service goes on serving")

    def enqueue(self, request: Any, done: Callable[[Any, BaseException | None], None]) -> None:
        """Queue a request; ``done(response, error)`` is called after the callback ran."""
        with self._lock:
            self._queue.append((request, done))
        self._notify()

    def execute(self) -> None:
        with self._lock:
            if not self._queue:
                return
            request, done = self._queue.popleft()
        self.handle_async(request, done)

    def destroy(self) -> None:
        if not self._destroyed:
            self._destroyed = True
            self.node.context.remove_service(self)


class Client:
    """Calls a service in this process or, through the transport, in another."""

    def __init__(self, node: Node, srv_type: ServiceType, name: str, group: CallbackGroup) -> None:
        self.node = node
        self.srv_type = srv_type
        self.srv_name = name
        self.callback_group = group

    def service_is_ready(self) -> bool:
        if self.srv_name in self.node.context.services:
            return True
        return any(t.service_is_ready(self.srv_name) for t in self.node.context.transports)

    def wait_for_service(self, timeout_sec: float | None = None) -> bool:
        """Wait (wall time) until a server exists; True if it does."""
        import time as _t

        deadline = None if timeout_sec is None else _t.monotonic() + timeout_sec
        while not self.service_is_ready():
            if deadline is not None and _t.monotonic() >= deadline:
                return False
            _t.sleep(0.01)
        return True

    def call_async(self, request: Any) -> Future:
        """Send ``request``; the future completes with the response (or the error)."""
        future = Future()

        def done(response: Any, error: BaseException | None) -> None:
            if error is not None:
                future.set_exception(error)
            else:
                future.set_result(response)
            self.node._future_done(future)

        local = self.node.context.services.get(self.srv_name)
        if local is not None:
            executor = local.node.executor
            if executor is None or not executor.is_spinning() or executor.is_current_thread_spinning():
                # Nobody else will run it (or we would deadlock waiting): answer inline.
                local.handle_async(request, done)
            else:
                local.enqueue(request, done)
            return future
        for t in self.node.context.transports:
            if t.call_service(self.srv_name, self.srv_type, request, done, client=self):
                return future
        future.set_exception(ServiceUnavailableError(f"service {self.srv_name!r} is not available"))
        return future

    def call(self, request: Any, timeout_sec: float | None = 5.0) -> Any:
        """Blocking call; raises ``ServiceUnavailableError`` or ``ServiceCallTimeoutError``."""
        future = self.call_async(request)
        if not future.done():
            executor = self.node.executor
            if executor is not None and executor.is_current_thread_spinning():
                executor.spin_until_future_complete(future, timeout_sec=timeout_sec)
            else:
                future.wait(timeout_sec)
        if not future.done():
            raise ServiceCallTimeoutError(
                f"service {self.srv_name!r} did not answer within {timeout_sec} s"
            )
        return future.result()

    def destroy(self) -> None:
        return None


class _Rcutils(enum.IntEnum):
    DEBUG = 10
    INFO = 20
    WARN = 30
    ERROR = 40
    FATAL = 50


class NodeLogger:
    """rclpy-style logger: ``info``, ``warn``, ``error``, ``debug``, ``fatal``, plus ``once``."""

    def __init__(self, name: str, node: Node | None = None) -> None:
        self.name = name
        self._log = logging.getLogger(name)
        self._node = node
        self._once: set[str] = set()

    def _emit(self, level: int, msg: str, once: bool = False) -> None:
        if once:
            if msg in self._once:
                return
            self._once.add(msg)
        self._log.log(level, msg)
        if self._node is not None:
            self._node._rosout(level, msg)

    def debug(self, msg: str, *, once: bool = False) -> None:
        self._emit(logging.DEBUG, msg, once)

    def info(self, msg: str, *, once: bool = False) -> None:
        self._emit(logging.INFO, msg, once)

    def warning(self, msg: str, *, once: bool = False) -> None:
        self._emit(logging.WARNING, msg, once)

    warn = warning

    def error(self, msg: str, *, once: bool = False) -> None:
        self._emit(logging.ERROR, msg, once)

    def fatal(self, msg: str, *, once: bool = False) -> None:
        self._emit(logging.CRITICAL, msg, once)

    def set_level(self, level: int) -> None:
        self._log.setLevel(level)

    def get_child(self, suffix: str) -> NodeLogger:
        return NodeLogger(f"{self.name}.{suffix}", self._node)


_ParamCallback = Callable[[list[Parameter]], SetParametersResult]


class Node(GraphQueries):
    """A participant in the graph, as ``rclpy.node.Node`` (graph queries: ``core.graph``)."""

    def __init__(
        self,
        node_name: str,
        *,
        namespace: str = "",
        context: Context | None = None,
        parameter_overrides: Sequence[Parameter | ParameterOverride] | dict[str, Any] | None = None,
        remappings: dict[str, str] | None = None,
        allow_undeclared_parameters: bool = False,
        automatically_declare_parameters_from_overrides: bool = False,
        use_global_arguments: bool = True,
        start_parameter_services: bool = True,
    ) -> None:
        self.context = context or get_default_context()
        self._name = validate_node_name(node_name)
        self._namespace = normalize_namespace(namespace)
        self.remappings = dict(remappings or {})
        self.executor: Executor | None = None
        self._default_group = MutuallyExclusiveCallbackGroup()
        self.publishers: list[Publisher] = []
        self.subscriptions: list[Subscription] = []
        self.timers: list[Timer] = []
        self.services: list[Service] = []
        self.clients: list[Client] = []
        self._unscheduled: list[Any] = []
        self._lock = threading.RLock()
        self.allow_undeclared_parameters = allow_undeclared_parameters
        self._parameters: dict[str, Parameter] = {}
        self._descriptors: dict[str, ParameterDescriptor] = {}
        self._on_set: list[_ParamCallback] = []
        self._post_set: list[Callable[[list[Parameter]], None]] = []
        self._overrides: dict[str, ParameterOverride] = {}
        self._logger = NodeLogger(self.fully_qualified_name.lstrip("/").replace("/", "."), self)
        self._rosout_pub: Publisher | None = None
        self._destroyed = False
        # Overrides: global sources (files, command line) first, then the node's own.
        if use_global_arguments:
            for o in self.context.parameter_sources:
                if node_matches(o.node_pattern, self.fully_qualified_name):
                    self._overrides[o.name] = o
        if isinstance(parameter_overrides, dict):
            for k, v in parameter_overrides.items():
                self._overrides[k] = ParameterOverride("/**", k, v, f"node {self.fully_qualified_name}")
        elif parameter_overrides:
            for p in parameter_overrides:
                if isinstance(p, ParameterOverride):
                    self._overrides[p.name] = p
                else:
                    self._overrides[p.name] = ParameterOverride(
                        "/**", p.name, p.value, f"node {self.fully_qualified_name}"
                    )
        self.context.add_node(self)
        self.declare_parameter("use_sim_time", self.context.use_sim_time)
        if automatically_declare_parameters_from_overrides:
            for name, o in list(self._overrides.items()):
                if name not in self._parameters:
                    self.declare_parameter(name, o.value)
        from eddiebot.core.param_services import ParameterService

        self._parameter_service: ParameterService | None = (
            ParameterService(self) if start_parameter_services else None
        )
        # ~/get_type_description, as every rclpy node (Iron and later) serves it
        from eddiebot.core.type_description import TypeDescriptionService

        self._type_description_service: TypeDescriptionService | None = (
            TypeDescriptionService(self) if start_parameter_services else None
        )

    # -- identity -----------------------------------------------------------------------
    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    @property
    def fully_qualified_name(self) -> str:
        return f"{self._namespace.rstrip('/')}/{self._name}"

    def get_fully_qualified_name(self) -> str:
        return self.fully_qualified_name

    def get_logger(self) -> NodeLogger:
        return self._logger

    def resolve_topic_name(self, name: str, *, only_expand: bool = False) -> str:
        full = resolve_name(name, self._namespace, self._name)
        return full if only_expand else apply_remaps(full, self.remappings, self._namespace, self._name)

    resolve_service_name = resolve_topic_name

    # -- time ---------------------------------------------------------------------------
    def get_clock(self) -> Clock:
        """The context's sim clock when use_sim_time is true, else the system clock."""
        use_sim = bool(self._parameters["use_sim_time"].value) if "use_sim_time" in self._parameters \
            else self.context.use_sim_time
        return self.context.sim_clock if use_sim else self.context.system_clock

    def now(self) -> Time:
        return self.get_clock().now()

    # -- entities -----------------------------------------------------------------------
    def create_publisher(
        self,
        msg_type: Any,
        topic: str,
        qos_profile: QoSProfile | int,
        *,
        callback_group: CallbackGroup | None = None,
        event_callbacks: PublisherEventCallbacks | None = None,
    ) -> Publisher:
        qos = as_qos(qos_profile)
        pub = Publisher(self, msg_type, self.resolve_topic_name(topic), qos)
        self.context.add_publisher(pub)
        self.publishers.append(pub)
        manual = (qos.liveliness == LivelinessPolicy.MANUAL_BY_TOPIC
                  and duration_ns(qos.liveliness_lease_duration) is not None)
        if event_callbacks is not None or manual:
            from eddiebot.core.qos_events import EndpointEvents

            pub.events = EndpointEvents(pub, event_callbacks or PublisherEventCallbacks(),
                                        publisher=True, group=callback_group)
        return pub

    def create_subscription(
        self,
        msg_type: Any,
        topic: str,
        callback: Callable[[Any], Any],
        qos_profile: QoSProfile | int,
        *,
        callback_group: CallbackGroup | None = None,
        raw: bool = False,
        event_callbacks: SubscriptionEventCallbacks | None = None,
    ) -> Subscription:
        sub = Subscription(
            self,
            msg_type,
            self.resolve_topic_name(topic),
            callback,
            as_qos(qos_profile),
            callback_group or self._default_group,
            raw,
        )
        self.subscriptions.append(sub)
        self.context.add_subscription(sub)
        if event_callbacks is not None:
            from eddiebot.core.qos_events import EndpointEvents

            sub.events = EndpointEvents(sub, event_callbacks, publisher=False)
        return sub

    def create_timer(
        self,
        timer_period_sec: float,
        callback: Callable[[], Any],
        callback_group: CallbackGroup | None = None,
        clock: Clock | None = None,
        *,
        oneshot: bool = False,
    ) -> Timer:
        timer = Timer(
            self,
            round(timer_period_sec * 1e9),
            callback,
            callback_group or self._default_group,
            clock or self.get_clock(),
            oneshot,
        )
        with self._lock:
            self.timers.append(timer)
        self._timers_changed()
        return timer

    def create_rate(self, frequency: float, clock: Clock | None = None) -> Rate:
        """A :class:`~eddiebot.core.rate.Rate` of ``frequency`` Hz on this node's clock."""
        from eddiebot.core.rate import Rate

        return Rate(self, frequency, clock)

    def create_service(
        self,
        srv_type: ServiceType,
        srv_name: str,
        callback: Callable[[Any, Any], Any],
        *,
        callback_group: CallbackGroup | None = None,
    ) -> Service:
        srv = Service(self, srv_type, self.resolve_service_name(srv_name), callback,
                      callback_group or self._default_group)
        self.context.add_service(srv)
        self.services.append(srv)
        return srv

    def create_guard_condition(
        self, callback: Callable[[], Any], callback_group: CallbackGroup | None = None
    ) -> GuardCondition:
        """A guard condition whose :meth:`~GuardCondition.trigger` (from any thread) runs
        ``callback`` on this node's executor."""
        return GuardCondition(self, callback, callback_group or self._default_group)

    def create_client(
        self, srv_type: ServiceType, srv_name: str, *, callback_group: CallbackGroup | None = None
    ) -> Client:
        client = Client(self, srv_type, self.resolve_service_name(srv_name),
                        callback_group or self._default_group)
        self.clients.append(client)
        for t in self.context.transports:
            announce = getattr(t, "on_client_added", None)
            if announce is not None:
                announce(client)
        return client

    def destroy_publisher(self, pub: Publisher) -> None:
        pub.destroy()
        if pub in self.publishers:
            self.publishers.remove(pub)

    def destroy_subscription(self, sub: Subscription) -> None:
        sub.destroy()
        if sub in self.subscriptions:
            self.subscriptions.remove(sub)

    def destroy_timer(self, timer: Timer) -> None:
        timer.destroy()

    def destroy_service(self, srv: Service) -> None:
        srv.destroy()
        if srv in self.services:
            self.services.remove(srv)

    def destroy_client(self, client: Client) -> None:
        if client in self.clients:
            self.clients.remove(client)
            for t in self.context.transports:
                forget = getattr(t, "on_client_removed", None)
                if forget is not None:
                    forget(client)

    def destroy_node(self) -> None:
        if self._destroyed:
            return
        self._destroyed = True
        for pub in list(self.publishers):
            pub.destroy()
        for sub in list(self.subscriptions):
            sub.destroy()
        for timer in list(self.timers):
            timer.destroy()
        for srv in list(self.services):
            srv.destroy()
        if self.executor is not None:
            self.executor.remove_node(self)
        self.context.remove_node(self)

    # -- executor plumbing --------------------------------------------------------------
    def _notify(self, entity: Any) -> None:
        executor = self.executor
        if executor is None:
            with self._lock:
                self._unscheduled.append(entity)
        else:
            executor.enqueue(entity)

    def _take_pending(self) -> list[Any]:
        with self._lock:
            pending, self._unscheduled = self._unscheduled, []
        return pending

    def _timers_changed(self) -> None:
        if self.executor is not None:
            self.executor.invalidate_timers()
            self.executor.wake()

    def _remove_timer(self, timer: Timer) -> None:
        with self._lock:
            if timer in self.timers:
                self.timers.remove(timer)
        if self.executor is not None:
            self.executor.invalidate_timers()

    def _future_done(self, future: Future) -> None:
        if self.executor is not None:
            self.executor.wake()

    def _run_callback(self, callback: Callable[..., Any], args: tuple[Any, ...], what: str) -> None:
        try:
            result = callback(*args)
            if result is not None and inspect.iscoroutine(result) and self.executor is not None:
                self.executor.create_task(result)
        except Exception as exc:
            self._logger.error(f"callback for {what} raised {type(exc).__name__}: {exc}")
            # a node that fails may leave the robot driving blind: stop the motors first
            self.context.safety_stop(f"{self.get_name()}: callback for {what} raised")
            if self.executor is not None and self.executor.stop_on_callback_error:
                raise

    def _rosout(self, level: int, msg: str) -> None:
        """Forward a log line to /rosout for remote viewers (dashboard, ``eddie topic echo``)."""
        hook = getattr(self.context, "rosout_hook", None)
        if hook is not None:
            hook(self, level, msg)

    # -- parameters ---------------------------------------------------------------------
    def declare_parameter(
        self,
        name: str,
        value: Any = None,
        descriptor: ParameterDescriptor | None = None,
        *,
        ignore_override: bool = False,
    ) -> Parameter:
        """Declare ``name`` with a default; an override from a file or the caller wins."""
        if name in self._parameters:
            raise ParameterAlreadyDeclaredError(
                f"parameter {name!r} already declared", where=f"node {self.fully_qualified_name}"
            )
        desc = descriptor or ParameterDescriptor()
        declared_type = ParameterType.of(value) if value is not None else ParameterType.NOT_SET
        if isinstance(value, (list, tuple)) and not value:
            declared_type = ParameterType.NOT_SET
        override = None if ignore_override else self._overrides.get(name)
        final = value
        if override is not None:
            where = f"{override.where} node {self.fully_qualified_name} key {name}"
            final = override.value if desc.dynamic_typing else coerce(
                override.value, declared_type, name=name, where=where
            )
            self._check_range(name, final, desc, where)
        elif isinstance(value, tuple):
            final = list(value)
        param = Parameter(name, final, ParameterType.of(final) if final is not None else declared_type)
        self._parameters[name] = param
        self._descriptors[name] = desc
        return param

    def declare_parameters(self, namespace: str, parameters: Sequence[tuple[Any, ...]]) -> list[Parameter]:
        prefix = f"{namespace}." if namespace else ""
        return [self.declare_parameter(prefix + p[0], *p[1:]) for p in parameters]

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def undeclared_overrides(self) -> list[ParameterOverride]:
        """Overrides (from files, command lines) that name no declared parameter."""
        return [o for n, o in self._overrides.items() if n not in self._parameters]

    def get_parameter(self, name: str) -> Parameter:
        try:
            return self._parameters[name]
        except KeyError:
            if self.allow_undeclared_parameters:
                return Parameter(name, None, ParameterType.NOT_SET)
            raise ParameterNotDeclaredError(
                f"parameter {name!r} is not declared", where=f"node {self.fully_qualified_name}"
            ) from None

    def get_parameter_or(self, name: str, alternative: Any = None) -> Parameter:
        return self._parameters.get(name, Parameter(name, alternative))

    def get_parameters(self, names: Sequence[str]) -> list[Parameter]:
        return [self.get_parameter(n) for n in names]

    def get_parameters_by_prefix(self, prefix: str) -> dict[str, Parameter]:
        p = f"{prefix}." if prefix else ""
        return {k[len(p):]: v for k, v in self._parameters.items() if k.startswith(p)}

    @property
    def parameters(self) -> dict[str, Parameter]:
        return dict(self._parameters)

    def describe_parameter(self, name: str) -> ParameterDescriptor:
        return self._descriptors.get(name, ParameterDescriptor())

    def add_on_set_parameters_callback(self, callback: _ParamCallback) -> None:
        self._on_set.append(callback)

    def remove_on_set_parameters_callback(self, callback: _ParamCallback) -> None:
        self._on_set.remove(callback)

    def add_post_set_parameters_callback(self, callback: Callable[[list[Parameter]], None]) -> None:
        """Called with the parameters after a successful set (rclpy's post-set callback)."""
        self._post_set.append(callback)

    def set_parameters(self, parameters: Sequence[Parameter]) -> list[SetParametersResult]:
        return [self.set_parameters_atomically([p]) for p in parameters]

    def set_parameters_atomically(self, parameters: Sequence[Parameter]) -> SetParametersResult:
        """Validate every parameter, ask the on-set callbacks, then apply all or none."""
        checked: list[Parameter] = []
        for p in parameters:
            where = f"node {self.fully_qualified_name} key {p.name}"
            current = self._parameters.get(p.name)
            if current is None and not self.allow_undeclared_parameters:
                return SetParametersResult(False, f"parameter {p.name!r} is not declared")
            desc = self._descriptors.get(p.name, ParameterDescriptor())
            if desc.read_only:
                return SetParametersResult(
                    False, f"parameter {p.name!r} is read-only: the node reads it once at start "
                    f"(set it in a params file or with -p)")
            try:
                if current is not None and not desc.dynamic_typing and p.value is not None:
                    value = coerce(p.value, current.type, name=p.name, where=where)
                else:
                    value = p.value
                self._check_range(p.name, value, desc, where)
            except (InvalidParameterTypeError, InvalidParameterValueError) as exc:
                return SetParametersResult(False, str(exc))
            checked.append(Parameter(p.name, value))
        for cb in self._on_set:
            result = cb(checked)
            if not result.successful:
                return result
        for p in checked:
            self._parameters[p.name] = p
        for post in self._post_set:
            post(checked)
        return SetParametersResult(True)

    def set_parameter(self, name: str, value: Any) -> SetParametersResult:
        return self.set_parameters_atomically([Parameter(name, value)])

    @staticmethod
    def _check_range(name: str, value: Any, desc: ParameterDescriptor, where: str) -> None:
        if desc.range is None or not isinstance(value, (int, float)) or isinstance(value, bool):
            return
        lo, hi = desc.range
        if not lo <= value <= hi:
            raise InvalidParameterValueError(
                f"parameter {name!r} = {value} is outside [{lo}, {hi}]", where=where
            )

    def __repr__(self) -> str:
        return f"<Node {self.fully_qualified_name}>"
