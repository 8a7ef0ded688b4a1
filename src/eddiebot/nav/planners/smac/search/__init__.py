"""Search kernels of the Smac planners (numba): the 2D A* of ``SmacPlanner2D``, the
obstacle heuristic and the Hybrid-A* of ``SmacPlannerHybrid``.

Status codes returned by the searches: ``FOUND``, ``NO_PATH`` (queue exhausted),
``MAX_ITERATIONS`` (``max_iterations`` expansions), ``TIMED_OUT`` (``max_planning_time``,
checked every ``terminal_checking_interval`` expansions as upstream does).

The kernels live by idea: :mod:`.common` (status codes, cell costs, turn directions),
:mod:`eddiebot.nav.planners._heap` (the open set, shared with Theta*), :mod:`.grid_2d` (the 2D A*), :mod:`.heuristics` and
:mod:`.hybrid` (the Hybrid-A*); this package re-exports them.
"""

from __future__ import annotations

from eddiebot.nav.planners.smac.search.common import (
    FORWARD,
    FOUND,
    INSCRIBED,
    LEFT,
    MAX_ITERATIONS,
    NO_PATH,
    OCCUPIED,
    REV_LEFT,
    REV_RIGHT,
    REVERSE,
    RIGHT,
    TIMED_OUT,
    UNKNOWN,
)
from eddiebot.nav.planners.smac.search.common import _now as _now
from eddiebot.nav.planners.smac.search.grid_2d import astar_2d, downsample_max
from eddiebot.nav.planners.smac.search.heuristics import obstacle_heuristic
from eddiebot.nav.planners.smac.search.hybrid import _in_collision as _in_collision
from eddiebot.nav.planners.smac.search.hybrid import hybrid_astar, traversal_cost

__all__ = [
    "FORWARD",
    "FOUND",
    "INSCRIBED",
    "LEFT",
    "MAX_ITERATIONS",
    "NO_PATH",
    "OCCUPIED",
    "REVERSE",
    "REV_LEFT",
    "REV_RIGHT",
    "RIGHT",
    "TIMED_OUT",
    "UNKNOWN",
    "astar_2d",
    "downsample_max",
    "hybrid_astar",
    "obstacle_heuristic",
    "traversal_cost",
]
