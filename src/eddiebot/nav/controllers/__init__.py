"""Local controllers and their checkers, with Nav2's plugin registries.

``CONTROLLER_PLUGINS``, ``PROGRESS_CHECKER_PLUGINS`` and ``GOAL_CHECKER_PLUGINS`` map plugin
type names to classes; :func:`build_controller_server` reads a controller server's
``ros__parameters`` (``controller_plugins: [FollowPath]``, ``FollowPath: {plugin: ...}``).
A controller has ``compute_velocity_commands(pose, velocity, path, costmap, dt) -> Twist2D``,
``set_plan``, ``set_speed_limit`` and ``set_goal_tolerance``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy.typing as npt

from eddiebot.nav.controllers.checkers import (
    PoseProgressChecker,
    PoseProgressCheckerConfig,
    SimpleGoalChecker,
    SimpleGoalCheckerConfig,
    SimpleProgressChecker,
    SimpleProgressCheckerConfig,
)
from eddiebot.nav.controllers.dwb import DWBConfig, DWBController, dwb_config_from_params
from eddiebot.nav.controllers.mppi import MPPIConfig, MPPIController
from eddiebot.nav.controllers.rpp import (
    RegulatedPurePursuitConfig,
    RegulatedPurePursuitController,
)
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import InvalidController, ParameterError, UnsupportedPlugin
from eddiebot.nav.params import from_params, require
from eddiebot.nav.planners import plugin_key
from eddiebot.nav.types import Twist2D


class Controller(Protocol):
    name: str

    def set_plan(self, path: npt.ArrayLike) -> None: ...

    def set_speed_limit(self, speed_limit: float, percentage: bool) -> None: ...

    def set_goal_tolerance(self, xy_tolerance: float) -> None: ...

    def compute_velocity_commands(
        self, pose: npt.ArrayLike, velocity: Twist2D, path: npt.ArrayLike | None,
        costmap: LayeredCostmap, dt: float | None = None,
    ) -> Twist2D: ...


CONTROLLER_PLUGINS: dict[str, type[Any]] = {
    "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController":
        RegulatedPurePursuitController,
    "dwb_core::DWBLocalPlanner": DWBController,
    "nav2_mppi_controller::MPPIController": MPPIController,
}
PROGRESS_CHECKER_PLUGINS: dict[str, type[Any]] = {
    "nav2_controller::SimpleProgressChecker": SimpleProgressChecker,
    "nav2_controller::PoseProgressChecker": PoseProgressChecker,
}
GOAL_CHECKER_PLUGINS: dict[str, type[Any]] = {
    "nav2_controller::SimpleGoalChecker": SimpleGoalChecker,
}


@dataclass(frozen=True)
class ControllerServerConfig:
    """``controller_server`` parameters (Jazzy code defaults)."""

    controller_frequency: float = 20.0
    min_x_velocity_threshold: float = 0.0001
    min_y_velocity_threshold: float = 0.0001
    min_theta_velocity_threshold: float = 0.0001
    failure_tolerance: float = 0.0
    speed_limit_topic: str = "speed_limit"
    use_realtime_priority: bool = False
    progress_checker_plugins: tuple[str, ...] = ("progress_checker",)
    goal_checker_plugins: tuple[str, ...] = ("goal_checker",)
    controller_plugins: tuple[str, ...] = ("FollowPath",)

    def validate(self, server: str = "controller_server") -> None:
        require(self.controller_frequency > 0.0, server, "controller_frequency",
                self.controller_frequency, "must be > 0")
        require(len(self.controller_plugins) > 0, server, "controller_plugins",
                list(self.controller_plugins), "needs at least one controller")


@dataclass
class ControllerServer:
    """What a controller server loads: plugins by instance name."""

    config: ControllerServerConfig
    controllers: dict[str, Controller] = field(default_factory=dict)
    progress_checkers: dict[str, SimpleProgressChecker] = field(default_factory=dict)
    goal_checkers: dict[str, SimpleGoalChecker] = field(default_factory=dict)

    def controller(self, controller_id: str) -> Controller:
        if not controller_id and len(self.controllers) == 1:
            return next(iter(self.controllers.values()))
        if controller_id not in self.controllers:
            raise InvalidController(
                f"controller {controller_id!r} not loaded; have {sorted(self.controllers)}"
            )
        return self.controllers[controller_id]


_DEFAULT_PLUGIN = {
    "FollowPath": "dwb_core::DWBLocalPlanner",
    "progress_checker": "nav2_controller::SimpleProgressChecker",
    "goal_checker": "nav2_controller::SimpleGoalChecker",
}


def _plugin(params: Mapping[str, Any], name: str, registry: Mapping[str, type[Any]],
            server: str) -> tuple[type[Any], dict[str, Any]]:
    sub = dict(params.get(name, {}) or {})
    plugin = sub.pop("plugin", _DEFAULT_PLUGIN.get(name))
    if plugin is None:
        raise ParameterError(server, f"{name}.plugin", None, "missing plugin type")
    cls = registry.get(plugin_key(str(plugin)))
    if cls is None:
        raise UnsupportedPlugin(server, f"{name}.plugin", plugin,
                             f"unknown plugin; known: {sorted(registry)}")
    return cls, sub


def build_controller_server(params: Mapping[str, Any] | None = None,
                            server: str = "controller_server") -> ControllerServer:
    params = dict(params or {})
    flat = {k: v for k, v in params.items() if not isinstance(v, dict)}
    # Humble spelled the checker lists in the singular.
    if "progress_checker_plugin" in flat and "progress_checker_plugins" not in flat:
        flat["progress_checker_plugins"] = [flat["progress_checker_plugin"]]
    cfg = from_params(ControllerServerConfig, flat, server=server)
    out = ControllerServer(cfg)
    for name in cfg.controller_plugins:
        cls, sub = _plugin(params, name, CONTROLLER_PLUGINS, server)
        where = f"{server}.{name}"
        if cls is DWBController:
            out.controllers[name] = DWBController(dwb_config_from_params(sub, where), name,
                                                  cfg.controller_frequency)
        elif cls is MPPIController:
            out.controllers[name] = MPPIController.from_params(
                sub, name, cfg.controller_frequency, server)
        else:
            out.controllers[name] = RegulatedPurePursuitController(
                from_params(RegulatedPurePursuitConfig, sub, server=where), name,
                cfg.controller_frequency,
            )
    for name in cfg.progress_checker_plugins:
        pcls, sub = _plugin(params, name, PROGRESS_CHECKER_PLUGINS, server)
        if pcls is PoseProgressChecker:
            out.progress_checkers[name] = PoseProgressChecker(
                from_params(PoseProgressCheckerConfig, sub, server=f"{server}.{name}"))
        else:
            out.progress_checkers[name] = SimpleProgressChecker(
                from_params(SimpleProgressCheckerConfig, sub, server=f"{server}.{name}"))
    for name in cfg.goal_checker_plugins:
        _, sub = _plugin(params, name, GOAL_CHECKER_PLUGINS, server)
        out.goal_checkers[name] = SimpleGoalChecker(
            from_params(SimpleGoalCheckerConfig, sub, server=f"{server}.{name}"))
    return out


__all__ = [
    "CONTROLLER_PLUGINS",
    "GOAL_CHECKER_PLUGINS",
    "PROGRESS_CHECKER_PLUGINS",
    "Controller",
    "ControllerServer",
    "ControllerServerConfig",
    "DWBConfig",
    "DWBController",
    "MPPIConfig",
    "MPPIController",
    "PoseProgressChecker",
    "PoseProgressCheckerConfig",
    "RegulatedPurePursuitConfig",
    "RegulatedPurePursuitController",
    "SimpleGoalChecker",
    "SimpleGoalCheckerConfig",
    "SimpleProgressChecker",
    "SimpleProgressCheckerConfig",
    "build_controller_server",
]
