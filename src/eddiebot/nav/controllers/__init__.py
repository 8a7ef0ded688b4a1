"""Local controllers and their checkers, with Nav2's plugin registries.

``CONTROLLER_PLUGINS``, ``PROGRESS_CHECKER_PLUGINS`` and ``GOAL_CHECKER_PLUGINS`` are the
``controllers``, ``progress_checkers`` and ``goal_checkers`` registries of
:mod:`eddiebot.nav.plugins` (built-in types, ``register`` calls, entry points);
:func:`build_controller_server` reads a controller server's ``ros__parameters``
(``controller_plugins: [FollowPath]``, ``FollowPath: {plugin: ...}``) and builds each
instance by its type's factory, with a :class:`~eddiebot.nav.plugins.PluginContext` whose
``server_config`` is the :class:`ControllerServerConfig` (``controller_frequency``).
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
from eddiebot.nav.controllers.rotation_shim import (
    SHIM_TYPE,
    RotationShimConfig,
    RotationShimController,
)
from eddiebot.nav.controllers.rpp import (
    RegulatedPurePursuitConfig,
    RegulatedPurePursuitController,
)
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import InvalidController, ParameterError
from eddiebot.nav.params import from_params, require
from eddiebot.nav.plugins import PluginContext, PluginRegistry, registry
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


CONTROLLER_PLUGINS = registry("controllers")
PROGRESS_CHECKER_PLUGINS = registry("progress_checkers")
GOAL_CHECKER_PLUGINS = registry("goal_checkers")


def _rpp(params: dict[str, Any], name: str, context: PluginContext) -> Any:
    return RegulatedPurePursuitController(
        from_params(RegulatedPurePursuitConfig, params, server=context.where), name,
        context.server_config.controller_frequency)


def _dwb(params: dict[str, Any], name: str, context: PluginContext) -> Any:
    return DWBController(dwb_config_from_params(params, context.where), name,
                         context.server_config.controller_frequency)


def _mppi(params: dict[str, Any], name: str, context: PluginContext) -> Any:
    return MPPIController.from_params(params, name, context.server_config.controller_frequency,
                                      context.server)


def _checker(cls: type[Any], config_cls: type[Any]) -> Any:
    def factory(params: dict[str, Any], name: str, context: PluginContext) -> Any:
        return cls(from_params(config_cls, params, server=context.where))
    return factory


CONTROLLER_PLUGINS.register(
    "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController", _rpp,
    RegulatedPurePursuitConfig, source="built-in")
# DWB's and MPPI's keys nest (critics' blocks), so no one config dataclass lists them
CONTROLLER_PLUGINS.register("dwb_core::DWBLocalPlanner", _dwb, source="built-in")
CONTROLLER_PLUGINS.register("nav2_mppi_controller::MPPIController", _mppi, source="built-in")
# the shim's block also holds its primary's keys
CONTROLLER_PLUGINS.register(SHIM_TYPE, RotationShimController.from_params, source="built-in")
PROGRESS_CHECKER_PLUGINS.register(
    "nav2_controller::SimpleProgressChecker",
    _checker(SimpleProgressChecker, SimpleProgressCheckerConfig), SimpleProgressCheckerConfig,
    source="built-in")
PROGRESS_CHECKER_PLUGINS.register(
    "nav2_controller::PoseProgressChecker",
    _checker(PoseProgressChecker, PoseProgressCheckerConfig), PoseProgressCheckerConfig,
    source="built-in")
GOAL_CHECKER_PLUGINS.register(
    "nav2_controller::SimpleGoalChecker",
    _checker(SimpleGoalChecker, SimpleGoalCheckerConfig), SimpleGoalCheckerConfig,
    source="built-in")


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


def _build(params: Mapping[str, Any], name: str, plugins: PluginRegistry,
           context: PluginContext) -> Any:
    sub = params.get(name, {}) or {}
    plugin = sub.get("plugin", _DEFAULT_PLUGIN.get(name))
    if plugin is None:
        raise ParameterError(context.server, f"{name}.plugin", None, "missing plugin type")
    return plugins.create(str(plugin), sub, name, context)


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
        out.controllers[name] = _build(params, name, CONTROLLER_PLUGINS,
                                       PluginContext(server, name, cfg))
    for name in cfg.progress_checker_plugins:
        out.progress_checkers[name] = _build(params, name, PROGRESS_CHECKER_PLUGINS,
                                             PluginContext(server, name, cfg))
    for name in cfg.goal_checker_plugins:
        out.goal_checkers[name] = _build(params, name, GOAL_CHECKER_PLUGINS,
                                         PluginContext(server, name, cfg))
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
    "RotationShimConfig",
    "RotationShimController",
    "SimpleGoalChecker",
    "SimpleGoalCheckerConfig",
    "SimpleProgressChecker",
    "SimpleProgressCheckerConfig",
    "build_controller_server",
]
