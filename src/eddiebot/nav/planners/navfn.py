"""NavFn global planner (``nav2_navfn_planner``): Dijkstra or A* wavefront over the costmap
with NavFn's cost translation, interpolated potential and gradient-descent path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import (
    GoalOccupied,
    GoalOutsideMapBounds,
    NoValidPath,
    StartOccupied,
    StartOutsideMapBounds,
)
from eddiebot.nav.params import require
from eddiebot.nav.planners import _navfn_kernels as K
from eddiebot.nav.types import as_pose


@dataclass(frozen=True)
class NavfnConfig:
    """``NavfnPlanner`` parameters (Jazzy code defaults)."""

    tolerance: float = 0.5
    use_astar: bool = False
    allow_unknown: bool = True
    use_final_approach_orientation: bool = False

    def validate(self, server: str = "planner_server") -> None:
        require(self.tolerance >= 0.0, server, "tolerance", self.tolerance, "must be >= 0")


class NavfnPlanner:
    """Nav2's NavFn.

    Semantics kept from upstream: the potential grows from the robot's cell (cleared first,
    as ``clearRobotCell`` does) until the goal cell is reached; if the goal has no finite
    potential, the reachable point nearest to it inside the square of half-side ``tolerance``
    (stepped by the resolution) becomes the goal; the path descends the interpolated
    potential gradient in half-cell steps and its end is smoothed onto that goal
    (``smoothApproachToGoal``). Additions: a robot inside a lethal cell raises
    :class:`StartOccupied` (upstream clears it silently), and an unreachable goal whose cell
    is lethal or inscribed raises :class:`GoalOccupied` instead of :class:`NoValidPath` (a
    goal in unknown space stays :class:`NoValidPath`, 208, as upstream, so the BT's planner
    recoveries run: Nav2's ``WouldAPlannerRecoveryHelp`` retries 208, not 206).
    Path poses carry the heading of their segment; the last one the goal's yaw (or the
    final approach's with ``use_final_approach_orientation``).
    """

    def __init__(self, config: NavfnConfig | None = None, name: str = "GridBased") -> None:
        self.config = config or NavfnConfig()
        self.name = name
        self.last_potential: npt.NDArray[np.float32] | None = None

    def create_plan(
        self, start: npt.ArrayLike, goal: npt.ArrayLike, costmap: Costmap2D
    ) -> npt.NDArray[np.float64]:
        """Path (N, 3) from ``start`` to ``goal`` (x, y, yaw in the costmap frame)."""
        s = as_pose(start)
        g = as_pose(goal)
        cs = costmap.world_to_map(s[0], s[1])
        if cs is None:
            raise StartOutsideMapBounds(f"start ({s[0]:.2f}, {s[1]:.2f}) is outside the costmap")
        cg = costmap.world_to_map(g[0], g[1])
        if cg is None:
            raise GoalOutsideMapBounds(f"goal ({g[0]:.2f}, {g[1]:.2f}) is outside the costmap")
        if costmap.get_cost(*cs) == LETHAL_OBSTACLE:
            raise StartOccupied(f"start ({s[0]:.2f}, {s[1]:.2f}) is in a lethal cell")
        if s[0] == g[0] and s[1] == g[1]:
            return np.array([[g[0], g[1], g[2]]])
        nx, ny = costmap.size_x, costmap.size_y
        if nx < 3 or ny < 3:
            raise NoValidPath("costmap too small")
        cost = K.translate_costs(costmap.data, self.config.allow_unknown)
        robot_cell = cs[1] * nx + cs[0]
        cost[robot_cell] = K.COST_NEUTRAL  # clearRobotCell (FREE_SPACE translated)
        goal_cell = cg[1] * nx + cg[0]
        cycles = max(nx * ny // 20, nx + ny)
        pot = K.propagate(cost, nx, ny, robot_cell, goal_cell, self.config.use_astar, cycles, True)
        self.last_potential = pot
        best = self._legal_goal(g, pot, costmap)
        if best is None:
            if costmap.get_cost(*cg) in (INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE):
                raise GoalOccupied(
                    f"goal ({g[0]:.2f}, {g[1]:.2f}) is occupied and no free point lies within "
                    f"tolerance {self.config.tolerance} m"
                )
            raise NoValidPath(f"failed to create plan with tolerance of: {self.config.tolerance}")
        bc = costmap.world_to_map(best[0], best[1])
        assert bc is not None
        # Upstream stops the descent after 4 x the larger side in cycles of PATH_STEP cells,
        # which cuts a winding path (a maze: 35 m on a 284-cell-wide map) before the start.
        # eddiebot: also allow 4 cycles per cell the path can hold (each costs >= COST_NEUTRAL).
        goal_pot = float(pot[bc[1] * nx + bc[0]])
        max_cycles = max(4 * max(nx, ny), int(4.0 * goal_pot / K.COST_NEUTRAL) + 16)
        cells = K.calc_path(pot, nx, ny, bc[1] * nx + bc[0], max_cycles)
        if cells.shape[0] == 0:
            raise NoValidPath("failed to extract a path from the potential")
        cells = cells[::-1]
        xy = np.empty((cells.shape[0], 2))
        xy[:, 0] = costmap.origin_x + (cells[:, 0] + 0.5) * costmap.resolution
        xy[:, 1] = costmap.origin_y + (cells[:, 1] + 0.5) * costmap.resolution
        xy = _smooth_approach_to_goal(xy, best[:2])
        return _with_headings(xy, g[2], self.config.use_final_approach_orientation)

    def _legal_goal(
        self, goal: npt.NDArray[np.float64], pot: npt.NDArray[np.float32], cm: Costmap2D
    ) -> npt.NDArray[np.float64] | None:
        def potential(x: float, y: float) -> float:
            c = cm.world_to_map(x, y)
            if c is None:
                return K.POT_HIGH
            return float(pot[c[1] * cm.size_x + c[0]])

        if potential(goal[0], goal[1]) < K.POT_HIGH:
            return goal
        tol = self.config.tolerance
        res = cm.resolution
        best = None
        best_sd = math.inf
        y = goal[1] - tol
        while y <= goal[1] + tol:
            x = goal[0] - tol
            while x <= goal[0] + tol:
                sd = (x - goal[0]) ** 2 + (y - goal[1]) ** 2
                if sd < best_sd and potential(x, y) < K.POT_HIGH:
                    best_sd = sd
                    best = np.array([x, y, goal[2]])
                x += res
            y += res
        return best


def _smooth_approach_to_goal(xy: npt.NDArray[np.float64], goal: npt.NDArray[np.float64]
                             ) -> npt.NDArray[np.float64]:
    if xy.shape[0] >= 2:
        second, last = xy[-2], xy[-1]
        if np.sum((last - second) ** 2) > np.sum((goal - second) ** 2):
            out = xy.copy()
            out[-1] = goal
            return out
    return np.vstack([xy, goal[None, :]])


def _with_headings(xy: npt.NDArray[np.float64], goal_yaw: float, final_approach: bool
                   ) -> npt.NDArray[np.float64]:
    n = xy.shape[0]
    out = np.zeros((n, 3))
    out[:, :2] = xy
    if n > 1:
        d = np.diff(xy, axis=0)
        out[:-1, 2] = np.arctan2(d[:, 1], d[:, 0])
        out[-1, 2] = out[-2, 2] if final_approach else goal_yaw
    else:
        out[0, 2] = goal_yaw
    return out


__all__ = ["NavfnConfig", "NavfnPlanner"]
