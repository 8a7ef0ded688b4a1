"""Where the way home goes by: the pure geometry behind the explore node's return to its start.

A failed goal home is tried again by way of the path the robot drove while exploring
(`retrace`: it drove there, the other way) or, away from that path, by way of the point of
its own path a little back (`path_back`); a start whose floor the map does not know as free
is approached from a pose facing it (`staging_pose`: the Kinect sees nothing nearer than
0.5 m, so the spot the robot started on may never have been seen). Paths are lists of
(x, y, t) in the map frame (m, s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from eddiebot.explore.config import ExploreConfig
from eddiebot.maps import OccupancyMap, is_inside, map_to_world, world_to_map

__all__ = ["path_back", "retrace", "staging_pose"]

#: The driven path is retraced from its point nearest the robot when within _RETRACE_NEAR m,
#: by way of points _RETRACE_STEP m apart. Away from it, the point of the robot's own path
#: _PATH_BACK m back.
_RETRACE_STEP = 1.0
_RETRACE_NEAR = 1.0
_PATH_BACK = 1.5
#: A start whose floor the map does not know as free is approached from this far, facing it.
_STAGING_DISTANCE = 1.2

Path = Sequence[tuple[float, float, float]]


def retrace(path: Path, outbound: int, length: float) -> list[tuple[float, float, float]]:
    """Points ``_RETRACE_STEP`` m apart along the path driven while exploring (the first
    ``outbound`` points of ``path``; all when 0), from its point nearest the robot (the last
    point of ``path``) towards the start, ``length`` m of it, each facing the way home along
    it; empty when that path passes no nearer than ``_RETRACE_NEAR`` m."""
    if not path:
        return []
    driven = path[:outbound] if outbound else path
    if len(driven) < 2:
        return []
    x, y, _ = path[-1]
    pts = np.asarray([(px, py) for px, py, _ in driven])
    near = np.hypot(pts[:, 0] - x, pts[:, 1] - y)
    i = int(np.argmin(near))
    if near[i] > _RETRACE_NEAR:
        return []
    out: list[tuple[float, float, float]] = []
    travelled = since = 0.0
    for k in range(i, 0, -1):
        (x0, y0), (x1, y1) = pts[k], pts[k - 1]
        step = math.hypot(x1 - x0, y1 - y0)
        travelled += step
        since += step
        if since >= _RETRACE_STEP or k == 1:
            out.append((float(x1), float(y1), math.atan2(y1 - y0, x1 - x0)))
            since = 0.0
        if travelled >= length:
            break
    return out


def path_back(path: Path) -> tuple[float, float, float] | None:
    """The point of ``path`` ``_PATH_BACK`` m (along it) before its end, facing the way the
    robot came; None on a shorter path."""
    travelled = 0.0
    for (x0, y0, _), (x1, y1, _) in zip(path[::-1], path[-2::-1], strict=False):
        travelled += math.hypot(x1 - x0, y1 - y0)
        if travelled >= _PATH_BACK:
            return x1, y1, math.atan2(y1 - y0, x1 - x0)
    return None


def staging_pose(grid: OccupancyMap, start: tuple[float, float, float],
                 config: ExploreConfig) -> tuple[float, float, float] | None:
    """A reachable pose ``_STAGING_DISTANCE`` m from ``start`` facing it, when ``grid`` does
    not know the start's floor as free; else None."""
    from eddiebot.explore.frontiers import reachable_mask

    sx, sy, _ = start
    cell = world_to_map(grid, np.array([sx, sy]))
    free = (grid.data >= 0) & (grid.data <= config.free_threshold)
    r = max(1, round(config.robot_radius / grid.resolution))
    if is_inside(grid, cell):
        c, rr = int(cell[0]), int(cell[1])
        patch = free[max(0, rr - r):rr + r + 1, max(0, c - r):c + r + 1]
        if patch.size and patch.all():
            return None
    ok = reachable_mask(grid, config)
    rows, cols = np.nonzero(ok)
    if rows.size == 0:
        return None
    pts = map_to_world(grid, np.stack([cols, rows], axis=1))
    d = np.hypot(pts[:, 0] - sx, pts[:, 1] - sy)
    band = np.abs(d - _STAGING_DISTANCE)
    k = int(np.argmin(band))
    if band[k] > 0.5:
        return None
    x, y = float(pts[k, 0]), float(pts[k, 1])
    return x, y, math.atan2(sy - y, sx - x)
