"""``SmacPlannerHybrid``'s search (numba): Hybrid-A* over (x, y, heading bin) with the
footprint collision check, upstream's traversal cost and analytic expansions."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.typed import Dict

from eddiebot.nav.costmap._kernels import polygon_outline_cost
from eddiebot.nav.planners._heap import _grow, _pop, _push
from eddiebot.nav.planners.smac.curves import curve_path, curve_sample
from eddiebot.nav.planners.smac.search.common import (
    FORWARD,
    FOUND,
    INSCRIBED,
    MAX_ITERATIONS,
    NO_PATH,
    OCCUPIED,
    REV_LEFT,
    REV_RIGHT,
    REVERSE,
    TIMED_OUT,
    UNKNOWN,
    _now,
)
from eddiebot.nav.planners.smac.search.heuristics import _heuristic


@njit(cache=True)
def _in_collision(grid: np.ndarray, x: float, y: float, bin_: int, allow_unknown: bool,
                  use_radius: bool, possible_cost: float, footprints: np.ndarray
                  ) -> tuple[bool, float]:
    """``GridCollisionChecker::inCollision`` (cell coordinates; footprints in cells). The
    centre cost is the cell containing (x, y); upstream rounds to ``int(x + 0.5)``, half a
    cell off its own ``worldToMapContinuous`` convention."""
    h, w = grid.shape
    if x < 0.0 or y < 0.0 or x > w or y > h:
        return True, 0.0
    cxi = int(x)
    cyi = int(y)
    if cxi >= w or cyi >= h:
        return True, 0.0
    center = float(grid[cyi, cxi])
    if not use_radius:
        if center < possible_cost and possible_cost > 0.0:
            return False, center
        if center == UNKNOWN and not allow_unknown:
            return True, center
        if center in (INSCRIBED, OCCUPIED):
            return True, center
        fp = footprints[bin_].copy()
        ox = math.floor(x) + 0.5
        oy = math.floor(y) + 0.5
        for i in range(fp.shape[0]):
            fp[i, 0] += ox
            fp[i, 1] += oy
        c = polygon_outline_cost(grid, fp, 0.0, 0.0, 1.0)
        if c < 0:
            return True, center
        if c == UNKNOWN and allow_unknown:
            return False, center
        return c >= OCCUPIED, center
    if center == UNKNOWN and allow_unknown:
        return False, center
    return center >= INSCRIBED, center


@njit(cache=True)
def traversal_cost(parent_turn: int, turn: int, travel: float, travel_distance_cost: float,
                   child_cost: float, cost_penalty: float, quadratic: bool,
                   travel_reward: float, non_straight_penalty: float, change_penalty: float,
                   reverse_penalty: float) -> float:
    """``NodeHybrid::getTraversalCost`` of a primitive (``parent_turn`` -1: the parent is
    the start, which costs ``travel_distance_cost``, the straight primitive's length)."""
    if parent_turn < 0:
        return travel_distance_cost
    nc = child_cost / 252.0
    raw = travel * (travel_reward + cost_penalty * (nc * nc if quadratic else nc))
    if turn in (FORWARD, REVERSE):
        tc = raw
    elif parent_turn == turn:
        tc = raw * non_straight_penalty
    else:
        tc = raw * (non_straight_penalty + change_penalty)
    if turn in (REVERSE, REV_LEFT, REV_RIGHT):
        tc *= reverse_penalty
    return tc


@njit(cache=True)
def _analytic_path(px: float, py: float, pth: float, gx: float, gy: float, gth: float,
                   rho: float, rs: bool, bins: int, grid: np.ndarray, allow_unknown: bool,
                   use_radius: bool, possible_cost: float, footprints: np.ndarray,
                   max_length: float, max_cost: float, max_cost_override: bool,
                   min_turning_radius: float) -> np.ndarray:
    """``AnalyticExpansion::getAnalyticPath``: the curve from a node to the goal sampled at
    about √2 cells, each sample free; rows (x, y, angle bin (float), cost, reverse). (0, 5)
    if it is too long, too short, blocked, or re-enters a cost above
    ``analytic_expansion_max_cost`` after leaving it."""
    empty = np.zeros((0, 5))
    kinds, lengths, d = curve_path(px, py, pth, gx, gy, gth, rho, rs)
    sqrt2 = math.sqrt(2.0)
    if d > max_length or d < sqrt2:
        return empty
    n = math.floor(d / sqrt2)
    out = np.empty((n, 5))
    bin_size = 2.0 * math.pi / bins
    two_pi = 2.0 * math.pi
    w = grid.shape[1]
    prev_key = -1
    for i in range(1, n + 1):
        x, y, th, rev = curve_sample(px, py, pth, kinds, lengths, rho, i / n)
        th = th - two_pi * math.floor(th / two_pi)
        if th >= two_pi:
            th -= two_pi
        ang = th / bin_size
        b = int(ang)
        if b >= bins:
            b -= bins
        if x < 0.0 or y < 0.0:
            return empty
        key = (int(y) * w + int(x)) * bins + b
        coll, cost = _in_collision(grid, x, y, b, allow_unknown, use_radius, possible_cost,
                                   footprints)
        if coll or key == prev_key:
            return empty
        prev_key = key
        out[i - 1, 0] = x
        out[i - 1, 1] = y
        out[i - 1, 2] = ang
        out[i - 1, 3] = cost
        out[i - 1, 4] = 1.0 if rev else 0.0
    if n > 0 and out[:, 3].max() > max_cost:
        left_high = False
        fail = False
        for i in range(n - 1, -1, -1):
            if out[i, 3] <= max_cost:
                left_high = True
            elif left_high:
                fail = True
                break
        if fail and not (max_cost_override and d < 2.0 * math.pi * min_turning_radius):
            return empty
    return out


@njit(cache=True)
def _score(path: np.ndarray, cost_penalty: float) -> float:
    if path.shape[0] < 2:
        return np.inf
    dist = math.hypot(path[1, 0] - path[0, 0], path[1, 1] - path[0, 1])
    s = 0.0
    for i in range(path.shape[0]):
        s += dist * (1.0 + cost_penalty * path[i, 3] / 252.0)
    return s


@njit(cache=True)
def hybrid_astar(
    grid: np.ndarray, sx: float, sy: float, sbin: int, gx: float, gy: float, gbin: int,
    bins: int, proj_dx: np.ndarray, proj_dy: np.ndarray, proj_dth: np.ndarray,
    proj_turn: np.ndarray, travel_costs: np.ndarray, rho: float, reeds_shepp: bool,
    non_straight_penalty: float, change_penalty: float, reverse_penalty: float,
    cost_penalty: float, quadratic: bool, retrospective_penalty: float, analytic_ratio: float,
    analytic_max_length: float, analytic_max_cost: float, analytic_max_cost_override: bool,
    lookup_dim: float, h_obs: np.ndarray, downsample_h: bool, allow_unknown: bool,
    use_radius: bool, possible_cost: float, footprints: np.ndarray, tolerance: float,
    max_iterations: int, max_on_approach_iterations: int, terminal_checking_interval: int,
    max_planning_time: float,
) -> tuple[int, np.ndarray, int]:
    """``AStarAlgorithm<NodeHybrid>::createPath``: (status, poses (K, 4) start -> goal as
    (x, y, angle bin (float), reverse flag) in cell coordinates, expansions)."""
    t0 = _now()
    h, w = grid.shape
    index = Dict.empty(key_type=types.int64, value_type=types.int64)
    cap = 4096
    nx = np.empty(cap)
    ny = np.empty(cap)
    nth = np.empty(cap)
    ng = np.empty(cap)
    npar = np.empty(cap, dtype=np.int64)
    nvis = np.zeros(cap, dtype=np.bool_)
    nvalid = np.zeros(cap, dtype=np.int8)  # 0 unchecked, 1 valid, 2 invalid
    ncost = np.zeros(cap)
    nprim = np.full(cap, -1, dtype=np.int64)
    nrev = np.zeros(cap)
    count = 0
    hk = np.empty(4096)
    hv = np.empty(4096, dtype=np.int64)
    size = 0
    travel_reward = 1.0 - retrospective_penalty
    two_pi_bins = float(bins)

    start_key = (int(sy) * w + int(sx)) * bins + sbin
    goal_key = (int(gy) * w + int(gx)) * bins + gbin
    # start node
    index[start_key] = 0
    nx[0] = sx
    ny[0] = sy
    nth[0] = sbin
    ng[0] = 0.0
    npar[0] = -1
    nvalid[0] = 1
    count = 1
    if size == hk.shape[0]:
        hk, hv = _grow(hk, hv, size)
    size = _push(hk, hv, size, 0.0, 0)
    best_h = np.inf
    best_slot = -1
    iterations = 0
    approach = 0
    analytic_iterations = 0
    closest = 2 ** 62
    status = NO_PATH
    end = -1
    analytic = np.zeros((0, 5))
    analytic_from = -1
    while size > 0:
        if iterations >= max_iterations:
            status = MAX_ITERATIONS
            break
        if iterations % terminal_checking_interval == 0 and _now() - t0 >= max_planning_time:
            status = TIMED_OUT
            break
        _, cur, size = _pop(hk, hv, size)
        if nvis[cur]:
            continue
        iterations += 1
        nvis[cur] = True
        # analytic expansion (AnalyticExpansion::tryAnalyticExpansion)
        hcur = _heuristic(nx[cur], ny[cur], nth[cur], gx, gy, gbin, h_obs, downsample_h,
                          bins, rho, reeds_shepp, lookup_dim)
        closest = min(closest, int(hcur))
        desired = max(int(closest / analytic_ratio), math.ceil(analytic_ratio))
        analytic_iterations = min(analytic_iterations, desired)
        if analytic_iterations <= 0:
            analytic_iterations = desired
            bsz = 2.0 * math.pi / bins
            gth = gbin * bsz
            path = _analytic_path(nx[cur], ny[cur], nth[cur] * bsz, gx, gy, gth, rho,
                                  reeds_shepp, bins, grid, allow_unknown, use_radius,
                                  possible_cost, footprints, analytic_max_length,
                                  analytic_max_cost, analytic_max_cost_override, rho)
            if path.shape[0] > 0:
                node = cur
                test = cur
                for _ in range(8):
                    up = test
                    k = 0
                    while k < 5 and npar[up] >= 0:
                        up = npar[up]
                        k += 1
                    if k < 5:
                        break
                    refined = _analytic_path(
                        nx[up], ny[up], nth[up] * bsz, gx, gy, gth, rho, reeds_shepp, bins,
                        grid, allow_unknown, use_radius, possible_cost, footprints,
                        analytic_max_length, analytic_max_cost, analytic_max_cost_override, rho)
                    if refined.shape[0] == 0:
                        break
                    path = refined
                    node = up
                    test = up
                best = _score(path, cost_penalty)
                r = rho
                while r < 4.0 * rho:
                    r += 0.5
                    refined = _analytic_path(
                        nx[node], ny[node], nth[node] * bsz, gx, gy, gth, r, reeds_shepp,
                        bins, grid, allow_unknown, use_radius, possible_cost, footprints,
                        analytic_max_length, analytic_max_cost, analytic_max_cost_override,
                        rho)
                    sc = _score(refined, cost_penalty)
                    if sc <= best:
                        path = refined
                        best = sc
                analytic = path
                analytic_from = node
                status = FOUND
                break
        analytic_iterations -= 1
        key_cur = (int(ny[cur]) * w + int(nx[cur])) * bins + int(nth[cur])
        if key_cur == goal_key:
            end = cur
            status = FOUND
            break
        if best_h < tolerance:
            approach += 1
            if approach >= max_on_approach_iterations:
                end = best_slot
                status = FOUND
                break
        base = int(nth[cur])
        for p in range(proj_dx.shape[0]):
            x = proj_dx[p, base] + nx[cur]
            y = proj_dy[p, base] + ny[cur]
            th = nth[cur] + proj_dth[p]
            if th < 0.0:
                th += two_pi_bins
            if th >= two_pi_bins:
                th -= two_pi_bins
            if x < 0.0 or y < 0.0 or x >= w or y >= h:
                continue
            key = (int(y) * w + int(x)) * bins + int(th)
            slot = -1
            if key in index:
                slot = index[key]
            if slot >= 0 and nvis[slot]:
                continue
            if slot < 0:
                if count == nx.shape[0]:
                    nc2 = 2 * count
                    nx = np.concatenate((nx, np.empty(count)))
                    ny = np.concatenate((ny, np.empty(count)))
                    nth = np.concatenate((nth, np.empty(count)))
                    ng = np.concatenate((ng, np.empty(count)))
                    npar = np.concatenate((npar, np.empty(count, dtype=np.int64)))
                    nvis = np.concatenate((nvis, np.zeros(count, dtype=np.bool_)))
                    nvalid = np.concatenate((nvalid, np.zeros(count, dtype=np.int8)))
                    ncost = np.concatenate((ncost, np.zeros(count)))
                    nprim = np.concatenate((nprim, np.full(count, -1, dtype=np.int64)))
                    nrev = np.concatenate((nrev, np.zeros(count)))
                    assert nx.shape[0] == nc2
                slot = count
                count += 1
                index[key] = slot
                ng[slot] = np.inf
                npar[slot] = -1
                nvis[slot] = False
                nvalid[slot] = 0
                nprim[slot] = -1
            if nvalid[slot] == 0:
                coll, c = _in_collision(grid, x, y, int(th), allow_unknown, use_radius,
                                        possible_cost, footprints)
                nvalid[slot] = 2 if coll else 1
                ncost[slot] = c
            if nvalid[slot] != 1:
                continue
            parent_turn = -1 if nprim[cur] < 0 else proj_turn[nprim[cur]]
            tc = traversal_cost(parent_turn, proj_turn[p], travel_costs[p], travel_costs[0],
                                ncost[slot], cost_penalty, quadratic, travel_reward,
                                non_straight_penalty, change_penalty, reverse_penalty)
            turn = proj_turn[p]
            gc = ng[cur] + tc
            if gc < ng[slot]:
                ng[slot] = gc
                npar[slot] = cur
                nprim[slot] = p
                nx[slot] = x
                ny[slot] = y
                nth[slot] = th
                nrev[slot] = 1.0 if turn >= REVERSE else 0.0
                hh = _heuristic(x, y, th, gx, gy, gbin, h_obs, downsample_h, bins, rho,
                                reeds_shepp, lookup_dim)
                if hh < best_h:
                    best_h = hh
                    best_slot = slot
                if size == hk.shape[0]:
                    hk, hv = _grow(hk, hv, size)
                size = _push(hk, hv, size, gc + hh, slot)
    if status != FOUND and status != TIMED_OUT and best_h < tolerance:
        end = best_slot
        status = FOUND
    if status != FOUND:
        return status, np.zeros((0, 4)), iterations
    tail = end if analytic_from < 0 else analytic_from
    k = 1
    c2 = tail
    while npar[c2] >= 0:
        c2 = npar[c2]
        k += 1
    extra = 0
    if analytic_from >= 0:
        extra = analytic.shape[0] + 1
        if analytic.shape[0] > 0:
            la = analytic[analytic.shape[0] - 1]
            if abs(la[0] - gx) < 1e-6 and abs(la[1] - gy) < 1e-6:
                extra -= 1  # the last sample is the goal itself
    out = np.empty((k + extra, 4))
    c2 = tail
    for i in range(k - 1, -1, -1):
        out[i, 0] = nx[c2]
        out[i, 1] = ny[c2]
        out[i, 2] = nth[c2]
        out[i, 3] = nrev[c2]
        c2 = npar[c2]
    if analytic_from >= 0:
        na = extra - 1
        for i in range(na):
            out[k + i, 0] = analytic[i, 0]
            out[k + i, 1] = analytic[i, 1]
            out[k + i, 2] = analytic[i, 2]
            out[k + i, 3] = analytic[i, 4]
        out[k + na, 0] = gx
        out[k + na, 1] = gy
        out[k + na, 2] = gbin
        out[k + na, 3] = analytic[analytic.shape[0] - 1, 4] if analytic.shape[0] > 0 else 0.0
    return status, out, iterations


__all__ = ["_in_collision", "hybrid_astar", "traversal_cost"]
