"""Global planners with Nav2's plugin registry (``planner_plugins``).

``PLANNER_PLUGINS`` maps plugin type names to classes; :func:`build_planners` reads a
planner server's ``ros__parameters`` (``planner_plugins: [GridBased]``, ``GridBased:
{plugin: nav2_navfn_planner::NavfnPlanner, ...}``) and returns ``{name: planner}``. Every
planner has ``create_plan(start, goal, costmap) -> (N, 3) path`` and raises the typed
failures of :mod:`eddiebot.nav.errors`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import InvalidPlanner, ParameterError, UnsupportedPlugin
from eddiebot.nav.params import from_params, require
from eddiebot.nav.planners.navfn import NavfnConfig, NavfnPlanner
from eddiebot.nav.planners.theta_star import ThetaStarConfig, ThetaStarPlanner


class GlobalPlanner(Protocol):
    name: str

    def create_plan(
        self, start: npt.ArrayLike, goal: npt.ArrayLike, costmap: Costmap2D
    ) -> npt.NDArray[np.float64]: ...


PLANNER_PLUGINS: dict[str, tuple[type[Any], type[Any]]] = {
    "nav2_navfn_planner::NavfnPlanner": (NavfnPlanner, NavfnConfig),
    "nav2_theta_star_planner::ThetaStarPlanner": (ThetaStarPlanner, ThetaStarConfig),
}


@dataclass(frozen=True)
class PlannerServerConfig:
    """``planner_server`` parameters (Jazzy code defaults)."""

    expected_planner_frequency: float = 1.0
    planner_plugins: tuple[str, ...] = ("GridBased",)
    costmap_update_timeout: float = 1.0

    def validate(self, server: str = "planner_server") -> None:
        require(len(self.planner_plugins) > 0, server, "planner_plugins",
                list(self.planner_plugins), "needs at least one planner")


def plugin_key(name: str) -> str:
    """``pkg/Type`` (Humble) and ``pkg::Type`` (Jazzy) name the same plugin."""
    return name.replace("/", "::")


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
        entry = PLANNER_PLUGINS.get(plugin_key(str(plugin)))
        if entry is None:
            raise UnsupportedPlugin(server, f"{name}.plugin", plugin,
                                 f"unknown planner plugin; known: {sorted(PLANNER_PLUGINS)}")
        cls, cfg_cls = entry
        out[name] = cls(from_params(cfg_cls, sub, server=f"{server}.{name}"), name=name)
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
]
