"""Compiled loops of the MPPI controller: the sequential parts Nav2 writes as loops too
(acceleration-limited velocity propagation, per-trajectory costmap walks, the path-progress
search). Arrays are (batch, time_steps) float64; the costmap grid is (size_y, size_x) uint8."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from eddiebot.nav.costmap._kernels import polygon_outline_cost

_LETHAL = 254
_INSCRIBED = 253
_NO_INFORMATION = 255


@njit(cache=True)
def predict_velocities(cvx: np.ndarray, cwz: np.ndarray, vx: np.ndarray, wz: np.ndarray,
                       max_dvx: float, min_dvx: float, max_dwz: float) -> None:
    """``MotionModel::predict``: ``vx[:, 0]``/``wz[:, 0]`` hold the robot's speed; each next
    state velocity is the previous control clamped to what the accelerations reach in one
    ``model_dt`` (the controls are clamped in place, as upstream does)."""
    b, t = vx.shape
    for i in range(b):
        vx_last = vx[i, 0]
        wz_last = wz[i, 0]
        for j in range(1, t):
            c = cvx[i, j - 1]
            if vx_last > 0.0:
                lo, hi = vx_last + min_dvx, vx_last + max_dvx
            else:
                lo, hi = vx_last - max_dvx, vx_last - min_dvx
            c = min(max(c, lo), hi)
            cvx[i, j - 1] = c
            vx[i, j] = c
            vx_last = c
            w = min(max(cwz[i, j - 1], wz_last - max_dwz), wz_last + max_dwz)
            cwz[i, j - 1] = w
            wz[i, j] = w
            wz_last = w


@njit(cache=True)
def _footprint_cost(grid: np.ndarray, footprint: np.ndarray, x: float, y: float, yaw: float,
                    origin_x: float, origin_y: float, resolution: float) -> float:
    c, s = math.cos(yaw), math.sin(yaw)
    poly = np.empty_like(footprint)
    for k in range(footprint.shape[0]):
        poly[k, 0] = x + c * footprint[k, 0] - s * footprint[k, 1]
        poly[k, 1] = y + s * footprint[k, 0] + c * footprint[k, 1]
    cost = polygon_outline_cost(grid, poly, origin_x, origin_y, resolution)
    # FootprintCollisionChecker: a vertex off the map is a lethal footprint
    return float(_LETHAL) if cost < 0 else float(cost)


@njit(cache=True)
def _on_map(grid: np.ndarray, x: float, y: float, origin_x: float, origin_y: float,
            resolution: float) -> bool:
    if x < origin_x or y < origin_y:
        return False
    return int((x - origin_x) / resolution) < grid.shape[1] and \
        int((y - origin_y) / resolution) < grid.shape[0]


@njit(cache=True)
def _point_cost(grid: np.ndarray, x: float, y: float, origin_x: float, origin_y: float,
                resolution: float) -> float:
    """Cell cost at a world point, NO_INFORMATION off the map (``worldToMapFloat``)."""
    if x < origin_x or y < origin_y:
        return float(_NO_INFORMATION)
    mx = int((x - origin_x) / resolution)
    my = int((y - origin_y) / resolution)
    if mx < grid.shape[1] and my < grid.shape[0]:
        return float(grid[my, mx])
    return float(_NO_INFORMATION)


@njit(cache=True)
def _in_collision(cost: float, consider_footprint: bool, tracking_unknown: bool) -> bool:
    c = int(cost)
    if c == _LETHAL:
        return True
    if c == _INSCRIBED:
        return not consider_footprint
    if c == _NO_INFORMATION:
        return not tracking_unknown
    return False


@njit(cache=True)
def cost_critic(traj_x: np.ndarray, traj_y: np.ndarray, traj_yaw: np.ndarray, step: int,
                grid: np.ndarray, origin_x: float, origin_y: float, resolution: float,
                footprint: np.ndarray, consider_footprint: bool, possible_collision_cost: float,
                tracking_unknown: bool, near_collision_cost: float, critical_cost: float,
                collision_cost: float, near_goal: bool) -> tuple[np.ndarray, bool]:
    """``CostCritic::score``'s walk: per trajectory the summed costs of every ``step``-th point
    (``critical_cost`` at or above ``near_collision_cost``, the cell cost itself unless near the
    goal), ``collision_cost`` for a trajectory that collides; and whether all collide."""
    b, t = traj_x.shape
    traj_len = t // step
    out = np.zeros(b)
    all_collide = True
    for i in range(b):
        collide = False
        acc = 0.0
        for jj in range(traj_len):
            j = jj * step
            x, y = traj_x[i, j], traj_y[i, j]
            cost = _point_cost(grid, x, y, origin_x, origin_y, resolution)
            if cost < 1.0:
                continue
            score = cost
            if consider_footprint and (cost >= possible_collision_cost
                                       or possible_collision_cost < 1.0):
                score = _footprint_cost(grid, footprint, x, y, traj_yaw[i, j], origin_x,
                                        origin_y, resolution)
            if _in_collision(score, consider_footprint, tracking_unknown):
                acc = collision_cost
                collide = True
                break
            if cost >= near_collision_cost:
                acc += critical_cost
            elif not near_goal:
                acc += cost
        out[i] = acc
        if not collide:
            all_collide = False
    return out, all_collide


@njit(cache=True)
def obstacles_critic(traj_x: np.ndarray, traj_y: np.ndarray, traj_yaw: np.ndarray,
                     grid: np.ndarray, origin_x: float, origin_y: float, resolution: float,
                     footprint: np.ndarray, consider_footprint: bool,
                     possible_collision_cost: float, tracking_unknown: bool,
                     inflation_radius: float, scale_factor: float, inscribed_radius: float,
                     collision_margin_distance: float, collision_cost: float, near_goal: bool
                     ) -> tuple[np.ndarray, np.ndarray, bool]:
    """``ObstaclesCritic::score``'s walk: (raw cost, repulsive cost) per trajectory from the
    distance to obstacles the inflation decay implies, and whether all trajectories collide."""
    b, t = traj_x.shape
    raw = np.zeros(b)
    repulsive = np.zeros(b)
    all_collide = True
    for i in range(b):
        collide = False
        acc = 0.0
        for j in range(t):
            x, y = traj_x[i, j], traj_y[i, j]
            cost = _point_cost(grid, x, y, origin_x, origin_y, resolution)
            using_footprint = False
            if _on_map(grid, x, y, origin_x, origin_y, resolution) and consider_footprint and (
                    cost >= possible_collision_cost or possible_collision_cost < 1.0):
                cost = _footprint_cost(grid, footprint, x, y, traj_yaw[i, j], origin_x,
                                       origin_y, resolution)
                using_footprint = True
            if cost < 1.0:
                continue
            if _in_collision(cost, consider_footprint, tracking_unknown):
                collide = True
                break
            if inflation_radius == 0.0 or scale_factor == 0.0:
                continue
            dist = (scale_factor * inscribed_radius - math.log(cost) + math.log(253.0)) \
                / scale_factor
            if not using_footprint:
                dist -= inscribed_radius
            if dist < collision_margin_distance:
                acc += collision_margin_distance - dist
            if not near_goal:
                repulsive[i] += inflation_radius - dist
        if not collide:
            all_collide = False
        raw[i] = collision_cost if collide else acc
    return raw, repulsive, all_collide


@njit(cache=True)
def furthest_reached_path_point(last_x: np.ndarray, last_y: np.ndarray, path_x: np.ndarray,
                                path_y: np.ndarray) -> int:
    """``findPathFurthestReachedPoint``: over the trajectories' end points, the furthest path
    index any of them is closest to (each search starts at the furthest found so far)."""
    best = 0
    n = path_x.shape[0]
    for i in range(last_x.shape[0]):
        min_id = 0
        min_d = np.inf
        for j in range(best, n):
            dx = path_x[j] - last_x[i]
            dy = path_y[j] - last_y[i]
            d = dx * dx + dy * dy
            if d < min_d:
                min_d = d
                min_id = j
        best = max(best, min_id)
    return best


@njit(cache=True)
def _closest_path_pt(cum: np.ndarray, dist: float, init: int) -> int:
    """``utils::findClosestPathPt``: the index whose integrated distance is nearest ``dist``,
    searching forward from ``init``."""
    prev = cum[init] if init != 0 else 0.0
    size = cum.shape[0]
    for i in range(init + 1, size):
        cur = cum[i]
        if cur > dist:
            if i > 0 and dist - prev < cur - dist:
                return i - 1
            return i
        prev = cur
    return size - 1


@njit(cache=True)
def path_align(traj_x: np.ndarray, traj_y: np.ndarray, traj_yaw: np.ndarray, step: int,
               px: np.ndarray, py: np.ndarray, pyaw: np.ndarray, cum: np.ndarray,
               valid: np.ndarray, use_orientations: bool) -> np.ndarray:
    """``PathAlignCritic::score``'s walk: per trajectory, the mean distance of every
    ``step``-th point to the path point at the same integrated distance along the path."""
    b, t = traj_x.shape
    out = np.zeros(b)
    n_samp = (t + step - 1) // step
    for i in range(b):
        summed = 0.0
        num = 0
        dist = 0.0
        pt = 0
        x_m1, y_m1 = traj_x[i, 0], traj_y[i, 0]
        for p in range(1, n_samp):
            j = p * step
            x, y = traj_x[i, j], traj_y[i, j]
            dist += math.sqrt((x - x_m1) ** 2 + (y - y_m1) ** 2)
            x_m1, y_m1 = x, y
            pt = _closest_path_pt(cum, dist, pt)
            if valid[pt]:
                dx = px[pt] - x
                dy = py[pt] - y
                num += 1
                if use_orientations:
                    a = traj_yaw[i, j] - pyaw[pt]
                    dyaw = math.atan2(math.sin(a), math.cos(a))
                    summed += math.sqrt(dx * dx + dy * dy + dyaw * dyaw)
                else:
                    summed += math.sqrt(dx * dx + dy * dy)
        out[i] = summed / num if num > 0 else 0.0
    return out


__all__ = [
    "cost_critic",
    "furthest_reached_path_point",
    "obstacles_critic",
    "path_align",
    "predict_velocities",
]
