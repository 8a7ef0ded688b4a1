"""DWB trajectory critics (``dwb_critics``), as array kernels over a batch of rollouts.

Each critic returns ``(score, legal)`` per trajectory; the planner sums ``scale · score`` over
the critics and drops trajectories any critic declared illegal (upstream's
``IllegalTrajectoryException``). Trajectories are ``(S, T, 3)`` arrays of poses in the
costmap's frame (m, rad); the grid is the costmap's master array indexed ``[y, x]``.

The map-grid critics (PathDist, GoalDist, PathAlign, GoalAlign) follow ``MapGridCritic``:
the (resolution-adjusted) plan cells that lie on the costmap and are not unknown seed a
wavefront (``costmap_queue::CostmapQueue`` with Manhattan priorities, LIFO within a
priority), and every cell scores the Manhattan distance in cells to the seed whose wave
reached it first. As in Jazzy (since ros-navigation/navigation2#719) the wave is not stopped
by lethal, inscribed or unknown cells, so a cell behind a wall scores its grid distance to
the plan, never the Euclidean one; only poses off the grid are illegal.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.nav.costmap._kernels import line_cost

NO_INFORMATION = 255
LETHAL_OBSTACLE = 254
INSCRIBED_INFLATED_OBSTACLE = 253

AGGREGATION_TYPES = ("last", "sum", "product")

Scored = tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]


# --- MapGridCritic -----------------------------------------------------------------------------
@njit(cache=True)
def _enqueue(cell: int, x: int, y: int, sx: int, sy: int, seen: np.ndarray, src_x: np.ndarray,
             src_y: np.ndarray, head: np.ndarray, nxt: np.ndarray, cur: int) -> int:
    """``CostmapQueue::enqueueCell`` (every cell valid): push on the bin of its Manhattan
    distance to ``(sx, sy)``; returns the lowest bin that may be non-empty."""
    if seen[cell]:
        return cur
    d = abs(x - sx) + abs(y - sy)
    seen[cell] = True
    src_x[cell] = sx
    src_y[cell] = sy
    nxt[cell] = head[d]
    head[d] = cell
    return min(cur, d)


@njit(cache=True)
def map_grid_wavefront(size_x: int, size_y: int, seeds: np.ndarray) -> np.ndarray:
    """``MapGridCritic`` cell values: ``(size_y, size_x)`` Manhattan distances (cells) from the
    seed cells ``seeds[:, (x, y)]`` (enqueued in order), ``size_x·size_y + 1`` where unreached."""
    n = size_x * size_y
    unreachable = float(n) + 1.0
    vals = np.full(n, unreachable)
    seen = np.zeros(n, dtype=np.bool_)
    src_x = np.zeros(n, dtype=np.int64)
    src_y = np.zeros(n, dtype=np.int64)
    nbins = size_x + size_y + 1
    head = np.full(nbins, -1, dtype=np.int64)
    nxt = np.full(n, -1, dtype=np.int64)
    cur = nbins
    for k in range(seeds.shape[0]):
        x = seeds[k, 0]
        y = seeds[k, 1]
        cell = y * size_x + x
        vals[cell] = 0.0
        cur = _enqueue(cell, x, y, x, y, seen, src_x, src_y, head, nxt, cur)
    while True:
        while cur < nbins and head[cur] < 0:
            cur += 1
        if cur >= nbins:
            break
        cell = head[cur]
        head[cur] = nxt[cell]
        x = cell % size_x
        y = cell // size_x
        sx = src_x[cell]
        sy = src_y[cell]
        vals[cell] = abs(sx - x) + abs(sy - y)
        if x > 0:
            cur = _enqueue(cell - 1, x - 1, y, sx, sy, seen, src_x, src_y, head, nxt, cur)
        if y > 0:
            cur = _enqueue(cell - size_x, x, y - 1, sx, sy, seen, src_x, src_y, head, nxt, cur)
        if x < size_x - 1:
            cur = _enqueue(cell + 1, x + 1, y, sx, sy, seen, src_x, src_y, head, nxt, cur)
        if y < size_y - 1:
            cur = _enqueue(cell + size_x, x, y + 1, sx, sy, seen, src_x, src_y, head, nxt, cur)
    return vals.reshape(size_y, size_x)


def adjust_plan_resolution(plan: npt.NDArray[np.float64], resolution: float
                           ) -> npt.NDArray[np.float64]:
    """``nav_2d_utils::adjustPlanResolution``: fill gaps over two cells with points (its exact
    step count, which leaves gaps of up to about two cells)."""
    if plan.shape[0] < 2:
        return plan
    a, b = plan[:-1], plan[1:]
    seg = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])
    steps = np.where(seg > 2.0 * resolution,
                     ((seg - 2.0 * resolution) / resolution).astype(np.int64) - 1, 0)
    extra = np.maximum(steps - 1, 0)  # points j = 1 .. steps-1 between a and b
    if not extra.any():
        return plan
    seg_idx = np.repeat(np.arange(a.shape[0]), extra)
    j = np.arange(seg_idx.size) - np.repeat(np.cumsum(extra) - extra, extra) + 1
    frac = j / steps[seg_idx]
    out = np.zeros((plan.shape[0] + seg_idx.size, plan.shape[1]))
    ends = np.arange(1, plan.shape[0]) + np.cumsum(extra)  # where plan[1:] land in out
    out[0] = plan[0]
    out[ends] = plan[1:]
    fill = np.ones(out.shape[0], dtype=bool)
    fill[0] = False
    fill[ends] = False
    out[fill, 0] = a[seg_idx, 0] + frac * (b[seg_idx, 0] - a[seg_idx, 0])
    out[fill, 1] = a[seg_idx, 1] + frac * (b[seg_idx, 1] - a[seg_idx, 1])
    return out


def _plan_cells_on_costmap(plan: npt.NDArray[np.float64], grid: npt.NDArray[np.uint8],
                           origin: tuple[float, float], resolution: float
                           ) -> npt.NDArray[np.int64]:
    """The leading run of plan cells on the costmap and not unknown (``PathDistCritic``):
    points before the run are skipped, the first point after it ends it."""
    h, w = grid.shape
    mx = np.floor((plan[:, 0] - origin[0]) / resolution).astype(np.int64)
    my = np.floor((plan[:, 1] - origin[1]) / resolution).astype(np.int64)
    on = (mx >= 0) & (my >= 0) & (mx < w) & (my < h)
    on[on] = grid[my[on], mx[on]] != NO_INFORMATION
    idx = np.nonzero(on)[0]
    if idx.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    first = idx[0]
    off_after = np.nonzero(~on[first:])[0]
    last = first + off_after[0] if off_after.size else on.size
    return np.stack([mx[first:last], my[first:last]], axis=1)


def path_dist_values(plan: npt.NDArray[np.float64], grid: npt.NDArray[np.uint8],
                     origin: tuple[float, float], resolution: float
                     ) -> npt.NDArray[np.float64] | None:
    """``PathDistCritic::prepare``: cell values seeded by every plan cell; None when no plan
    point is on the costmap and known (upstream's prepare failure)."""
    seeds = _plan_cells_on_costmap(adjust_plan_resolution(plan, resolution), grid, origin,
                                   resolution)
    if seeds.shape[0] == 0:
        return None
    return map_grid_wavefront(grid.shape[1], grid.shape[0], seeds)


def goal_dist_values(plan: npt.NDArray[np.float64], grid: npt.NDArray[np.uint8],
                     origin: tuple[float, float], resolution: float
                     ) -> npt.NDArray[np.float64] | None:
    """``GoalDistCritic::prepare``: seeded by the last plan cell of that run only."""
    seeds = _plan_cells_on_costmap(adjust_plan_resolution(plan, resolution), grid, origin,
                                   resolution)
    if seeds.shape[0] == 0:
        return None
    return map_grid_wavefront(grid.shape[1], grid.shape[0], seeds[-1:])


@njit(cache=True)
def _score_map_grid(xy: np.ndarray, vals: np.ndarray, ox: float, oy: float, res: float,
                    mode: int, stop_on_failure: bool) -> tuple[np.ndarray, np.ndarray]:
    n, steps, _ = xy.shape
    h, w = vals.shape
    obstacle = float(h * w)
    score = np.zeros(n)
    ok = np.ones(n, dtype=np.bool_)
    start = steps - 1 if (mode == 0 and not stop_on_failure) else 0
    for i in range(n):
        s = 1.0 if mode == 2 else 0.0
        for k in range(start, steps):
            mx = math.floor((xy[i, k, 0] - ox) / res)
            my = math.floor((xy[i, k, 1] - oy) / res)
            if mx < 0 or my < 0 or mx >= w or my >= h:
                ok[i] = False
                break
            g = vals[my, mx]
            if stop_on_failure and g >= obstacle:  # obstacle or unreachable score
                ok[i] = False
                break
            if mode == 0:
                s = g
            elif mode == 1:
                s += g
            elif s > 0.0:
                s *= g
        score[i] = s
    return score, ok


def score_map_grid(traj: npt.NDArray[np.float64], vals: npt.NDArray[np.float64],
                   origin: tuple[float, float], resolution: float, aggregation_type: str,
                   stop_on_failure: bool, forward_point_distance: float = 0.0) -> Scored:
    """``MapGridCritic::scoreTrajectory`` over the poses (moved ``forward_point_distance``
    ahead along their heading for the Align critics). ``last`` scores the final pose (every
    pose is still checked when ``stop_on_failure``), ``sum`` adds, ``product`` multiplies the
    scores while the running product is positive."""
    if aggregation_type.lower() == "last" and not stop_on_failure:
        traj = traj[:, -1:]  # only the final pose is scored
    th = traj[..., 2]
    xy = np.stack([traj[..., 0] + forward_point_distance * np.cos(th),
                   traj[..., 1] + forward_point_distance * np.sin(th)], axis=-1)
    mode = AGGREGATION_TYPES.index(aggregation_type.lower())
    return _score_map_grid(np.ascontiguousarray(xy), vals, origin[0], origin[1], resolution,
                           mode, stop_on_failure)


# --- obstacle critics --------------------------------------------------------------------------
@njit(cache=True)
def score_base_obstacle(traj: np.ndarray, grid: np.ndarray, ox: float, oy: float, res: float,
                        sum_scores: bool) -> tuple[np.ndarray, np.ndarray]:
    """``BaseObstacleCritic``: cost of the last pose (or the sum over poses); lethal,
    inscribed and unknown cells and poses off the grid make the trajectory illegal."""
    n, steps, _ = traj.shape
    h, w = grid.shape
    score = np.zeros(n)
    ok = np.ones(n, dtype=np.bool_)
    for i in range(n):
        s = 0.0
        for k in range(steps):
            mx = math.floor((traj[i, k, 0] - ox) / res)
            my = math.floor((traj[i, k, 1] - oy) / res)
            if mx < 0 or my < 0 or mx >= w or my >= h:
                ok[i] = False
                break
            c = grid[my, mx]
            if c >= INSCRIBED_INFLATED_OBSTACLE:  # inscribed, lethal or unknown
                ok[i] = False
                break
            s = (s if sum_scores else 0.0) + c
        score[i] = s
    return score, ok


@njit(cache=True)
def score_obstacle_footprint(traj: np.ndarray, footprint: np.ndarray, grid: np.ndarray,
                             ox: float, oy: float, res: float, sum_scores: bool
                             ) -> tuple[np.ndarray, np.ndarray]:
    """``ObstacleFootprintCritic``: per pose the highest cost on the footprint's outline
    (Bresenham lines between the oriented vertices), aggregated as BaseObstacle; a lethal or
    unknown outline cell, or a pose or vertex off the grid, makes the trajectory illegal."""
    n, steps, _ = traj.shape
    h, w = grid.shape
    m = footprint.shape[0]
    score = np.zeros(n)
    ok = np.ones(n, dtype=np.bool_)
    vx = np.empty(m, dtype=np.int64)
    vy = np.empty(m, dtype=np.int64)
    for i in range(n):
        s = 0.0
        for k in range(steps):
            px = traj[i, k, 0]
            py = traj[i, k, 1]
            if (math.floor((px - ox) / res) < 0 or math.floor((py - oy) / res) < 0
                    or math.floor((px - ox) / res) >= w or math.floor((py - oy) / res) >= h):
                ok[i] = False
                break
            c = math.cos(traj[i, k, 2])
            sn = math.sin(traj[i, k, 2])
            for j in range(m):
                fx = px + footprint[j, 0] * c - footprint[j, 1] * sn
                fy = py + footprint[j, 0] * sn + footprint[j, 1] * c
                vx[j] = math.floor((fx - ox) / res)
                vy[j] = math.floor((fy - oy) / res)
                if vx[j] < 0 or vy[j] < 0 or vx[j] >= w or vy[j] >= h:
                    ok[i] = False
            if not ok[i]:
                break
            cost = 0
            for j in range(m):
                jn = (j + 1) % m
                lc = line_cost(grid, vx[j], vy[j], vx[jn], vy[jn])
                if lc > cost:
                    cost = lc
            if cost >= LETHAL_OBSTACLE:  # lethal or unknown
                ok[i] = False
                break
            s = (s if sum_scores else 0.0) + cost
        score[i] = s
    return score, ok


# --- velocity critics --------------------------------------------------------------------------
def score_prefer_forward(vx: npt.NDArray[np.float64], wz: npt.NDArray[np.float64],
                         penalty: float, strafe_x: float, strafe_theta: float,
                         theta_scale: float) -> Scored:
    """``PreferForwardCritic``: ``penalty`` for reversing or for creeping (``vx < strafe_x``)
    without turning (``|wz| < strafe_theta``), else ``|wz| · theta_scale``."""
    creep = (vx < strafe_x) & (np.abs(wz) < strafe_theta)
    sc = np.where((vx < 0.0) | creep, penalty, np.abs(wz) * theta_scale)
    return sc.astype(np.float64), np.ones(vx.shape[0], dtype=bool)


def score_twirling(wz: npt.NDArray[np.float64]) -> Scored:
    """``TwirlingCritic``: ``|wz|``, a cost for spinning."""
    return np.abs(wz).astype(np.float64), np.ones(wz.shape[0], dtype=bool)


__all__ = [
    "AGGREGATION_TYPES", "adjust_plan_resolution", "goal_dist_values", "map_grid_wavefront",
    "path_dist_values", "score_base_obstacle", "score_map_grid", "score_obstacle_footprint",
    "score_prefer_forward", "score_twirling",
]
