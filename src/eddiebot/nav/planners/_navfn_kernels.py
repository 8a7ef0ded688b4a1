"""numba port of NavFn's wavefront propagation and gradient path extraction (``navfn.cpp``)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

COST_UNKNOWN_ROS = 255
COST_OBS = 254
COST_OBS_ROS = 253
COST_NEUTRAL = 50
COST_FACTOR = 0.8
POT_HIGH = 1.0e10
PATH_STEP = 0.5
INVSQRT2 = 0.707106781


@njit(cache=True)
def translate_costs(cmap: np.ndarray, allow_unknown: bool) -> np.ndarray:
    """``NavFn::setCostmap(isROS=true)`` then ``setupNavFn``'s obstacle border."""
    ny, nx = cmap.shape
    out = np.empty(nx * ny, dtype=np.float32)
    k = 0
    for i in range(ny):
        for j in range(nx):
            v = int(cmap[i, j])
            c = COST_OBS
            if v < COST_OBS_ROS:
                v2 = int(COST_NEUTRAL + COST_FACTOR * v)
                if v2 >= COST_OBS:
                    v2 = COST_OBS - 1
                c = v2
            elif v == COST_UNKNOWN_ROS and allow_unknown:
                c = COST_OBS - 1
            out[k] = c
            k += 1
    for j in range(nx):
        out[j] = COST_OBS
        out[(ny - 1) * nx + j] = COST_OBS
    for i in range(ny):
        out[i * nx] = COST_OBS
        out[i * nx + nx - 1] = COST_OBS
    return out


@njit(cache=True)
def propagate(
    cost: np.ndarray, nx: int, ny: int, goal_cell: int, start_cell: int,
    astar: bool, cycles: int, stop_at_start: bool,
) -> np.ndarray:
    """Potential field from ``goal_cell`` (potential 0) with NavFn's priority-band wavefront.

    (NavFn's own naming: the field grows from its "goal", the robot, and stops once its
    "start", the navigation goal, has a potential.) Buffers are sized to the map, so no
    push is ever dropped (upstream caps them at 10000 entries).
    """
    ns = nx * ny
    pot = np.full(ns, POT_HIGH, dtype=np.float32)
    pending = np.zeros(ns, dtype=np.bool_)
    curp = np.empty(ns + 4, dtype=np.int32)
    nextp = np.empty(ns + 4, dtype=np.int32)
    overp = np.empty(ns + 4, dtype=np.int32)
    n_cur = 0
    n_next = 0
    n_over = 0
    sx = start_cell % nx
    sy = start_cell // nx
    pot[goal_cell] = 0.0
    for m in (goal_cell + 1, goal_cell - 1, goal_cell - nx, goal_cell + nx):
        if 0 <= m < ns and not pending[m] and cost[m] < COST_OBS:
            pending[m] = True
            curp[n_cur] = m
            n_cur += 1
    cur_t = np.float32(COST_OBS)
    if astar:
        cur_t += np.float32(math.hypot(goal_cell % nx - sx, goal_cell // nx - sy) * COST_NEUTRAL)
    s2 = np.float32(INVSQRT2)
    qa = np.float32(-0.2301)
    qb = np.float32(0.5307)
    qc = np.float32(0.7040)
    neutral = np.float32(COST_NEUTRAL)
    high = np.float32(POT_HIGH)
    for _ in range(cycles):
        if n_cur == 0 and n_next == 0:
            break
        for i in range(n_cur):
            pending[curp[i]] = False
        for i in range(n_cur):
            n = curp[i]
            h = cost[n]
            if h >= COST_OBS:
                continue
            left = pot[n - 1]
            right = pot[n + 1]
            up = pot[n - nx]
            down = pot[n + nx]
            tc = min(left, right)
            ta = min(up, down)
            dc = tc - ta
            if dc < 0:
                dc = -dc
                ta = tc
            if dc >= h:
                p = ta + h
            else:
                d = dc / h
                p = ta + h * (qa * d * d + qb * d + qc)
            if p < pot[n]:
                pot[n] = p
                key = p
                if astar:
                    key = p + np.float32(math.hypot(n % nx - sx, n // nx - sy)) * neutral
                low = key < cur_t
                for m, pm in ((n - 1, left), (n + 1, right), (n - nx, up), (n + nx, down)):
                    cm = cost[m]
                    if pm > p + s2 * cm and not pending[m] and cm < COST_OBS:
                        pending[m] = True
                        if low:
                            nextp[n_next] = m
                            n_next += 1
                        else:
                            overp[n_over] = m
                            n_over += 1
        tmp = curp
        curp = nextp
        nextp = tmp
        n_cur = n_next
        n_next = 0
        if n_cur == 0:
            cur_t += np.float32(2 * COST_NEUTRAL)
            tmp = curp
            curp = overp
            overp = tmp
            n_cur = n_over
            n_over = 0
        if stop_at_start and pot[start_cell] < high:
            break
    return pot


@njit(cache=True)
def _grad_cell(n: int, nx: int, ns: int, pot: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> float:
    if gx[n] + gy[n] > 0.0:
        return 1.0
    if n < nx or n > ns - nx:
        return 0.0
    cv = pot[n]
    dx = 0.0
    dy = 0.0
    if cv >= POT_HIGH:
        if pot[n - 1] < POT_HIGH:
            dx = -COST_OBS
        elif pot[n + 1] < POT_HIGH:
            dx = COST_OBS
        if pot[n - nx] < POT_HIGH:
            dy = -COST_OBS
        elif pot[n + nx] < POT_HIGH:
            dy = COST_OBS
    else:
        if pot[n - 1] < POT_HIGH:
            dx += pot[n - 1] - cv
        if pot[n + 1] < POT_HIGH:
            dx += cv - pot[n + 1]
        if pot[n - nx] < POT_HIGH:
            dy += pot[n - nx] - cv
        if pot[n + nx] < POT_HIGH:
            dy += cv - pot[n + nx]
    norm = math.hypot(dx, dy)
    if norm > 0:
        inv = 1.0 / norm
        gx[n] = inv * dx
        gy[n] = inv * dy
    return norm


@njit(cache=True)
def calc_path(pot: np.ndarray, nx: int, ny: int, start_cell: int, max_cycles: int) -> np.ndarray:
    """``NavFn::calcPath``: descend the potential from ``start_cell``; (K, 2) cell coords,
    first = start; empty on failure."""
    ns = nx * ny
    gx = np.zeros(ns, dtype=np.float32)
    gy = np.zeros(ns, dtype=np.float32)
    out = np.empty((max_cycles + 1, 2), dtype=np.float64)
    npath = 0
    stc = start_cell
    dx = 0.0
    dy = 0.0
    for _ in range(max_cycles):
        nearest = stc + round(dx) + nx * round(dy)
        nearest = max(0, min(ns - 1, nearest))
        if pot[nearest] < COST_NEUTRAL:
            out[npath, 0] = nearest % nx
            out[npath, 1] = nearest // nx
            npath += 1
            return out[:npath]
        if stc < nx or stc > ns - nx:
            return out[:0]
        out[npath, 0] = stc % nx + dx
        out[npath, 1] = stc // nx + dy
        npath += 1
        osc = False
        if npath > 2 and out[npath - 1, 0] == out[npath - 3, 0] and out[npath - 1, 1] == out[npath - 3, 1]:
            osc = True
        stcnx = stc + nx
        stcpx = stc - nx
        if (pot[stc] >= POT_HIGH or pot[stc + 1] >= POT_HIGH or pot[stc - 1] >= POT_HIGH
                or pot[stcnx] >= POT_HIGH or pot[stcnx + 1] >= POT_HIGH
                or pot[stcnx - 1] >= POT_HIGH or pot[stcpx] >= POT_HIGH
                or pot[stcpx + 1] >= POT_HIGH or pot[stcpx - 1] >= POT_HIGH or osc):
            minc = stc
            minp = pot[stc]
            for c in (stcpx - 1, stcpx, stcpx + 1, stc - 1, stc + 1, stcnx - 1, stcnx, stcnx + 1):
                if pot[c] < minp:
                    minp = pot[c]
                    minc = c
            stc = minc
            dx = 0.0
            dy = 0.0
            if pot[stc] >= POT_HIGH:
                return out[:0]
        else:
            _grad_cell(stc, nx, ns, pot, gx, gy)
            _grad_cell(stc + 1, nx, ns, pot, gx, gy)
            _grad_cell(stcnx, nx, ns, pot, gx, gy)
            _grad_cell(stcnx + 1, nx, ns, pot, gx, gy)
            x1 = (1.0 - dx) * gx[stc] + dx * gx[stc + 1]
            x2 = (1.0 - dx) * gx[stcnx] + dx * gx[stcnx + 1]
            x = (1.0 - dy) * x1 + dy * x2
            y1 = (1.0 - dx) * gy[stc] + dx * gy[stc + 1]
            y2 = (1.0 - dx) * gy[stcnx] + dx * gy[stcnx + 1]
            y = (1.0 - dy) * y1 + dy * y2
            if x == 0.0 and y == 0.0:
                return out[:0]
            ss = PATH_STEP / math.hypot(x, y)
            dx += x * ss
            dy += y * ss
            if dx > 1.0:
                stc += 1
                dx -= 1.0
            if dx < -1.0:
                stc -= 1
                dx += 1.0
            if dy > 1.0:
                stc += nx
                dy -= 1.0
            if dy < -1.0:
                stc -= nx
                dy += 1.0
    return out[:0]
