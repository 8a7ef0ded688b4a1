"""Theta* any-angle global planner (after ``nav2_theta_star_planner``).

A* over the 8-connected grid in which a node, when expanded, takes its grandparent as parent
if the straight line between them is traversable and cheaper, so paths are chains of
straight segments instead of grid zig-zags. Upstream's cost model: every cell entered costs
``w_euc_cost`` · step length + ``w_traversal_cost`` · ``(26 + 0.9·cost)² / 252²``; that
factor is 0.011 for free space, and unknown space (``allow_unknown``) costs about as much as
the most expensive known cell (1.03 per grid step, 1.008 on a line), so it is crossed only
when going round is dearer. Heuristic ``min(w_euc_cost, 1)`` · Euclidean distance (cells), as
upstream derives it (its documented ``w_heuristic_cost`` is accepted and, as upstream, not
read). The result is interpolated at the costmap resolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import (
    GoalOccupied,
    GoalOutsideMapBounds,
    NoValidPath,
    PlannerTimedOut,
    StartOccupied,
    StartOutsideMapBounds,
)
from eddiebot.nav.params import require
from eddiebot.nav.planners._heap import _grow, _pop, _push
from eddiebot.nav.types import as_pose


@dataclass(frozen=True)
class ThetaStarConfig:
    """``ThetaStarPlanner`` parameters (Jazzy code defaults)."""

    how_many_corners: int = 8
    w_euc_cost: float = 1.0
    w_traversal_cost: float = 2.0
    #: accepted because Nav2's README lists it; upstream's code does not read it either
    w_heuristic_cost: float = 1.0
    use_final_approach_orientation: bool = False
    allow_unknown: bool = True
    terminal_checking_interval: int = 5000

    def validate(self, server: str = "planner_server") -> None:
        require(self.how_many_corners in (4, 8), server, "how_many_corners",
                self.how_many_corners, "must be 4 or 8")
        require(self.w_euc_cost >= 0.0, server, "w_euc_cost", self.w_euc_cost, "must be >= 0")
        require(self.w_traversal_cost >= 0.0, server, "w_traversal_cost",
                self.w_traversal_cost, "must be >= 0")
        require(self.w_heuristic_cost >= 0.0, server, "w_heuristic_cost",
                self.w_heuristic_cost, "must be >= 0")


@njit(cache=True)
def _cell_ok(c: int, allow_unknown: bool) -> bool:
    """Upstream's ``isSafe(cx, cy)``: cost <= MAX_NON_OBSTACLE (252), or unknown if allowed."""
    return c <= 252 or (allow_unknown and c == 255)


@njit(cache=True)
def _cost_grids(grid: np.ndarray, allow_unknown: bool) -> tuple[np.ndarray, np.ndarray]:
    """Per-cell traversal factors ``(26 + 0.9·cost)² / 252²`` (upstream's ``getCost``):
    for grid steps (unknown at its raw 255, so ≈1.03 — dearer than any known cell) and for
    line-of-sight checks (unknown at 253, known cells above 251 blocked: the shifted cost must
    stay <= 252). -1 marks a cell that cannot be entered."""
    h, w = grid.shape
    step = np.empty((h, w))
    los = np.empty((h, w))
    for y in range(h):
        for x in range(w):
            c = grid[y, x]
            shifted = 26.0 + 0.9 * c
            step[y, x] = shifted * shifted / (252.0 * 252.0) if _cell_ok(c, allow_unknown) \
                else -1.0
            if c == 255 and allow_unknown:
                los[y, x] = 253.0 * 253.0 / (252.0 * 252.0)
            elif c != 255 and shifted <= 252.0:
                los[y, x] = shifted * shifted / (252.0 * 252.0)
            else:
                los[y, x] = -1.0
    return step, los


@njit(cache=True)
def _los_add(los: np.ndarray, x: int, y: int) -> float:
    h, w = los.shape
    if x < 0 or y < 0 or x >= w or y >= h:
        return -1.0
    return los[y, x]


@njit(cache=True)
def _line_of_sight(los: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> float:
    """Upstream's ``losCheck``: the summed factors of the cells it visits, -1 if blocked."""
    cost = 0.0
    dy = abs(y1 - y0)
    dx = abs(x1 - x0)
    f = 0
    sx = 1 if x1 > x0 else -1
    sy = 1 if y1 > y0 else -1
    ux = (sx - 1) // 2
    uy = (sy - 1) // 2
    cx = x0
    cy = y0
    if dx >= dy:
        while cx != x1:
            f += dy
            if f >= dx:
                v = _los_add(los, cx + ux, cy + uy)
                if v < 0.0:
                    return -1.0
                cost += v
                cy += sy
                f -= dx
            if f != 0:
                v = _los_add(los, cx + ux, cy + uy)
                if v < 0.0:
                    return -1.0
                cost += v
            if dy == 0:
                v = _los_add(los, cx + ux, cy)
                if v < 0.0:
                    v = _los_add(los, cx + ux, cy - 1)
                    if v < 0.0:
                        return -1.0
                cost += v
            cx += sx
    else:
        while cy != y1:
            f += dx
            if f >= dy:
                v = _los_add(los, cx + ux, cy + uy)
                if v < 0.0:
                    return -1.0
                cost += v
                cx += sx
                f -= dy
            if f != 0:
                v = _los_add(los, cx + ux, cy + uy)
                if v < 0.0:
                    return -1.0
                cost += v
            if dx == 0:
                v = _los_add(los, cx, cy + uy)
                if v < 0.0:
                    v = _los_add(los, cx - 1, cy + uy)
                    if v < 0.0:
                        return -1.0
                cost += v
            cy += sy
    return cost


_MOVES_X = np.array([0, 0, 1, -1, 1, -1, 1, -1])
_MOVES_Y = np.array([1, -1, 0, 0, -1, 1, 1, -1])


@njit(cache=True)
def theta_star_search(
    grid: np.ndarray, sx: int, sy: int, gx: int, gy: int, w_euc: float, w_trav: float,
    w_heur: float, corners: int, allow_unknown: bool, max_expansions: int,
) -> np.ndarray:
    """Cells (K, 2) of the path start -> goal; (0, 2) if none; [[-1, -1]] on timeout.

    ``ThetaStar::generatePath``: a node is expanded in order of ``f = g + h``; on expansion it
    takes its grandparent as parent when the line between them is free and cheaper
    (``resetParent``), then offers each neighbour ``g + w_euc_cost·step + w_traversal_cost·
    factor(neighbour)`` (``setNeighbors``). A line costs ``w_euc_cost·length +
    w_traversal_cost·Σ factor`` over the cells ``losCheck`` visits. Nodes improved after
    expansion are expanded again, as upstream's queue allows.
    """
    h, w = grid.shape
    ns = h * w
    step, los = _cost_grids(grid, allow_unknown)
    g = np.full(ns, np.inf)
    f = np.full(ns, np.inf)
    parent = np.full(ns, -1, dtype=np.int64)
    cap = 4 * ns + 16
    hk = np.empty(cap)
    hv = np.empty(cap, dtype=np.int64)
    size = 0
    s = sy * w + sx
    goal = gy * w + gx
    g[s] = w_trav * step[sy, sx]
    f[s] = g[s] + w_heur * math.hypot(gx - sx, gy - sy)
    parent[s] = s
    size = _push(hk, hv, size, f[s], s)
    expansions = 0
    found = False
    while size > 0:
        key, n, size = _pop(hk, hv, size)
        if key > f[n]:
            continue  # superseded by a cheaper entry
        if n == goal:
            found = True
            break
        expansions += 1
        if expansions > max_expansions:
            return np.full((1, 2), -1, dtype=np.int64)
        nx_ = n % w
        ny_ = n // w
        gp = parent[parent[n]]
        gpx = gp % w
        gpy = gp // w
        lc = _line_of_sight(los, nx_, ny_, gpx, gpy)
        if lc >= 0.0:
            cand = g[gp] + w_euc * math.hypot(nx_ - gpx, ny_ - gpy) + w_trav * lc
            if cand < g[n]:
                parent[n] = gp
                f[n] = cand + (f[n] - g[n])
                g[n] = cand
        for k in range(corners):
            mx = nx_ + _MOVES_X[k]
            my = ny_ + _MOVES_Y[k]
            if mx < 0 or my < 0 or mx >= w or my >= h or step[my, mx] < 0.0:
                continue
            m = my * w + mx
            gc = g[n] + w_euc * math.hypot(_MOVES_X[k], _MOVES_Y[k]) + w_trav * step[my, mx]
            cal = gc + w_heur * math.hypot(mx - gx, my - gy)
            if f[m] > cal:
                g[m] = gc
                f[m] = cal
                parent[m] = n
                hk, hv = _grow(hk, hv, size)
                size = _push(hk, hv, size, cal, m)
    if not found:
        return np.zeros((0, 2), dtype=np.int64)
    count = 1
    c = goal
    while c != s:
        c = parent[c]
        count += 1
    out = np.empty((count, 2), dtype=np.int64)
    c = goal
    for i in range(count - 1, -1, -1):
        out[i, 0] = c % w
        out[i, 1] = c // w
        c = parent[c]
    return out


class ThetaStarPlanner:
    """Theta* planner plugin (``nav2_theta_star_planner::ThetaStarPlanner``)."""

    def __init__(self, config: ThetaStarConfig | None = None, name: str = "ThetaStar",
                 max_expansions: int | None = None) -> None:
        self.config = config or ThetaStarConfig()
        self.name = name
        self.max_expansions = max_expansions

    def create_plan(
        self, start: npt.ArrayLike, goal: npt.ArrayLike, costmap: Costmap2D
    ) -> npt.NDArray[np.float64]:
        s = as_pose(start)
        g = as_pose(goal)
        cs = costmap.world_to_map(s[0], s[1])
        if cs is None:
            raise StartOutsideMapBounds(f"start ({s[0]:.2f}, {s[1]:.2f}) is outside the costmap")
        cg = costmap.world_to_map(g[0], g[1])
        if cg is None:
            raise GoalOutsideMapBounds(f"goal ({g[0]:.2f}, {g[1]:.2f}) is outside the costmap")
        au = self.config.allow_unknown
        if not _cell_ok(costmap.get_cost(*cs), au):
            raise StartOccupied(f"start ({s[0]:.2f}, {s[1]:.2f}) is occupied")
        if not _cell_ok(costmap.get_cost(*cg), au):
            raise GoalOccupied(f"goal ({g[0]:.2f}, {g[1]:.2f}) is occupied")
        if cs == cg:
            return np.array([[g[0], g[1], g[2]]])
        limit = self.max_expansions or costmap.size_x * costmap.size_y + 1
        cells = theta_star_search(
            costmap.data, cs[0], cs[1], cg[0], cg[1], self.config.w_euc_cost,
            self.config.w_traversal_cost, min(self.config.w_euc_cost, 1.0),
            self.config.how_many_corners, au, limit,
        )
        if cells.shape[0] == 1 and cells[0, 0] < 0:
            raise PlannerTimedOut("Theta* exceeded its expansion budget")
        if cells.shape[0] == 0:
            raise NoValidPath("Theta* found no path")
        res = costmap.resolution
        corners = np.empty((cells.shape[0], 2))
        corners[:, 0] = costmap.origin_x + (cells[:, 0] + 0.5) * res
        corners[:, 1] = costmap.origin_y + (cells[:, 1] + 0.5) * res
        corners[0] = s[:2]
        corners[-1] = g[:2]
        pts = [corners[0]]
        for a, b in zip(corners[:-1], corners[1:]):
            n = max(1, math.ceil(float(np.hypot(*(b - a))) / res))
            t = np.arange(1, n + 1)[:, None] / n
            pts.extend(a + t * (b - a))
        xy = np.asarray(pts)
        out = np.zeros((xy.shape[0], 3))
        out[:, :2] = xy
        d = np.diff(xy, axis=0)
        out[:-1, 2] = np.arctan2(d[:, 1], d[:, 0])
        out[-1, 2] = out[-2, 2] if self.config.use_final_approach_orientation else g[2]
        return out


__all__ = ["ThetaStarConfig", "ThetaStarPlanner", "theta_star_search"]
