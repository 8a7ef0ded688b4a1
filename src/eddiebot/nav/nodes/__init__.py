"""Nav2's servers as lifecycle nodes over the pure cores in :mod:`eddiebot.nav`.

One module per server (``map_server``, ``amcl``, ``planner_server``, ``controller_server``,
``smoother_server``, ``velocity_smoother``, ``collision_monitor``, ``behavior_server``,
``bt_navigator``, ``waypoint_follower``), each taking Nav2's parameter names and defaults,
serving the nav2_msgs actions and services, and publishing Nav2's topics. The velocity
chain is ``/cmd_vel_nav`` → velocity smoother → ``/cmd_vel_smoothed`` → collision monitor
→ ``/cmd_vel_safe``. ``SERVER_CLASSES`` maps default node names to classes, imported lazily;
``params_audit.audit_nav2_params`` says what a Nav2 parameters file asks that they do not do.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["SERVER_CLASSES", "server_class"]

_WHERE = {
    "map_server": "map_server:MapServer",
    "map_saver": "map_server:MapSaver",
    "amcl": "amcl:AmclNode",
    "planner_server": "planner_server:PlannerServer",
    "controller_server": "controller_server:ControllerServer",
    "smoother_server": "smoother_server:SmootherServer",
    "velocity_smoother": "velocity_smoother:VelocitySmootherNode",
    "collision_monitor": "collision_monitor:CollisionMonitorNode",
    "behavior_server": "behavior_server:BehaviorServer",
    "bt_navigator": "bt_navigator:BtNavigator",
    "waypoint_follower": "waypoint_follower:WaypointFollower",
}


def server_class(name: str) -> Any:
    """The node class of server ``name`` (its default node name)."""
    module, _, attr = _WHERE[name].partition(":")
    return getattr(importlib.import_module(f"eddiebot.nav.nodes.{module}"), attr)


class _Lazy(dict[str, Any]):
    def __missing__(self, key: str) -> Any:
        cls = server_class(key)
        self[key] = cls
        return cls


SERVER_CLASSES: dict[str, Any] = _Lazy()
