"""``SmacPlanner2D``'s search (numba): 8-connected A* over the costmap, and the
``CostmapDownsampler`` that coarsens the grid before it."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from eddiebot.nav.planners._heap import _grow, _pop, _push
from eddiebot.nav.planners.smac.search.common import (
    FOUND,
    INSCRIBED,
    MAX_ITERATIONS,
    NO_PATH,
    TIMED_OUT,
    UNKNOWN,
    _now,
)


@njit(cache=True)
def astar_2d(grid: np.ndarray, sx: int, sy: int, gx: float, gy: float, cost_penalty: float,
             allow_unknown: bool, tolerance: float, max_iterations: int,
             max_on_approach_iterations: int, terminal_checking_interval: int,
             max_planning_time: float) -> tuple[int, np.ndarray, int]:
    """``AStarAlgorithm<Node2D>::createPath``: (status, cells (K, 2) start -> end, expansions).

    Travel cost ``(1 or √2)·(1 + cost_penalty·cost/252)`` (``Node2D::getTraversalCost``),
    heuristic the Euclidean distance to the goal's continuous cell coordinates; the node of
    least heuristic seen is returned when it lies within ``tolerance`` (cells) after
    ``max_on_approach_iterations`` further expansions or when the queue runs dry.
    """
    t0 = _now()
    h, w = grid.shape
    n = h * w
    # per-cell travel factor 1 + cost_penalty·cost/252; -1 where the cell cannot be entered
    fac = np.empty(n)
    flat = grid.ravel()
    for i in range(n):
        c = flat[i]
        fac[i] = 1.0 + cost_penalty * c / 252.0 if (c < INSCRIBED or (c == UNKNOWN and
                                                                   allow_unknown)) else -1.0
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    visited = np.zeros(n, dtype=np.bool_)
    hk = np.empty(1024)
    hv = np.empty(1024, dtype=np.int64)
    size = 0
    start = sy * w + sx
    goal = int(gy) * w + int(gx)
    g[start] = 0.0
    if size == hk.shape[0]:
        hk, hv = _grow(hk, hv, size)
    size = _push(hk, hv, size, 0.0, start)
    best_h = np.inf
    best_i = -1
    iterations = 0
    approach = 0
    end = -1
    status = NO_PATH
    sqrt2 = math.sqrt(2.0)
    while size > 0:
        if iterations >= max_iterations:
            status = MAX_ITERATIONS
            break
        if iterations % terminal_checking_interval == 0 and _now() - t0 >= max_planning_time:
            status = TIMED_OUT
            break
        _, cur, size = _pop(hk, hv, size)
        if visited[cur]:
            continue
        iterations += 1
        visited[cur] = True
        if cur == goal:
            end = cur
            status = FOUND
            break
        if best_h < tolerance:
            approach += 1
            if approach >= max_on_approach_iterations:
                end = best_i
                status = FOUND
                break
        cx = cur % w
        cy = cur // w
        for k in range(8):
            dx = (-1, 1, 0, 0, -1, 1, -1, 1)[k]
            dy = (0, 0, -1, 1, -1, -1, 1, 1)[k]
            mx = cx + dx
            my = cy + dy
            if mx < 0 or my < 0 or mx >= w or my >= h:
                continue
            m = my * w + mx
            if visited[m]:
                continue
            fm = fac[m]
            if fm < 0.0:
                continue
            gc = g[cur] + (sqrt2 * fm if k >= 4 else fm)
            if gc < g[m]:
                g[m] = gc
                parent[m] = cur
                hh = math.hypot(gx - mx, gy - my)
                if hh < best_h:
                    best_h = hh
                    best_i = m
                if size == hk.shape[0]:
                    hk, hv = _grow(hk, hv, size)
                size = _push(hk, hv, size, gc + hh, m)
    if status != FOUND and best_h < tolerance and status != TIMED_OUT:
        end = best_i
        status = FOUND
    if status != FOUND:
        return status, np.zeros((0, 2), dtype=np.int64), iterations
    count = 1
    c2 = end
    while c2 != start:
        c2 = parent[c2]
        count += 1
    out = np.empty((count, 2), dtype=np.int64)
    c2 = end
    for i in range(count - 1, -1, -1):
        out[i, 0] = c2 % w
        out[i, 1] = c2 // w
        c2 = parent[c2]
    return status, out, iterations


@njit(cache=True)
def downsample_max(grid: np.ndarray, factor: int) -> np.ndarray:
    """``CostmapDownsampler``: each cell of the coarse grid is the largest of its block."""
    h, w = grid.shape
    hh = (h + factor - 1) // factor
    ww = (w + factor - 1) // factor
    out = np.zeros((hh, ww), dtype=np.uint8)
    for y in range(h):
        for x in range(w):
            c = grid[y, x]
            if c > out[y // factor, x // factor]:
                out[y // factor, x // factor] = c
    return out


__all__ = ["astar_2d", "downsample_max"]
