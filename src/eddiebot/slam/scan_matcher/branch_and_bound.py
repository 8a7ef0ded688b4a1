"""Branch and bound over the correlation grid's pyramid (Cartographer's form of Olson's
multi-resolution search): the best candidate of a wide window, and every candidate of one
heading that can come within 0.1 of it (the ones the covariance keeps)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.slam.scan_matcher.grid import _score


@njit(cache=True)
def _penalty(
    dx: float, dy: float, dth: float, dvp: float, avp: float, mdp: float, map_: float
) -> float:
    """Karto's distance × angle penalty of a candidate (sequential matching)."""
    dist_pen = 1.0 - 0.2 * (dx * dx + dy * dy) / dvp
    if dist_pen < mdp:
        dist_pen = mdp
    ang_pen = 1.0 - 0.2 * dth * dth / avp
    if ang_pen < map_:
        ang_pen = map_
    return dist_pen * ang_pen


@njit(cache=True)
def _top_level_scores(
    grid: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    window: int,
    step: int,
) -> npt.NDArray[np.float64]:
    """Scores on a pyramid level of every (angle, dx, dy) candidate ``step`` cells apart,
    flattened as ((a · n_side) + ix) · n_side + iy."""
    n_ang = px.shape[0]
    n_side = (2 * window + 1 + step - 1) // step
    out = np.empty(n_ang * n_side * n_side)
    k = 0
    for a in range(n_ang):
        for ix in range(n_side):
            for iy in range(n_side):
                out[k] = _score(grid, px[a], py[a], -window + ix * step, -window + iy * step)
                k += 1
    return out


@njit(cache=True)
def _seed_stack(
    n_levels: int,
    window: int,
    top_scores: npt.NDArray[np.float64],
    order: npt.NDArray[np.int64],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64],
           npt.NDArray[np.int64], npt.NDArray[np.float64], int]:
    """The depth-first stack with the coarsest level's candidates on it in ``order``
    (ascending, so the best is popped first): angle indices, dx, dy, heights, scores and
    the stack's size."""
    top = n_levels - 1
    step = 1 << top
    n_side = (2 * window + 1 + step - 1) // step
    cap = order.size + 8 * n_levels + 8
    s_a = np.empty(cap, np.int64)
    s_x = np.empty(cap, np.int64)
    s_y = np.empty(cap, np.int64)
    s_h = np.empty(cap, np.int64)
    s_s = np.empty(cap, np.float64)
    n = 0
    for k in range(order.size):
        flat = order[k]
        s_a[n] = flat // (n_side * n_side)
        s_x[n] = -window + ((flat // n_side) % n_side) * step
        s_y[n] = -window + (flat % n_side) * step
        s_h[n] = top
        s_s[n] = top_scores[flat]
        n += 1
    return s_a, s_x, s_y, s_h, s_s, n


@njit(cache=True)
def _push_children(
    grid: npt.NDArray[np.float32],
    pxa: npt.NDArray[np.int64],
    pya: npt.NDArray[np.int64],
    a: int,
    x: int,
    y: int,
    h: int,
    window: int,
    bar: float,
    s_a: npt.NDArray[np.int64],
    s_x: npt.NDArray[np.int64],
    s_y: npt.NDArray[np.int64],
    s_h: npt.NDArray[np.int64],
    s_s: npt.NDArray[np.float64],
    n: int,
    c_x: npt.NDArray[np.int64],
    c_y: npt.NDArray[np.int64],
    c_s: npt.NDArray[np.float64],
) -> int:
    """Score the (up to four) children of candidate (``a``, ``x``, ``y``) at height ``h`` on
    ``grid`` (height ``h - 1``) and push those scoring above ``bar`` in ascending order, so
    the best child is popped first; the new stack size. ``c_x``, ``c_y``, ``c_s``: scratch
    arrays of four."""
    half = 1 << (h - 1)
    q = 0
    for ox in (0, half):
        for oy in (0, half):
            cx = x + ox
            cy = y + oy
            if cx > window or cy > window:
                continue
            c_x[q] = cx
            c_y[q] = cy
            c_s[q] = _score(grid, pxa, pya, cx, cy)
            q += 1
    for _ in range(q):
        low = -1
        v = 1e300
        for j in range(q):
            if c_s[j] >= 0.0 and c_s[j] < v:
                v = c_s[j]
                low = j
        if low < 0:
            break
        if v > bar:
            s_a[n] = a
            s_x[n] = c_x[low]
            s_y[n] = c_y[low]
            s_h[n] = h - 1
            s_s[n] = v
            n += 1
        c_s[low] = -1.0
    return n


@njit(cache=True)
def _branch_and_bound(
    g0: npt.NDArray[np.float32],
    g1: npt.NDArray[np.float32],
    g2: npt.NDArray[np.float32],
    g3: npt.NDArray[np.float32],
    g4: npt.NDArray[np.float32],
    g5: npt.NDArray[np.float32],
    n_levels: int,
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: npt.NDArray[np.float64],
    window: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
    top_scores: npt.NDArray[np.float64],
    order: npt.NDArray[np.int64],
) -> tuple[int, int, int, float]:
    """Best (angle index, dx, dy, penalised response) over the window, depth-first B&B.

    ``top_scores`` are `_top_level_scores` on the coarsest grid, ``order`` their ascending
    argsort (done outside: numba's sort costs seconds of compilation).
    """
    grids = (g0, g1, g2, g3, g4, g5)
    s_a, s_x, s_y, s_h, s_s, n = _seed_stack(n_levels, window, top_scores, order)
    best_a, best_x, best_y, best_s = -1, 0, 0, 0.0
    c_x = np.empty(4, np.int64)
    c_y = np.empty(4, np.int64)
    c_s = np.empty(4, np.float64)
    while n > 0:
        n -= 1
        a, x, y, h, s = s_a[n], s_x[n], s_y[n], s_h[n], s_s[n]
        if s <= best_s:
            continue
        if h == 0:
            if penalize:
                s = s * _penalty(x * res, y * res, dth[a], dvp, avp, mdp, map_)
            if s > best_s:
                best_a, best_x, best_y, best_s = a, x, y, s
            continue
        n = _push_children(grids[h - 1], px[a], py[a], a, x, y, h, window, best_s,
                           s_a, s_x, s_y, s_h, s_s, n, c_x, c_y, c_s)
    return best_a, best_x, best_y, best_s


@njit(cache=True)
def _bounded_score(
    grid: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    x: int,
    y: int,
    size: int,
    inv: float,
) -> float:
    """Mean of a pyramid level under the points moved by (x, y): on level 0 (``size`` 1) a
    candidate's response exactly as `_response_block` sums it (point order, times 1/n); on a
    coarser level an upper bound of every candidate in the size × size block from (x, y),
    a point whose anchor falls off the grid while its block still overlaps it counting 1
    (no cell exceeds 1). Rounding is monotone, so the bound holds in floating point too."""
    h, w = grid.shape
    total = 0.0
    for i in range(px.size):
        c = px[i] + x
        r = py[i] + y
        if 0 <= c < w and 0 <= r < h:
            total += grid[r, c]
        elif size > 1 and c + size > 0 and c < w and r + size > 0 and r < h:
            total += 1.0
    return total * inv


@njit(cache=True)
def _window_near_best(
    g0: npt.NDArray[np.float32],
    g1: npt.NDArray[np.float32],
    g2: npt.NDArray[np.float32],
    g3: npt.NDArray[np.float32],
    g4: npt.NDArray[np.float32],
    g5: npt.NDArray[np.float32],
    n_levels: int,
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: float,
    window: int,
    seed_x: int,
    seed_y: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
) -> npt.NDArray[np.float64]:
    """One heading's (penalised) responses over the ±window, [ix, iy] as `_exhaustive` gives
    them, where they can matter to the covariance: every candidate within 0.1 of the window's
    best holds `_exhaustive`'s value bit for bit (and so does the best), the others hold
    either their value or -1. Two passes over the pyramid: branch and bound for the best
    (seeded with the candidate at ``seed_x``, ``seed_y``), then every block whose bound
    reaches best - 0.1 down to its cells."""
    grids = (g0, g1, g2, g3, g4, g5)
    side = 2 * window + 1
    out = np.full((side, side), -1.0)
    inv = 1.0 / max(px.size, 1)
    top = n_levels - 1
    step = 1 << top
    n_side = (side + step - 1) // step
    cap = n_side * n_side + 4 * n_levels + 8
    s_x = np.empty(cap, np.int64)
    s_y = np.empty(cap, np.int64)
    s_h = np.empty(cap, np.int64)
    s_b = np.empty(cap, np.float64)
    best = -1.0
    if abs(seed_x) <= window and abs(seed_y) <= window:
        best = _bounded_score(g0, px, py, seed_x, seed_y, 1, inv)
        if penalize and best > 0.0:
            best *= _penalty(seed_x * res, seed_y * res, dth, dvp, avp, mdp, map_)
    for phase in range(2):
        thresh = best - 0.1
        n = 0
        for ix in range(n_side):
            for iy in range(n_side):
                x = -window + ix * step
                y = -window + iy * step
                b = _bounded_score(grids[top], px, py, x, y, step, inv)
                if (phase == 0 and b > best) or (phase == 1 and b >= thresh):
                    s_x[n], s_y[n], s_h[n], s_b[n] = x, y, top, b
                    n += 1
        while n > 0:
            n -= 1
            x, y, h, b = s_x[n], s_y[n], s_h[n], s_b[n]
            if phase == 0 and b <= best:
                continue
            if h == 0:
                v = b
                if penalize and v > 0.0:
                    v *= _penalty(x * res, y * res, dth, dvp, avp, mdp, map_)
                if phase == 0:
                    best = max(best, v)
                else:
                    out[x + window, y + window] = v
                continue
            half = 1 << (h - 1)
            for ox in (0, half):
                for oy in (0, half):
                    cx = x + ox
                    cy = y + oy
                    if cx > window or cy > window:
                        continue
                    cb = _bounded_score(grids[h - 1], px, py, cx, cy, half, inv)
                    if (phase == 0 and cb > best) or (phase == 1 and cb >= thresh):
                        s_x[n], s_y[n], s_h[n], s_b[n] = cx, cy, h - 1, cb
                        n += 1
    return out
