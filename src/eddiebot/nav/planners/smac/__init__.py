"""Smac planners (``nav2_smac_planner``): :class:`SmacPlanner2D` (cost-aware A*) and
:class:`SmacPlannerHybrid` (Hybrid-A* with Dubins / Reeds-Shepp motion, footprint collision
checking, analytic expansion and the Smac smoother)."""

from eddiebot.nav.planners.smac.planners import (
    SmacPlanner2D,
    SmacPlanner2DConfig,
    SmacPlannerHybrid,
    SmacPlannerHybridConfig,
    SmacSmootherConfig,
)

__all__ = [
    "SmacPlanner2D",
    "SmacPlanner2DConfig",
    "SmacPlannerHybrid",
    "SmacPlannerHybridConfig",
    "SmacSmootherConfig",
]
