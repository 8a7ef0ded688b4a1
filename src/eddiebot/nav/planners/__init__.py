"""Global planners with Nav2's plugin registry (``planner_plugins``).

``PLANNER_PLUGINS`` is the ``planners`` registry of :mod:`eddiebot.nav.plugins` (built-in
types, :func:`register_planner` calls and entry points of group ``eddiebot.nav.planners``);
:func:`build_planners` reads a planner server's ``ros__parameters`` (``planner_plugins:
[GridBased]``, ``GridBased: {plugin: nav2_navfn_planner::NavfnPlanner, ...}``) and returns
``{name: planner}``. Every planner has ``create_plan(start, goal, costmap) -> (N, 3) path``
and raises the typed failures of :mod:`eddiebot.nav.errors`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import InvalidPlanner, ParameterError
from eddiebot.nav.params import from_params, require
from eddiebot.nav.planners.navfn import NavfnConfig, NavfnPlanner
from eddiebot.nav.planners.smac import (
    SmacPlanner2D,
    SmacPlanner2DConfig,
    SmacPlannerHybrid,
    SmacPlannerHybridConfig,
)
from eddiebot.nav.planners.theta_star import ThetaStarConfig, ThetaStarPlanner
from eddiebot.nav.plugins import PluginContext, PluginFactory, plugin_key, registry


class GlobalPlanner(Protocol):
    name: str

    def create_plan(
        self, start: npt.ArrayLike, goal: npt.ArrayLike, costmap: Costmap2D
    ) -> npt.NDArray[np.float64]: ...


PLANNER_PLUGINS = registry("planners")


def register_planner(type_name: str, cls: type[Any], config_cls: type[Any]) -> None:
    """Register a planner built as ``cls(config, name=name)`` with its config dataclass
    ``config_cls`` read from the instance's parameters (Nav2 names and defaults)."""

    def factory(params: dict[str, Any], name: str, context: PluginContext) -> Any:
        return cls(from_params(config_cls, params, server=context.where), name=name)

    f: PluginFactory = factory
    PLANNER_PLUGINS.register(type_name, f, config_cls, source="built-in")


register_planner("nav2_navfn_planner::NavfnPlanner", NavfnPlanner, NavfnConfig)
register_planner("nav2_theta_star_planner::ThetaStarPlanner", ThetaStarPlanner, ThetaStarConfig)
register_planner("nav2_smac_planner::SmacPlanner2D", SmacPlanner2D, SmacPlanner2DConfig)
register_planner("nav2_smac_planner::SmacPlannerHybrid", SmacPlannerHybrid, SmacPlannerHybridConfig)


@dataclass(frozen=True)
class PlannerServerConfig:
    """``planner_server`` parameters (Jazzy code defaults)."""

    expected_planner_frequency: float = 1.0
    planner_plugins: tuple[str, ...] = ("GridBased",)
    costmap_update_timeout: float = 1.0

    def validate(self, server: str = "planner_server") -> None:
        require(len(self.planner_plugins) > 0, server, "planner_plugins",
                list(self.planner_plugins), "needs at least one planner")


def build_planners(params: Mapping[str, Any] | None = None, server: str = "planner_server"
                   ) -> dict[str, GlobalPlanner]:
    params = dict(params or {})
    flat = {k: v for k, v in params.items() if not isinstance(v, dict)}
    cfg = from_params(PlannerServerConfig, flat, server=server)
    out: dict[str, GlobalPlanner] = {}
    for name in cfg.planner_plugins:
        sub = dict(params.get(name, {}) or {})
        plugin = sub.pop("plugin", "nav2_navfn_planner::NavfnPlanner" if name == "GridBased" else None)
        if plugin is None:
            raise ParameterError(server, f"{name}.plugin", None, "missing plugin type")
        out[name] = PLANNER_PLUGINS.create(str(plugin), sub, name,
                                           PluginContext(server, name, cfg))
    return out


def get_planner(planners: Mapping[str, GlobalPlanner], planner_id: str) -> GlobalPlanner:
    """Planner by id; an empty id picks the only planner (as the planner server does)."""
    if not planner_id and len(planners) == 1:
        return next(iter(planners.values()))
    if planner_id not in planners:
        raise InvalidPlanner(f"planner {planner_id!r} not loaded; have {sorted(planners)}")
    return planners[planner_id]


__all__ = [
    "PLANNER_PLUGINS",
    "GlobalPlanner",
    "NavfnConfig",
    "NavfnPlanner",
    "PlannerServerConfig",
    "ThetaStarConfig",
    "ThetaStarPlanner",
    "build_planners",
    "get_planner",
    "plugin_key",
    "register_planner",
]
