"""numba kernels for the costmap: ray tracing, marking, inflation, footprint cost."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_LETHAL = 254
_INSCRIBED = 253
_NO_INFO = 255
_FREE = 0


@njit(cache=True)
def raytrace_clear(
    grid: np.ndarray, x0: int, y0: int, x1: int, y1: int,
    max_length: float, min_length: float, value: int,
) -> None:
    """Nav2 ``Costmap2D::raytraceLine``: set cells on the line (x0,y0)->(x1,y1) to ``value``.

    The start moves forward to ``min_length`` cells; the trace is cut at ``max_length`` cells
    of the full ray (Bresenham, the final cell included as upstream's ``bresenham2D`` does).
    """
    dxf = x1 - x0
    dyf = y1 - y0
    dist = math.hypot(dxf, dyf)
    if dist < min_length:
        return
    if dist > 0.0:
        x0 = int(x0 + dxf / dist * min_length)
        y0 = int(y0 + dyf / dist * min_length)
    dx = x1 - x0
    dy = y1 - y0
    adx = abs(dx)
    ady = abs(dy)
    sx = 1 if dx > 0 else -1
    sy = 1 if dy > 0 else -1
    scale = 1.0 if dist == 0.0 else min(1.0, max_length / dist)
    h, w = grid.shape
    x = x0
    y = y0
    if adx >= ady:
        n = min(int(scale * adx), adx)
        err = adx // 2
        for _ in range(n):
            if 0 <= x < w and 0 <= y < h:
                grid[y, x] = value
            x += sx
            err += ady
            if err >= adx:
                y += sy
                err -= adx
    else:
        n = min(int(scale * ady), ady)
        err = ady // 2
        for _ in range(n):
            if 0 <= x < w and 0 <= y < h:
                grid[y, x] = value
            y += sy
            err += adx
            if err >= ady:
                x += sx
                err -= ady
    if 0 <= x < w and 0 <= y < h:
        grid[y, x] = value


@njit(cache=True)
def raytrace_many(
    grid: np.ndarray, ox: float, oy: float, pts: np.ndarray, origin_x: float, origin_y: float,
    resolution: float, max_range: float, min_range: float,
) -> np.ndarray:
    """Clear along rays from world origin (ox, oy) to each world point; returns touched bounds."""
    h, w = grid.shape
    bounds = np.array([1e300, 1e300, -1e300, -1e300])
    x0 = math.floor((ox - origin_x) / resolution)
    y0 = math.floor((oy - origin_y) / resolution)
    if x0 < 0 or y0 < 0 or x0 >= w or y0 >= h:
        return bounds
    map_end_x = origin_x + w * resolution
    map_end_y = origin_y + h * resolution
    cell_max = max_range / resolution
    cell_min = min_range / resolution
    for k in range(pts.shape[0]):
        wx = pts[k, 0]
        wy = pts[k, 1]
        a = wx - ox
        b = wy - oy
        # Clip the ray to the map, keeping its direction (Nav2 raytraceFreespace).
        if wx < origin_x:
            t = (origin_x - ox) / a
            wx = origin_x
            wy = oy + b * t
        if wy < origin_y:
            t = (origin_y - oy) / b
            wx = ox + a * t
            wy = origin_y
        if wx > map_end_x:
            t = (map_end_x - ox) / a
            wx = map_end_x - 0.001
            wy = oy + b * t
        if wy > map_end_y:
            t = (map_end_y - oy) / b
            wx = ox + a * t
            wy = map_end_y - 0.001
        x1 = math.floor((wx - origin_x) / resolution)
        y1 = math.floor((wy - origin_y) / resolution)
        raytrace_clear(grid, x0, y0, x1, y1, cell_max, cell_min, _FREE)
        # Bounds of the cleared ray (capped at max_range).
        d = math.hypot(a, b)
        s = 1.0 if d <= max_range or d == 0.0 else max_range / d
        ex = ox + a * s
        ey = oy + b * s
        bounds[0] = min(bounds[0], min(ox, ex))
        bounds[1] = min(bounds[1], min(oy, ey))
        bounds[2] = max(bounds[2], max(ox, ex))
        bounds[3] = max(bounds[3], max(oy, ey))
    return bounds


@njit(cache=True)
def mark_points(
    grid: np.ndarray, origin3: np.ndarray, pts: np.ndarray, origin_x: float, origin_y: float,
    resolution: float, max_range: float, min_range: float, max_height: float,
) -> np.ndarray:
    """Mark points LETHAL (range and height gated as Nav2's ObstacleLayer); returns bounds."""
    h, w = grid.shape
    bounds = np.array([1e300, 1e300, -1e300, -1e300])
    sq_max = max_range * max_range
    sq_min = min_range * min_range
    for k in range(pts.shape[0]):
        px = pts[k, 0]
        py = pts[k, 1]
        pz = pts[k, 2]
        if pz > max_height:
            continue
        sq = (px - origin3[0]) ** 2 + (py - origin3[1]) ** 2 + (pz - origin3[2]) ** 2
        if sq >= sq_max or sq < sq_min:
            continue
        mx = math.floor((px - origin_x) / resolution)
        my = math.floor((py - origin_y) / resolution)
        if mx < 0 or my < 0 or mx >= w or my >= h:
            continue
        grid[my, mx] = _LETHAL
        bounds[0] = min(bounds[0], px)
        bounds[1] = min(bounds[1], py)
        bounds[2] = max(bounds[2], px)
        bounds[3] = max(bounds[3], py)
    return bounds


@njit(cache=True)
def inflate(
    master: np.ndarray, kernel: np.ndarray, cell_radius: int,
    i0: int, j0: int, i1: int, j1: int,
    inflate_unknown: bool, inflate_around_unknown: bool,
) -> None:
    """Inflate obstacles into window [i0, i1) x [j0, j1) of ``master`` (x = i, y = j).

    ``kernel[dy + r, dx + r]`` is the cost at offset (dx, dy) from a seed (0 beyond the
    radius). Each cell gets the cost of its nearest seed (maximum over seeds, since the cost
    falls with distance), seeds taken from the window grown by the radius; interior seeds
    (all four neighbours also seeds) are skipped: a boundary seed is always nearer.
    """
    h, w = master.shape
    r = cell_radius
    ei0 = max(0, i0 - r)
    ej0 = max(0, j0 - r)
    ei1 = min(w, i1 + r)
    ej1 = min(h, j1 + r)
    bw = i1 - i0
    bh = j1 - j0
    if bw <= 0 or bh <= 0:
        return
    best = np.zeros((bh, bw), dtype=np.uint8)
    for sy in range(ej0, ej1):
        for sx in range(ei0, ei1):
            c = master[sy, sx]
            if not (c == _LETHAL or (inflate_around_unknown and c == _NO_INFO)):
                continue
            interior = True
            if sx == 0 or sx == w - 1 or sy == 0 or sy == h - 1:
                interior = False
            else:
                for ny, nx in ((sy - 1, sx), (sy + 1, sx), (sy, sx - 1), (sy, sx + 1)):
                    cn = master[ny, nx]
                    if not (cn == _LETHAL or (inflate_around_unknown and cn == _NO_INFO)):
                        interior = False
                        break
            if interior:
                continue
            y_lo = max(j0, sy - r)
            y_hi = min(j1, sy + r + 1)
            x_lo = max(i0, sx - r)
            x_hi = min(i1, sx + r + 1)
            for y in range(y_lo, y_hi):
                ky = y - sy + r
                for x in range(x_lo, x_hi):
                    kc = kernel[ky, x - sx + r]
                    if kc > best[y - j0, x - i0]:
                        best[y - j0, x - i0] = kc
    for y in range(j0, j1):
        for x in range(i0, i1):
            cost = best[y - j0, x - i0]
            old = master[y, x]
            if old == _NO_INFO:
                if (inflate_unknown and cost > 0) or ((not inflate_unknown) and cost >= _INSCRIBED):
                    master[y, x] = cost
            elif cost > old:
                master[y, x] = cost


@njit(cache=True)
def line_cost(grid: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> int:
    """Maximum cost on the Bresenham line, both ends included (-1 if a cell is off the map)."""
    h, w = grid.shape
    dx = abs(x1 - x0)
    dy = -abs(y1 - y0)
    sx = 1 if x0 < x1 else -1
    sy = 1 if y0 < y1 else -1
    err = dx + dy
    x = x0
    y = y0
    best = 0
    while True:
        if x < 0 or y < 0 or x >= w or y >= h:
            return -1
        c = grid[y, x]
        if c > best:
            best = c
        if x == x1 and y == y1:
            break
        e2 = 2 * err
        if e2 >= dy:
            err += dy
            x += sx
        if e2 <= dx:
            err += dx
            y += sy
    return best


@njit(cache=True)
def polygon_outline_cost(
    grid: np.ndarray, poly_world: np.ndarray, origin_x: float, origin_y: float, resolution: float,
) -> int:
    """Nav2 ``FootprintCollisionChecker::footprintCost``: max cost along the polygon's edges.

    Returns -1 if any vertex is off the map (the caller treats it per its own rule).
    """
    n = poly_world.shape[0]
    best = 0
    for k in range(n):
        a = poly_world[k]
        b = poly_world[(k + 1) % n]
        x0 = math.floor((a[0] - origin_x) / resolution)
        y0 = math.floor((a[1] - origin_y) / resolution)
        x1 = math.floor((b[0] - origin_x) / resolution)
        y1 = math.floor((b[1] - origin_y) / resolution)
        c = line_cost(grid, x0, y0, x1, y1)
        if c < 0:
            return -1
        if c > best:
            best = c
        if best == _LETHAL:
            return best
    return best


@njit(cache=True)
def fill_polygon(grid: np.ndarray, poly_cells: np.ndarray, value: int) -> None:
    """Set every cell whose centre lies inside the polygon (cell coordinates) to ``value``."""
    h, w = grid.shape
    n = poly_cells.shape[0]
    ymin = max(0, math.floor(poly_cells[:, 1].min()))
    ymax = min(h - 1, math.ceil(poly_cells[:, 1].max()))
    xmin = max(0, math.floor(poly_cells[:, 0].min()))
    xmax = min(w - 1, math.ceil(poly_cells[:, 0].max()))
    for y in range(ymin, ymax + 1):
        cy = y + 0.5
        for x in range(xmin, xmax + 1):
            cx = x + 0.5
            inside = False
            j = n - 1
            for i in range(n):
                yi = poly_cells[i, 1]
                yj = poly_cells[j, 1]
                if (yi > cy) != (yj > cy):
                    xi = poly_cells[i, 0]
                    xj = poly_cells[j, 0]
                    if cx < (xj - xi) * (cy - yi) / (yj - yi) + xi:
                        inside = not inside
                j = i
            if inside:
                grid[y, x] = value
