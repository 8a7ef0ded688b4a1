"""What the navigator gives the tree's nodes: clock, robot pose and speed, and the ROS
clients (made on first use, one per server name, shared by every node naming it).

Nav2 hands these over on the blackboard (``node``, ``tf_buffer``, ``server_timeout``, …);
here they are one object, :class:`TreeContext`, so the blackboard holds only the tree's
own entries. A context without a node (``node=None``) still loads and ticks trees whose
nodes need no server — enough to validate a file.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

__all__ = ["TreeContext"]


class TreeContext:
    def __init__(self, node: Any = None, *,
                 clock: Callable[[], int] | None = None,
                 robot_pose: Callable[[str | None, str | None], Any] | None = None,
                 speed: Callable[[], float] | None = None,
                 server_timeout_ms: int = 20,
                 wait_for_service_timeout_ms: int = 1000,
                 goal_updater_topic: str = "goal_update") -> None:
        self.node = node
        self._clock = clock
        self._robot_pose = robot_pose
        self._speed = speed
        self.server_timeout_ms = int(server_timeout_ms)
        self.wait_for_service_timeout_ms = int(wait_for_service_timeout_ms)
        self.goal_updater_topic = goal_updater_topic
        self._action_clients: dict[str, Any] = {}
        self._service_clients: dict[str, Any] = {}
        self._subs: dict[str, Any] = {}
        self._latest: dict[str, Any] = {}
        #: goal handles in flight per action name (for the Cancel* nodes)
        self.active_goals: dict[str, set[Any]] = {}
        #: the message of the last server failure, for the navigation's result
        self.last_error_msg = ""
        #: ComputePath* requests made so far (numbered from 1), and the number of the one
        #: whose path came last (None before one): a path requested before a preemption
        #: is the old goal's
        self.plan_requests = 0
        self.planned_request: int | None = None

    # -- time, pose, speed --------------------------------------------------------------------
    def now_ns(self) -> int:
        if self._clock is not None:
            return int(self._clock())
        if self.node is not None:
            return int(self.node.now().nanoseconds)
        return time.monotonic_ns()

    def robot_pose(self, global_frame: str | None = None, base_frame: str | None = None) -> Any:
        """(x, y, yaw) of the robot, or None when TF does not give it."""
        return self._robot_pose(global_frame, base_frame) if self._robot_pose is not None else None

    def speed(self) -> float:
        return float(self._speed()) if self._speed is not None else 0.0

    def warn(self, msg: str) -> None:
        if self.node is not None:
            self.node.get_logger().warning(msg)

    # -- clients ------------------------------------------------------------------------------
    @staticmethod
    def _absolute(name: str) -> str:
        return name if name.startswith("/") else "/" + name

    def action_client(self, action_type: Any, name: str) -> Any:
        if self.node is None:
            return None
        key = self._absolute(name)
        client = self._action_clients.get(key)
        if client is None:
            from eddiebot.core.action import ActionClient

            client = ActionClient(self.node, action_type, key)
            self._action_clients[key] = client
        return client

    def service_client(self, srv_type: Any, name: str) -> Any:
        if self.node is None:
            return None
        key = self._absolute(name)
        client = self._service_clients.get(key)
        if client is None:
            client = self.node.create_client(srv_type, key)
            self._service_clients[key] = client
        return client

    def latest(self, topic: str, msg_type: Any = None) -> Any:
        """The last message on ``topic`` (subscribed on first use), or None."""
        if self.node is not None and topic not in self._subs:
            if msg_type is None:
                from eddiebot.msgs.geometry_msgs import PoseStamped

                msg_type = PoseStamped
            self._subs[topic] = self.node.create_subscription(
                msg_type, topic, lambda m, t=topic: self._latest.__setitem__(t, m), 10)
        return self._latest.get(topic)

    def destroy(self) -> None:
        """Destroy every client and subscription made for the trees."""
        if self.node is None:
            return
        for c in self._action_clients.values():
            c.destroy()
        for s in self._service_clients.values():
            self.node.destroy_client(s)
        for sub in self._subs.values():
            self.node.destroy_subscription(sub)
        self._action_clients.clear()
        self._service_clients.clear()
        self._subs.clear()
