"""``Node``: names, parameters, logging and the factory of its entities.

Names and behaviour follow rclpy. Callbacks run on the executor the node is added to. The
entities live beside it: callback groups (``callback_groups``), publishers, subscriptions,
timers and guard conditions (``entities``), services and clients (``services``), graph
queries (``graph``), QoS events (``qos_events``), rates (``rate``) and the
``~/get_type_description`` service (``type_description``); they are importable from here too.
"""

from __future__ import annotations

import enum
import inspect
import logging
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from eddiebot.core.callback_groups import (
    CallbackGroup,
    MutuallyExclusiveCallbackGroup,
    ReentrantCallbackGroup,
)
from eddiebot.core.context import Context, get_default_context
from eddiebot.core.entities import GuardCondition, Publisher, Subscription, Timer
from eddiebot.core.errors import (
    InvalidParameterTypeError,
    InvalidParameterValueError,
    ParameterAlreadyDeclaredError,
    ParameterNotDeclaredError,
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
from eddiebot.core.services import Client, Service
from eddiebot.core.task import Future
from eddiebot.core.time import Clock, Time
from eddiebot.msgs import ServiceType

if TYPE_CHECKING:
    from eddiebot.core.executors import Executor
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
