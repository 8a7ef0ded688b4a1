"""A managed node (rclpy.lifecycle.LifecycleNode) and its publishers, silent until active."""

from __future__ import annotations

import uuid
from typing import Any

from eddiebot.core.lifecycle.bond import _NODE_BOND_TIMEOUT_S, bond_status
from eddiebot.core.lifecycle.states import (
    _ERROR_RESULT_BASE,
    _F,
    _TRANSITIONS,
    _U,
    LifecycleState,
    State,
    TransitionCallbackReturn,
    _Transition,
)
from eddiebot.core.node import Node, Publisher, Timer
from eddiebot.core.qos import QoSProfile, as_qos


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
