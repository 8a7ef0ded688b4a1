"""Nav2's lifecycle_manager: brings managed nodes up in order, down in reverse, and watches
their bonds."""

from __future__ import annotations

import enum
import uuid
from collections.abc import Callable
from typing import Any

from eddiebot.core.lifecycle.bond import _MANAGER_BOND_PERIOD_S, _bond_id, bond_status
from eddiebot.core.lifecycle.states import _TRANSITIONS, LifecycleState
from eddiebot.core.node import Node, Timer


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
