"""Managed (lifecycle) nodes and Nav2's lifecycle manager.

``LifecycleNode`` follows the ROS 2 managed-node state machine (lifecycle_msgs ids)::

    unconfigured --configure--> inactive --activate--> active
         ^  <--cleanup--           ^   <--deactivate--    |
         |                                                 |
         +------ shutdown (from any primary state) -----> finalized

Each transition runs a callback (``on_configure`` …) answering
``TransitionCallbackReturn.SUCCESS`` / ``FAILURE`` (stay) / ``ERROR`` (→ ``on_error``:
SUCCESS back to unconfigured, otherwise finalized); an exception counts as ERROR.
The node serves ``<node>/change_state``, ``get_state``, ``get_available_states``,
``get_available_transitions`` and publishes ``<node>/transition_event``. Lifecycle
publishers stay silent until the node is active. While active the node keeps a bond as
bondcpp does, so a real ``nav2_lifecycle_manager`` can manage it: ``bond/msg/Status`` on the
relative ``bond`` topic (id = node name, a fresh instance id per bond, ``active``, the
heartbeat timeout and period) every ``bond_heartbeat_period`` seconds (0.1 s, as nav2_util),
and one ``active: false`` when the bond is broken on deactivation.

``LifecycleManager`` is Nav2's lifecycle_manager: it configures then activates
``node_names`` in order, takes them down in reverse, serves ``<manager>/manage_nodes``
(nav2_msgs/ManageLifecycleNodes) and ``<manager>/is_active`` (std_srvs/Trigger), and
takes the group down when an active node's heartbeat stops for ``bond_timeout`` or the node
says its bond is broken. Its own side of each bond beats every 0.1 s with its own instance
id, so nodes of a real Nav2 (bondcpp) see their bond formed too.
"""

from __future__ import annotations

import enum
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from eddiebot.core.node import Node, Publisher, Timer
from eddiebot.core.qos import QoSProfile, as_qos

__all__ = [
    "LifecycleManager",
    "LifecycleNode",
    "LifecyclePublisher",
    "LifecycleState",
    "State",
    "TransitionCallbackReturn",
]


class TransitionCallbackReturn(enum.IntEnum):
    """What a transition callback answers (lifecycle_msgs/Transition TRANSITION_CALLBACK_*)."""

    SUCCESS = 97
    FAILURE = 98
    ERROR = 99


class LifecycleState(enum.IntEnum):
    """lifecycle_msgs/State ids."""

    UNKNOWN = 0
    UNCONFIGURED = 1
    INACTIVE = 2
    ACTIVE = 3
    FINALIZED = 4
    CONFIGURING = 10
    CLEANINGUP = 11
    SHUTTINGDOWN = 12
    ACTIVATING = 13
    DEACTIVATING = 14
    ERRORPROCESSING = 15

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass(frozen=True)
class State:
    """A lifecycle state as callbacks receive it (rclpy.lifecycle.State)."""

    state_id: int
    label: str

    @classmethod
    def of(cls, s: LifecycleState) -> State:
        return cls(int(s), s.label)

    def to_msg(self) -> Any:
        from eddiebot.msgs.lifecycle_msgs import State as StateMsg

        return StateMsg(id=self.state_id, label=self.label)


@dataclass(frozen=True)
class _Transition:
    id: int
    label: str
    start: LifecycleState
    via: LifecycleState
    callback: str
    on_success: LifecycleState
    on_failure: LifecycleState
    result_base: int  # lifecycle_msgs/Transition TRANSITION_ON_<X>_SUCCESS


_U, _I, _A, _F = (LifecycleState.UNCONFIGURED, LifecycleState.INACTIVE, LifecycleState.ACTIVE,
                  LifecycleState.FINALIZED)
_TRANSITIONS = (
    _Transition(1, "configure", _U, LifecycleState.CONFIGURING, "on_configure", _I, _U, 10),
    _Transition(2, "cleanup", _I, LifecycleState.CLEANINGUP, "on_cleanup", _U, _I, 20),
    _Transition(3, "activate", _I, LifecycleState.ACTIVATING, "on_activate", _A, _I, 30),
    _Transition(4, "deactivate", _A, LifecycleState.DEACTIVATING, "on_deactivate", _I, _A, 40),
    _Transition(5, "shutdown", _U, LifecycleState.SHUTTINGDOWN, "on_shutdown", _F, _F, 50),
    _Transition(6, "shutdown", _I, LifecycleState.SHUTTINGDOWN, "on_shutdown", _F, _F, 50),
    _Transition(7, "shutdown", _A, LifecycleState.SHUTTINGDOWN, "on_shutdown", _F, _F, 50),
)
_ERROR_RESULT_BASE = 60
#: nav2_util's LifecycleNode: setHeartbeatTimeout(4.0); nav2's manager beats every 0.1 s
_NODE_BOND_TIMEOUT_S = 4.0
_MANAGER_BOND_PERIOD_S = 0.1


def _bond_id(node_name: str) -> str:
    """The bond id nav2 uses for a managed node: its name, without namespace."""
    return node_name.rstrip("/").rsplit("/", 1)[-1]


def bond_status(bond_id: str, instance_id: str, active: bool, stamp_ns: int,
                heartbeat_timeout_s: float, heartbeat_period_s: float) -> Any:
    """A ``bond/msg/Status`` heartbeat as bondcpp publishes it."""
    from eddiebot.msgs.bond import Status
    from eddiebot.msgs.builtin_interfaces import Time

    msg = Status(id=bond_id, instance_id=instance_id, active=active,
                 heartbeat_timeout=heartbeat_timeout_s, heartbeat_period=heartbeat_period_s)
    msg.header.stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    return msg


class LifecyclePublisher(Publisher):
    """A publisher that drops messages (logging once) while its node is not active."""

    def __init__(self, node: Node, msg_type: Any, topic: str, qos: QoSProfile) -> None:
        super().__init__(node, msg_type, topic, qos)
        self._activated = False

    @property
    def is_activated(self) -> bool:
        return self._activated

    def on_activate(self) -> None:
        self._activated = True

    def on_deactivate(self) -> None:
        self._activated = False

    def publish(self, msg: Any) -> None:
        if not self._activated:
            self.node.get_logger().warning(
                f"Trying to publish message on the topic '{self.topic_name}', but the "
                f"publisher is not activated", once=True)
            return
        super().publish(msg)


class LifecycleNode(Node):
    """A managed node (rclpy.lifecycle.LifecycleNode); override the ``on_*`` callbacks."""

    def __init__(self, node_name: str, *, enable_communication_interface: bool = True,
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._state = LifecycleState.UNCONFIGURED
        self._managed: list[LifecyclePublisher] = []
        self._bond_timer: Timer | None = None
        self._bond_pub: Publisher | None = None
        self._bond_instance = ""
        self._in_transition = False
        if not self.has_parameter("bond_heartbeat_period"):
            self.declare_parameter("bond_heartbeat_period", 0.1)
        self._transition_pub: Publisher | None = None
        if enable_communication_interface:
            from eddiebot.msgs import get_service
            from eddiebot.msgs.lifecycle_msgs import TransitionEvent

            self._transition_pub = self.create_publisher(TransitionEvent, "~/transition_event", 10)
            for name, cb in (
                ("change_state", self._srv_change_state),
                ("get_state", self._srv_get_state),
                ("get_available_states", self._srv_available_states),
                ("get_available_transitions", self._srv_available_transitions),
                ("get_transition_graph", self._srv_transition_graph),
            ):
                kind = "GetAvailableTransitions" if name == "get_transition_graph" else \
                    "".join(w.capitalize() for w in name.split("_"))
                self.create_service(get_service(f"lifecycle_msgs/srv/{kind}"), f"~/{name}", cb)

    # -- callbacks to override --------------------------------------------------------------
    def on_configure(self, state: State) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: State) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: State) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    # -- state --------------------------------------------------------------------------
    @property
    def current_state(self) -> State:
        return State.of(self._state)

    def get_current_state(self) -> State:
        return State.of(self._state)

    def available_transitions(self) -> list[tuple[int, str]]:
        """(id, label) of the transitions valid from the current state."""
        return [(t.id, t.label) for t in _TRANSITIONS if t.start == self._state]

    def trigger_configure(self) -> TransitionCallbackReturn:
        return self.trigger_transition("configure")

    def trigger_cleanup(self) -> TransitionCallbackReturn:
        return self.trigger_transition("cleanup")

    def trigger_activate(self) -> TransitionCallbackReturn:
        return self.trigger_transition("activate")

    def trigger_deactivate(self) -> TransitionCallbackReturn:
        return self.trigger_transition("deactivate")

    def trigger_shutdown(self) -> TransitionCallbackReturn:
        return self.trigger_transition("shutdown")

    def trigger_transition(self, transition: int | str) -> TransitionCallbackReturn:
        """Run one transition from the current state; FAILURE (and a warning) if it is not
        valid from there."""
        match = [t for t in _TRANSITIONS if t.start == self._state
                 and (t.id == transition or t.label == transition)]
        if not match or self._in_transition:
            self.get_logger().warning(
                f"transition {transition!r} is not available from state {self._state.label!r}"
                + (" (another transition is running)" if self._in_transition else ""))
            return TransitionCallbackReturn.FAILURE
        t = match[0]
        self._in_transition = True
        try:
            return self._run(t)
        finally:
            self._in_transition = False

    def _run(self, t: _Transition) -> TransitionCallbackReturn:
        start = self._state
        self._set_state(t.via, t.id, start)
        if t.id == 3:  # publishers may be used inside on_activate
            for pub in self._managed:
                pub.on_activate()
        ret = self._call(t.callback, start)
        if ret == TransitionCallbackReturn.SUCCESS:
            self._set_state(t.on_success, t.result_base, t.via)
        elif ret == TransitionCallbackReturn.FAILURE:
            self._set_state(t.on_failure, t.result_base + 1, t.via)
        else:
            self._set_state(LifecycleState.ERRORPROCESSING, t.result_base + 2, t.via)
            err = self._call("on_error", start)
            goal = _U if err == TransitionCallbackReturn.SUCCESS else _F
            self._set_state(goal, _ERROR_RESULT_BASE + (0 if goal == _U else 1),
                            LifecycleState.ERRORPROCESSING)
        active = self._state == LifecycleState.ACTIVE
        for pub in self._managed:
            if active:
                pub.on_activate()
            else:
                pub.on_deactivate()
        if active:
            self._create_bond()
        else:
            self._destroy_bond()
        return ret

    def _call(self, name: str, start: LifecycleState) -> TransitionCallbackReturn:
        try:
            ret = getattr(self, name)(State.of(start))
        except Exception as exc:
            self.get_logger().error(f"{name} raised {type(exc).__name__}: {exc}")
            return TransitionCallbackReturn.ERROR
        if ret is None or ret is True:
            return TransitionCallbackReturn.SUCCESS
        if ret is False:
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn(int(ret))

    def _set_state(self, state: LifecycleState, transition_id: int, start: LifecycleState) -> None:
        self._state = state
        if self._transition_pub is None:
            return
        from eddiebot.msgs.lifecycle_msgs import Transition, TransitionEvent

        labels = {t.id: t.label for t in _TRANSITIONS}
        self._transition_pub.publish(TransitionEvent(
            timestamp=self.now().nanoseconds,
            transition=Transition(id=transition_id, label=labels.get(transition_id, "")),
            start_state=State.of(start).to_msg(),
            goal_state=State.of(state).to_msg(),
        ))

    # -- lifecycle publishers -----------------------------------------------------------------
    def create_lifecycle_publisher(self, msg_type: Any, topic: str,
                                   qos_profile: QoSProfile | int) -> LifecyclePublisher:
        pub = LifecyclePublisher(self, msg_type, self.resolve_topic_name(topic), as_qos(qos_profile))
        if self._state == LifecycleState.ACTIVE:
            pub.on_activate()
        self.context.add_publisher(pub)
        self.publishers.append(pub)
        self._managed.append(pub)
        return pub

    def destroy_lifecycle_publisher(self, pub: LifecyclePublisher) -> None:
        if pub in self._managed:
            self._managed.remove(pub)
        self.destroy_publisher(pub)

    # -- bond heartbeat -------------------------------------------------------------------
    def _create_bond(self) -> None:
        period = float(self.get_parameter("bond_heartbeat_period").value)
        if period <= 0 or self._bond_timer is not None:
            return
        if self._bond_pub is None:
            from eddiebot.msgs.bond import Status

            # bondcpp: KeepLast(5) on the relative "bond" topic, one instance id per bond
            self._bond_pub = self.create_publisher(Status, "bond", 5)
        self._bond_instance = uuid.uuid4().hex
        self._heartbeat()
        self._bond_timer = self.create_timer(period, self._heartbeat)

    def _destroy_bond(self) -> None:
        if self._bond_timer is not None:
            self.destroy_timer(self._bond_timer)
            self._bond_timer = None
            self._heartbeat(active=False)  # bondcpp's breakBond: tell the sister at once

    def _heartbeat(self, active: bool = True) -> None:
        if self._bond_pub is not None:
            self._bond_pub.publish(bond_status(
                self.get_name(), self._bond_instance, active, self.now().nanoseconds,
                _NODE_BOND_TIMEOUT_S, float(self.get_parameter("bond_heartbeat_period").value)))

    # -- services -------------------------------------------------------------------------
    def _srv_change_state(self, request: Any, response: Any) -> Any:
        tid = int(request.transition.id)
        label = str(request.transition.label)
        key: int | str = label if tid == 0 and label else tid
        valid = any(t.start == self._state and (t.id == key or t.label == key)
                    for t in _TRANSITIONS)
        response.success = valid and self.trigger_transition(key) == TransitionCallbackReturn.SUCCESS
        return response

    def _srv_get_state(self, request: Any, response: Any) -> Any:
        response.current_state = self.current_state.to_msg()
        return response

    def _srv_available_states(self, request: Any, response: Any) -> Any:
        response.available_states = [State.of(s).to_msg() for s in LifecycleState
                                     if s != LifecycleState.UNKNOWN]
        return response

    def _descriptions(self, transitions: list[_Transition]) -> list[Any]:
        from eddiebot.msgs.lifecycle_msgs import Transition, TransitionDescription

        return [TransitionDescription(transition=Transition(id=t.id, label=t.label),
                                      start_state=State.of(t.start).to_msg(),
                                      goal_state=State.of(t.via).to_msg()) for t in transitions]

    def _srv_available_transitions(self, request: Any, response: Any) -> Any:
        response.available_transitions = self._descriptions(
            [t for t in _TRANSITIONS if t.start == self._state])
        return response

    def _srv_transition_graph(self, request: Any, response: Any) -> Any:
        response.available_transitions = self._descriptions(list(_TRANSITIONS))
        return response


# -- manager ----------------------------------------------------------------------------------
class _Call:
    """Executor work item running one call (the autostart, as Nav2's init timer)."""

    __slots__ = ("callback_group", "fn", "node")

    def __init__(self, node: Node, fn: Callable[[], Any]) -> None:
        self.node = node
        self.fn = fn
        self.callback_group = None

    def execute(self) -> None:
        self.fn()


class ManagerCommand(enum.IntEnum):
    """nav2_msgs/ManageLifecycleNodes commands."""

    STARTUP = 0
    PAUSE = 1
    RESUME = 2
    RESET = 3
    SHUTDOWN = 4
    CONFIGURE = 5
    CLEANUP = 6


class LifecycleManager(Node):
    """Nav2's lifecycle_manager: brings ``node_names`` up in order and watches their bonds.

    Parameters (Nav2 names and defaults): ``node_names`` (list of node names, relative to
    the manager's namespace unless they start with ``/``), ``autostart`` (False),
    ``bond_timeout`` (4.0 s; 0 disables bonds), ``attempt_respawn_reconnection`` (True),
    ``bond_respawn_max_duration`` (10.0 s), plus ``service_timeout`` (5.0 s, wall time).
    """

    def __init__(self, node_name: str = "lifecycle_manager", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        from eddiebot.msgs import get_service

        self.declare_parameter("node_names", [""])
        self.declare_parameter("autostart", False)
        self.declare_parameter("bond_timeout", 4.0)
        self.declare_parameter("attempt_respawn_reconnection", True)
        self.declare_parameter("bond_respawn_max_duration", 10.0)
        self.declare_parameter("service_timeout", 5.0)
        self.node_names: list[str] = [str(n) for n in self.get_parameter("node_names").value if n]
        ns = self.get_namespace().rstrip("/")
        self._fqn = {n: n if n.startswith("/") else f"{ns}/{n}" for n in self.node_names}
        change, get = (get_service("lifecycle_msgs/srv/ChangeState"),
                       get_service("lifecycle_msgs/srv/GetState"))
        self._change = {n: self.create_client(change, f"{self._fqn[n]}/change_state")
                        for n in self.node_names}
        self._get = {n: self.create_client(get, f"{self._fqn[n]}/get_state") for n in self.node_names}
        self.system_active = False
        self.last_error = ""
        self.dead_nodes: list[str] = []
        self._last_beat: dict[str, int] = {}
        self._broken: set[str] = set()
        self._bond_timer: Timer | None = None
        self._respawn_timer: Timer | None = None
        self._respawn_since = 0
        self.create_service(get_service("nav2_msgs/srv/ManageLifecycleNodes"), "~/manage_nodes",
                            self._srv_manage)
        self.create_service(get_service("std_srvs/srv/Trigger"), "~/is_active", self._srv_is_active)
        from eddiebot.msgs.bond import Status

        self.create_subscription(Status, "bond", self._on_heartbeat, 100)
        self._bond_pub_mgr = self.create_publisher(Status, "bond", 5)
        self._bond_instance = uuid.uuid4().hex
        self._beat_timer: Timer | None = None
        if self.get_parameter("autostart").value:
            self._notify(_Call(self, self.startup))

    # -- parameters -----------------------------------------------------------------------
    @property
    def bond_timeout_ns(self) -> int:
        return round(float(self.get_parameter("bond_timeout").value) * 1e9)

    # -- transitions --------------------------------------------------------------------
    def _state_of(self, name: str) -> int:
        from eddiebot.msgs.lifecycle_msgs import GetState

        response = self._call(self._get[name], GetState.Request())
        return int(response.current_state.id)

    def _call(self, client: Any, request: Any) -> Any:
        timeout = float(self.get_parameter("service_timeout").value)
        if not client.service_is_ready() and self.context.transports:
            client.wait_for_service(timeout)
        return client.call(request, timeout_sec=timeout)

    def _change_state(self, name: str, transition: int) -> bool:
        from eddiebot.msgs.lifecycle_msgs import ChangeState, Transition

        label = {t.id: t.label for t in _TRANSITIONS}.get(transition, "")
        try:
            response = self._call(self._change[name],
                                  ChangeState.Request(transition=Transition(id=transition)))
        except Exception as exc:
            self.last_error = f"Failed to change state for node: {name} ({label}: {exc})"
            self.get_logger().error(self.last_error)
            return False
        if not response.success:
            self.last_error = f"Failed to change state for node: {name} ({label})"
            self.get_logger().error(self.last_error)
            return False
        return True

    def _bring_up(self, names: list[str]) -> bool:
        for step_from, transition in ((LifecycleState.UNCONFIGURED, 1), (LifecycleState.INACTIVE, 3)):
            for name in names:
                try:
                    state = self._state_of(name)
                except Exception as exc:
                    self.last_error = f"Failed to change state for node: {name} (unreachable: {exc})"
                    self.get_logger().error(self.last_error)
                    return False
                if state == step_from and not self._change_state(name, transition):
                    return False
        return True

    def _bring_down(self, names: list[str], *, cleanup: bool, shutdown: bool = False) -> bool:
        """Deactivate (then clean up / shut down) ``names`` in reverse; keep going on errors."""
        ok = True
        for wanted in ("deactivate", "cleanup", "shutdown"):
            if (wanted == "cleanup" and not cleanup) or (wanted == "shutdown" and not shutdown):
                continue
            for name in reversed(names):
                try:
                    state = self._state_of(name)
                except Exception:
                    ok = False
                    continue
                transition = {("deactivate", 3): 4, ("cleanup", 2): 2, ("shutdown", 1): 5,
                              ("shutdown", 2): 6, ("shutdown", 3): 7}.get((wanted, state))
                if transition is not None and not self._change_state(name, transition):
                    ok = False
        return ok

    def startup(self) -> bool:
        """Configure every node, then activate every node, in order. On a failure the group
        is taken down again and ``last_error`` names the node."""
        self.get_logger().info("Starting managed nodes bringup...")
        self.last_error = ""
        if not self._bring_up(self.node_names):
            error = self.last_error
            self.get_logger().error(f"Failed to bring up all requested nodes. Aborting bringup. "
                                    f"{error}")
            self._bring_down(self.node_names, cleanup=True)
            self.last_error = error
            self.system_active = False
            return False
        self.system_active = True
        self.dead_nodes = []
        self._create_bonds()
        self.get_logger().info("Managed nodes are active")
        return True

    def shutdown(self) -> bool:
        self._destroy_bonds()
        self.system_active = False
        self.get_logger().info("Shutting down managed nodes...")
        return self._bring_down(self.node_names, cleanup=True, shutdown=True)

    def reset(self, hard: bool = False) -> bool:
        self._destroy_bonds()
        self.system_active = False
        names = [n for n in self.node_names if n not in self.dead_nodes] if hard else self.node_names
        return self._bring_down(names, cleanup=True)

    def pause(self) -> bool:
        self._destroy_bonds()
        self.system_active = False
        return self._bring_down(self.node_names, cleanup=False)

    def resume(self) -> bool:
        for name in self.node_names:
            if self._state_of(name) == LifecycleState.INACTIVE and not self._change_state(name, 3):
                return False
        self.system_active = True
        self._create_bonds()
        return True

    def configure(self) -> bool:
        return all(self._state_of(n) != LifecycleState.UNCONFIGURED or self._change_state(n, 1)
                   for n in self.node_names)

    def cleanup(self) -> bool:
        return all(self._state_of(n) != LifecycleState.INACTIVE or self._change_state(n, 2)
                   for n in reversed(self.node_names))

    # -- bonds ------------------------------------------------------------------------------
    def _create_bonds(self) -> None:
        timeout_ns = self.bond_timeout_ns
        if timeout_ns <= 0:
            return
        now = self.now().nanoseconds
        self._last_beat = {_bond_id(n): now for n in self.node_names}
        self._broken = set()
        if self._bond_timer is None:
            self._bond_timer = self.create_timer(min(0.2, timeout_ns / 2e9), self._check_bonds)
        if self._beat_timer is None:
            # the manager's side of each bond beats too, as nav2's lifecycle manager does
            self._beat_timer = self.create_timer(_MANAGER_BOND_PERIOD_S, self._beat)
            self._beat()

    def _beat(self, active: bool = True) -> None:
        now = self.now().nanoseconds
        timeout_s = self.bond_timeout_ns / 1e9
        for bond_id in list(self._last_beat):
            self._bond_pub_mgr.publish(bond_status(bond_id, self._bond_instance, active, now,
                                                   timeout_s, _MANAGER_BOND_PERIOD_S))

    def _destroy_bonds(self) -> None:
        if self._beat_timer is not None:
            self.destroy_timer(self._beat_timer)
            self._beat_timer = None
            self._beat(active=False)
        self._last_beat = {}
        if self._bond_timer is not None:
            self.destroy_timer(self._bond_timer)
            self._bond_timer = None

    def _on_heartbeat(self, msg: Any) -> None:
        # bondcpp's filter: this bond's id, the sister's instance (not our own)
        if msg.id not in self._last_beat or msg.instance_id == self._bond_instance:
            return
        if not msg.active:  # the sister says the bond is broken: dead now, not after the timeout
            self._broken.add(msg.id)
        elif msg.id not in self._broken:  # bondcpp: a dead bond stays dead
            self._last_beat[msg.id] = self.now().nanoseconds

    def _check_bonds(self) -> None:
        if not self.system_active or not self._last_beat:
            return
        now = self.now().nanoseconds
        timeout_ns = self.bond_timeout_ns
        dead = [n for n in self.node_names if _bond_id(n) in self._broken
                or now - self._last_beat.get(_bond_id(n), now) > timeout_ns]
        if not dead:
            return
        for name in dead:
            silent_ms = (now - self._last_beat[_bond_id(name)]) / 1e6
            self.get_logger().error(
                f"CRITICAL FAILURE: SERVER {name} IS DOWN after not receiving a heartbeat for "
                f"{silent_ms:.0f} ms. Shutting down related nodes.")
        self.dead_nodes = dead
        self.last_error = f"bond with {', '.join(dead)} timed out"
        self.reset(hard=True)
        if self.get_parameter("attempt_respawn_reconnection").value:
            self._respawn_since = now
            self._respawn_timer = self.create_timer(1.0, self._check_respawn)

    def _check_respawn(self) -> None:
        elapsed_s = (self.now().nanoseconds - self._respawn_since) / 1e9
        if elapsed_s > float(self.get_parameter("bond_respawn_max_duration").value):
            self.get_logger().error(
                f"Failed to bring up all requested nodes after {elapsed_s:.1f} s of waiting for "
                f"{', '.join(self.dead_nodes)} to come back. Giving up.")
            self._stop_respawn()
            return
        if all(self._get[n].service_is_ready() for n in self.node_names):
            self.get_logger().info("Managed nodes are reachable again; attempting to reconnect")
            self._stop_respawn()
            self.startup()

    def _stop_respawn(self) -> None:
        if self._respawn_timer is not None:
            self.destroy_timer(self._respawn_timer)
            self._respawn_timer = None

    # -- services -----------------------------------------------------------------------
    def _srv_manage(self, request: Any, response: Any) -> Any:
        command = ManagerCommand(int(request.command))
        action = {
            ManagerCommand.STARTUP: self.startup,
            ManagerCommand.PAUSE: self.pause,
            ManagerCommand.RESUME: self.resume,
            ManagerCommand.RESET: self.reset,
            ManagerCommand.SHUTDOWN: self.shutdown,
            ManagerCommand.CONFIGURE: self.configure,
            ManagerCommand.CLEANUP: self.cleanup,
        }[command]
        response.success = bool(action())
        return response

    def _srv_is_active(self, request: Any, response: Any) -> Any:
        response.success = self.system_active
        return response
