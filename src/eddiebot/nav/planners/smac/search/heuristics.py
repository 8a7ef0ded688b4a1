"""The heuristics of ``SmacPlannerHybrid`` (numba): the obstacle heuristic (a 2D cost-aware
Dijkstra from the goal) and the combined estimate, the larger of it and the
Dubins/Reeds-Shepp distance."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from eddiebot.nav.planners._heap import _grow, _pop, _push
from eddiebot.nav.planners.smac.curves import curve_path
from eddiebot.nav.planners.smac.search.common import INSCRIBED


@njit(cache=True)
def obstacle_heuristic(grid: np.ndarray, goal_x: float, goal_y: float, cost_penalty: float,
                       downsample: bool, quadratic: bool) -> np.ndarray:
    """``NodeHybrid::getObstacleHeuristic``'s wavefront, run to completion: cost-aware 2D
    Dijkstra from the goal (on the 2x-downsampled grid, each coarse cell the cheapest of its
    block, when ``downsample``). Cells at INSCRIBED or above, unknown included, are walls;
    cells within 3 of the border are not entered, as upstream. Values are in full-grid cells
    (doubled when downsampled); ``inf`` where the wavefront does not reach."""
    h, w = grid.shape
    if downsample:
        sh = (h + 1) // 2
        sw = (w + 1) // 2
        cg = np.full((sh, sw), 255, dtype=np.uint8)
        for y in range(h):
            for x in range(w):
                c = grid[y, x]
                if c < cg[y // 2, x // 2]:
                    cg[y // 2, x // 2] = c
        gx = math.floor(goal_x / 2.0)
        gy = math.floor(goal_y / 2.0)
    else:
        sh = h
        sw = w
        cg = grid
        gx = math.floor(goal_x)
        gy = math.floor(goal_y)
    n = sh * sw
    dist = np.full(n, np.inf)
    done = np.zeros(n, dtype=np.bool_)
    hk = np.empty(1024)
    hv = np.empty(1024, dtype=np.int64)
    size = 0
    s = gy * sw + gx
    dist[s] = 0.0
    if size == hk.shape[0]:
        hk, hv = _grow(hk, hv, size)
    size = _push(hk, hv, size, 0.0, s)
    sqrt2 = math.sqrt(2.0)
    while size > 0:
        _, cur, size = _pop(hk, hv, size)
        if done[cur]:
            continue
        done[cur] = True
        cx = cur % sw
        cy = cur // sw
        for k in range(8):
            dx = (1, -1, 0, 0, 1, -1, 1, -1)[k]
            dy = (0, 0, 1, -1, 1, 1, -1, -1)[k]
            mx = cx + dx
            my = cy + dy
            if mx <= 3 or my <= 3 or mx >= sw - 3 or my >= sh - 3:
                continue
            m = my * sw + mx
            if done[m]:
                continue
            c = cg[my, mx]
            if c >= INSCRIBED:
                continue
            step = 1.0 if k < 4 else sqrt2
            if quadratic:
                nc = dist[cur] + step * (1.0 + cost_penalty * c * c / 63504.0)
            else:
                nc = dist[cur] + step * (1.0 + cost_penalty * c / 252.0)
            if nc < dist[m]:
                dist[m] = nc
                if size == hk.shape[0]:
                    hk, hv = _grow(hk, hv, size)
                size = _push(hk, hv, size, nc, m)
    out = dist.reshape(sh, sw)
    if downsample:
        out = out * 2.0
    return out


@njit(cache=True)
def _heuristic(x: float, y: float, th_bin: float, gx: float, gy: float, gbin: int,
               h_obs: np.ndarray, downsample: bool, bins: int, rho: float, rs: bool,
               lookup_dim: float) -> float:
    """``NodeHybrid::getHeuristicCost``: max(obstacle heuristic, motion heuristic). The
    motion heuristic is the Dubins/Reeds-Shepp length from the node, expressed in the goal's
    frame and rounded to whole cells and bins, when it lies inside the ``lookup_table_size``
    window (upstream reads the same value from its precomputed table); outside it, it counts
    only when the obstacle heuristic has no value there."""
    if downsample:
        hx = math.floor(x / 2.0)
        hy = math.floor(y / 2.0)
    else:
        hx = math.floor(x)
        hy = math.floor(y)
    ho = 0.0
    if 0 <= hy < h_obs.shape[0] and 0 <= hx < h_obs.shape[1]:
        v = h_obs[hy, hx]
        if v < np.inf:
            ho = v
    bin_size = 2.0 * math.pi / bins
    gth = gbin * bin_size
    c = math.cos(gth)
    s = -math.sin(gth)
    dx = x - gx
    dy = y - gy
    rx = round(dx * c - dy * s)
    ry = round(dx * s + dy * c)
    dth = th_bin - gbin
    if dth < 0:
        dth += bins
    rth = round(dth)
    floored = math.floor(lookup_dim / 2.0)
    hm = 0.0
    if abs(rx) < floored and abs(ry) < floored:
        hm = curve_path(rx, ry, rth * bin_size, 0.0, 0.0, 0.0, rho, rs)[2]
    elif ho <= 0.0:
        hm = curve_path(x, y, th_bin * bin_size, gx, gy, gth, rho, rs)[2]
    return max(ho, hm)


__all__ = ["_heuristic", "obstacle_heuristic"]
