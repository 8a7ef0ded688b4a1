"""Theta* any-angle global planner (after ``nav2_theta_star_planner``).

A* over the 8-connected grid in which a node may take its grandparent as parent when the
straight line between them is traversable, so paths are chains of straight segments
instead of grid zig-zags (the lazy variant: one line check per expansion). Edge cost = ``w_euc_cost`` · length + ``w_traversal_cost`` ·
∫ (cost/252)² along the line (cells), heuristic ``w_heuristic_cost`` · Euclidean distance.
The result is interpolated at the costmap resolution.
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
from eddiebot.nav.types import as_pose


@dataclass(frozen=True)
class ThetaStarConfig:
    """``ThetaStarPlanner`` parameters (Jazzy code defaults)."""

    how_many_corners: int = 8
    w_euc_cost: float = 1.0
    w_traversal_cost: float = 2.0
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
    return c < 253 or (allow_unknown and c == 255)


@njit(cache=True)
def _trav_grid(grid: np.ndarray, allow_unknown: bool) -> np.ndarray:
    """Per-cell (cost/252)² (unknown: 0), or -1 where the cell cannot be crossed."""
    h, w = grid.shape
    out = np.empty((h, w), dtype=np.float32)
    for y in range(h):
        for x in range(w):
            c = grid[y, x]
            if not _cell_ok(c, allow_unknown):
                out[y, x] = -1.0
            elif c == 255:
                out[y, x] = 0.0
            else:
                v = c / 252.0
                out[y, x] = v * v
    return out


@njit(cache=True)
def _line_cost(trav: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> float:
    """Integral of (cost/252)² along the line (cells), or -1 when a cell is not traversable."""
    dx = abs(x1 - x0)
    dy = abs(y1 - y0)
    sx = 1 if x1 > x0 else -1
    sy = 1 if y1 > y0 else -1
    n = max(dx, dy)
    if n == 0:
        return 0.0
    total = np.float32(0.0)
    err = dx - dy
    x = x0
    y = y0
    for _ in range(n):
        e2 = 2 * err
        if e2 > -dy:
            err -= dy
            x += sx
        if e2 < dx:
            err += dx
            y += sy
        c = trav[y, x]
        if c < 0.0:
            return -1.0
        total += c
    return float(total) * math.hypot(dx, dy) / n


@njit(cache=True)
def _heap_push(hk: np.ndarray, hv: np.ndarray, size: int, key: float, val: int) -> int:
    i = size
    hk[i] = key
    hv[i] = val
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] <= hk[i]:
            break
        hk[p], hk[i] = hk[i], hk[p]
        hv[p], hv[i] = hv[i], hv[p]
        i = p
    return size + 1


@njit(cache=True)
def _heap_pop(hk: np.ndarray, hv: np.ndarray, size: int) -> tuple[int, int]:
    top = hv[0]
    size -= 1
    hk[0] = hk[size]
    hv[0] = hv[size]
    i = 0
    while True:
        left = 2 * i + 1
        r = left + 1
        m = i
        if left < size and hk[left] < hk[m]:
            m = left
        if r < size and hk[r] < hk[m]:
            m = r
        if m == i:
            break
        hk[m], hk[i] = hk[i], hk[m]
        hv[m], hv[i] = hv[i], hv[m]
        i = m
    return top, size


@njit(cache=True)
def _step_cost(trav: np.ndarray, x: int, y: int, dist: float, w_euc: float, w_trav: float) -> float:
    return w_euc * dist + w_trav * trav[y, x] * dist


@njit(cache=True)
def theta_star_search(
    grid: np.ndarray, sx: int, sy: int, gx: int, gy: int, w_euc: float, w_trav: float,
    w_heur: float, corners: int, allow_unknown: bool, max_expansions: int,
) -> np.ndarray:
    """Cells (K, 2) of the path start -> goal; (0, 2) if none; [[-1, -1]] on timeout.

    Lazy Theta*: a generated node optimistically takes its grandparent as parent (cost
    estimated from the end cell); the line is checked once, when the node is expanded,
    and on failure the node falls back to its best expanded grid neighbour.
    """
    h, w = grid.shape
    ns = h * w
    trav = _trav_grid(grid, allow_unknown)
    g = np.full(ns, np.inf)
    parent = np.full(ns, -1, dtype=np.int64)
    closed = np.zeros(ns, dtype=np.bool_)
    cap = ns * 8 + 16
    hk = np.empty(cap)
    hv = np.empty(cap, dtype=np.int64)
    size = 0
    s = sy * w + sx
    goal = gy * w + gx
    g[s] = 0.0
    parent[s] = s
    size = _heap_push(hk, hv, size, w_heur * math.hypot(gx - sx, gy - sy), s)
    ddx = np.array([1, -1, 0, 0, 1, 1, -1, -1])
    ddy = np.array([0, 0, 1, -1, 1, -1, 1, -1])
    expansions = 0
    found = False
    # Break f ties toward the goal (deeper nodes first); 0.1 % keeps paths near-optimal.
    tie = w_heur * 1.001
    while size > 0:
        n, size = _heap_pop(hk, hv, size)
        if closed[n]:
            continue
        closed[n] = True
        nx_ = n % w
        ny_ = n // w
        p = parent[n]
        if p != n:
            px = p % w
            py = p // w
            lc = _line_cost(trav, px, py, nx_, ny_)
            if lc >= 0.0:
                g[n] = g[p] + w_euc * math.hypot(nx_ - px, ny_ - py) + w_trav * lc
            else:
                best = np.inf
                bp = -1
                for k in range(corners):
                    qx = nx_ + ddx[k]
                    qy = ny_ + ddy[k]
                    if qx < 0 or qy < 0 or qx >= w or qy >= h:
                        continue
                    q = qy * w + qx
                    if not closed[q] or q == n:
                        continue
                    c = g[q] + _step_cost(trav, nx_, ny_, math.hypot(ddx[k], ddy[k]), w_euc, w_trav)
                    if c < best:
                        best = c
                        bp = q
                if bp < 0:
                    continue
                g[n] = best
                parent[n] = bp
        if n == goal:
            found = True
            break
        expansions += 1
        if expansions > max_expansions:
            return np.full((1, 2), -1, dtype=np.int64)
        p = parent[n]
        px = p % w
        py = p // w
        for k in range(corners):
            mx = nx_ + ddx[k]
            my = ny_ + ddy[k]
            if mx < 0 or my < 0 or mx >= w or my >= h:
                continue
            m = my * w + mx
            if closed[m] or trav[my, mx] < 0.0:
                continue
            if p != n:
                cand = g[p] + _step_cost(trav, mx, my, math.hypot(mx - px, my - py), w_euc, w_trav)
                cpar = p
            else:
                cand = g[n] + _step_cost(trav, mx, my, math.hypot(ddx[k], ddy[k]), w_euc, w_trav)
                cpar = n
            if cand < g[m]:
                g[m] = cand
                parent[m] = cpar
                size = _heap_push(hk, hv, size, cand + tie * math.hypot(gx - mx, gy - my), m)
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
            self.config.w_traversal_cost, self.config.w_heuristic_cost,
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
