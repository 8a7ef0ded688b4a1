"""Frontier search on an occupancy grid: where the known free space meets the unknown.

Steps (explore_lite's ``FrontierSearch``, vectorised, with path costs and a camera's gain):

1. Cells: free (0 ≤ v ≤ ``free_threshold``), occupied (v ≥ ``occupied_threshold``), unknown
   (v < 0). A *frontier cell* is an unknown cell with a free 4-neighbour; frontier cells are
   grouped 8-connected (`group_frontier_cells` can also join pieces a few cells apart:
   the edge of a narrow scan's view is ragged) and groups shorter than ``min_frontier_size`` (cells × resolution) are
   dropped.
2. Reachable space: free cells at least ``robot_radius`` from every occupied cell (where
   the robot's centre may be). A wavefront (8-connected Dijkstra, numba) from the robot
   gives the path length to each of them.
3. A frontier is reachable when a reachable cell with ``goal_clearance`` from the known
   obstacles lies within that clearance + 2 cells of one of its cells; the nearest such
   cell by path is its *entry*. Its *viewpoint* is the
   reachable cell between ``standoff`` and half the sensor's range from it through known
   free space (the Kinect sees nothing nearer than 0.5 m, nor through walls) that is
   nearest by path, nearer the standoff preferred, facing the heading (towards the
   centroid or one of eight) that shows the most unknown area.
4. Information gain: the unknown area (m²) the camera would see from the viewpoint — rays
   across ``sensor_fov`` between ``sensor_min_range`` and ``sensor_max_range``, stopped by
   occupied cells.
5. Cost = ``potential_scale`` · path length (m) + ``orientation_scale`` · turning (rad)
   − ``gain_scale`` · gain (m²); the lowest cost is explored first.

Grids are `eddiebot.maps.OccupancyMap`; poses are in the grid's frame (m, rad).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import ndimage

from eddiebot.explore.config import ExploreConfig
from eddiebot.maps import OccupancyMap, is_inside, map_to_world, world_to_map

__all__ = [
    "Frontier",
    "FrontierSearch",
    "distance_field",
    "frontier_cells",
    "frontier_cost",
    "group_frontier_cells",
    "information_gain",
    "mark_swept",
    "reachable_mask",
    "search_frontiers",
]

#: Information gain: how fast the view through unknown space fades (per m): unknown cells
#: 1 m into the unknown count 0.61, 2 m in 0.37, 4 m in 0.14.
UNKNOWN_BLOCKING = 0.5
#: Frontier pieces up to 2·this cells apart are one frontier; 0: plain 8-connected groups
#: (joining pieces 2 cells apart explored the house less well in the one run it was tried:
#: docs/benchmarks/explore.md).
_MERGE_GAP_CELLS = 0
#: Viewpoint choice: metres of path worth one metre nearer the standoff distance.
_CLOSER_WEIGHT = 1.5
_EIGHT = np.ones((3, 3), dtype=bool)
_FOUR = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], dtype=bool)


@dataclass(frozen=True)
class Frontier:
    """One frontier: its cells, where the robot goes to look at it, and what it is worth.

    Positions in the grid's frame (m); ``viewpoint`` is (x, y, yaw); ``distance`` is the
    path length from the robot to the viewpoint (m); ``gain`` the unknown area the camera
    would see from there (m²); ``turn`` the turning it takes (rad).
    """

    points: npt.NDArray[np.float64]
    """(N, 2) centres of the frontier cells (m)."""
    size: float
    centroid: tuple[float, float]
    entry: tuple[float, float]
    viewpoint: tuple[float, float, float]
    distance: float
    gain: float
    turn: float
    cost: float


@dataclass(frozen=True)
class FrontierSearch:
    """What one search found: the reachable frontiers (cheapest first) and how many groups
    were dropped as too small or unreachable."""

    frontiers: tuple[Frontier, ...]
    too_small: int
    unreachable: int
    distance: npt.NDArray[np.float64]
    """Path length (m) from the robot to every cell (inf where unreachable)."""


def _classes(grid: OccupancyMap, config: ExploreConfig
             ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    d = grid.data
    free = (d >= 0) & (d <= config.free_threshold)
    occupied = d >= config.occupied_threshold
    unknown = d < 0
    return free, occupied, unknown


def frontier_cells(grid: OccupancyMap, config: ExploreConfig) -> npt.NDArray[np.bool_]:
    """Unknown cells with at least one free 4-neighbour (explore_lite's ``isNewFrontierCell``)."""
    free, _, unknown = _classes(grid, config)
    return unknown & ndimage.binary_dilation(free, structure=_FOUR)


def reachable_mask(grid: OccupancyMap, config: ExploreConfig) -> npt.NDArray[np.bool_]:
    """Free cells whose centre is at least ``robot_radius`` from every occupied cell."""
    free, occupied, _ = _classes(grid, config)
    if not occupied.any():
        return free
    clearance = ndimage.distance_transform_edt(~occupied) * grid.resolution
    return free & (clearance >= config.robot_radius)


@njit(cache=True)
def _heap_push(hc: np.ndarray, hi: np.ndarray, n: int, cost: float, idx: int
               ) -> int:  # pragma: no cover - compiled
    """Push (cost, idx) on the binary min-heap held in ``hc``/``hi[:n]``; the new size."""
    hc[n] = cost
    hi[n] = idx
    j = n
    while j > 0:
        p = (j - 1) // 2
        if hc[p] <= hc[j]:
            break
        hc[p], hc[j] = hc[j], hc[p]
        hi[p], hi[j] = hi[j], hi[p]
        j = p
    return n + 1


@njit(cache=True)
def _dijkstra(passable: np.ndarray, seeds_r: np.ndarray, seeds_c: np.ndarray,
              seed_cost: np.ndarray, seed_label: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    h, w = passable.shape
    dist = np.full((h, w), np.inf)
    label = np.zeros((h, w), dtype=np.int64)
    # binary heap of (cost, flat index)
    cap = h * w * 4 + 16
    hc = np.empty(cap)
    hi = np.empty(cap, dtype=np.int64)
    n = 0
    for k in range(seeds_r.size):
        r, c = seeds_r[k], seeds_c[k]
        if seed_cost[k] < dist[r, c]:
            dist[r, c] = seed_cost[k]
            label[r, c] = seed_label[k]
            n = _heap_push(hc, hi, n, seed_cost[k], r * w + c)
    dr = np.array([-1, -1, -1, 0, 0, 1, 1, 1])
    dc = np.array([-1, 0, 1, -1, 1, -1, 0, 1])
    step = np.array([1.4142135623730951, 1.0, 1.4142135623730951, 1.0, 1.0,
                     1.4142135623730951, 1.0, 1.4142135623730951])
    while n > 0:
        cost = hc[0]
        idx = hi[0]
        n -= 1
        hc[0] = hc[n]
        hi[0] = hi[n]
        j = 0
        while True:
            a = 2 * j + 1
            if a >= n:
                break
            b = a + 1
            m = b if b < n and hc[b] < hc[a] else a
            if hc[j] <= hc[m]:
                break
            hc[m], hc[j] = hc[j], hc[m]
            hi[m], hi[j] = hi[j], hi[m]
            j = m
        r = idx // w
        c = idx % w
        if cost > dist[r, c]:
            continue
        for k in range(8):
            rr = r + dr[k]
            cc = c + dc[k]
            if rr < 0 or cc < 0 or rr >= h or cc >= w or not passable[rr, cc]:
                continue
            nc = cost + step[k]
            if nc < dist[rr, cc]:
                dist[rr, cc] = nc
                label[rr, cc] = label[r, c]
                if n < cap:
                    n = _heap_push(hc, hi, n, nc, rr * w + cc)
    return dist, label


def distance_field(passable: npt.NDArray[np.bool_], start: tuple[int, int],
                   resolution: float, snap_radius_cells: int = 10) -> npt.NDArray[np.float64]:
    """Path length (m, 8-connected) from cell ``start`` = (column, row) through ``passable``
    cells; inf where none leads. A start off the passable cells (the robot inside the
    inflation after a map update) starts from the passable cells within
    ``snap_radius_cells``, each at its straight-line distance."""
    h, w = passable.shape
    c0, r0 = start
    rr, cc = np.mgrid[-snap_radius_cells:snap_radius_cells + 1, -snap_radius_cells:snap_radius_cells + 1]
    rr, cc = rr.ravel() + r0, cc.ravel() + c0
    ok = (rr >= 0) & (cc >= 0) & (rr < h) & (cc < w)
    rr, cc = rr[ok], cc[ok]
    if 0 <= r0 < h and 0 <= c0 < w and passable[r0, c0]:
        seeds_r, seeds_c, cost = np.array([r0]), np.array([c0]), np.zeros(1)
    else:
        keep = passable[rr, cc]
        seeds_r, seeds_c = rr[keep], cc[keep]
        cost = np.hypot(seeds_r - r0, seeds_c - c0).astype(np.float64)
    if seeds_r.size == 0:
        return np.full((h, w), np.inf)
    dist, _ = _dijkstra(np.ascontiguousarray(passable), seeds_r.astype(np.int64),
                        seeds_c.astype(np.int64), cost, np.zeros(seeds_r.size, dtype=np.int64))
    return dist * resolution


def _ray_offsets(config: ExploreConfig, resolution: float) -> tuple[npt.NDArray[np.float64], ...]:
    n_rays = max(3, math.ceil(config.sensor_fov * config.sensor_max_range / resolution) + 1)
    angles = np.linspace(-config.sensor_fov / 2, config.sensor_fov / 2, n_rays)
    ranges = np.arange(0.0, config.sensor_max_range, resolution / 2) + resolution / 2
    return angles, ranges


def information_gain(grid: OccupancyMap, pose: Sequence[float], config: ExploreConfig) -> float:
    """Unknown floor area (m²) the camera at ``pose`` (x, y, yaw in the grid's frame) would
    see: cells on rays across ``sensor_fov`` between ``sensor_min_range`` and
    ``sensor_max_range``, each ray stopped at the first occupied cell and each unknown cell
    weighted by the chance that the unknown cells before it on the ray are not walls."""
    angles, ranges = _ray_offsets(config, grid.resolution)
    x, y, yaw = (float(v) for v in pose)
    a = yaw + angles[:, None]
    pts = np.stack([x + ranges[None, :] * np.cos(a), y + ranges[None, :] * np.sin(a)], axis=-1)
    cells = world_to_map(grid, pts)
    inside = is_inside(grid, cells)
    col = np.where(inside, cells[..., 0], 0)
    row = np.where(inside, cells[..., 1], 0)
    values = np.where(inside, grid.data[row, col].astype(np.int16), 100)
    blocked = np.maximum.accumulate(values >= config.occupied_threshold, axis=1)
    in_range = ranges[None, :] >= config.sensor_min_range
    unknown = values < 0
    # an unknown cell may be a wall: the further a ray has run through unknown space, the
    # less likely it still sees (exp(-UNKNOWN_BLOCKING · metres of unknown before it))
    behind = (np.cumsum(unknown, axis=1) - unknown) * (grid.resolution / 2)
    weight = np.exp(-UNKNOWN_BLOCKING * behind)
    seen_unknown = inside & ~blocked & in_range & unknown
    if not seen_unknown.any():
        return 0.0
    flat = row[seen_unknown] * grid.width + col[seen_unknown]
    best = np.zeros(grid.width * grid.height)
    np.maximum.at(best, flat, weight[seen_unknown])
    return float(best.sum() * grid.resolution**2)


def frontier_cost(distance: float, turn: float, gain: float, config: ExploreConfig) -> float:
    """``potential_scale``·distance (m) + ``orientation_scale``·turn (rad) −
    ``gain_scale``·gain (m²): lower is better."""
    return (config.potential_scale * distance + config.orientation_scale * turn
            - config.gain_scale * gain)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _walk_back(dist: npt.NDArray[np.float64], start: tuple[int, int], cells: npt.NDArray[np.int64],
               standoff_cells: float) -> tuple[int, int]:
    """From ``start`` (row, col) step down the wavefront until the nearest of ``cells``
    (column, row) is ``standoff_cells`` away or the robot is reached."""
    h, w = dist.shape
    r, c = start
    for _ in range(int(4 * standoff_cells) + 4):
        if np.min(np.hypot(cells[:, 0] - c, cells[:, 1] - r)) >= standoff_cells:
            break
        best = (r, c)
        best_d = dist[r, c]
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr, cc = r + dr, c + dc
                if 0 <= rr < h and 0 <= cc < w and dist[rr, cc] < best_d:
                    best, best_d = (rr, cc), dist[rr, cc]
        if best == (r, c):
            break
        r, c = best
    return r, c


def mark_swept(grid: OccupancyMap, positions: npt.ArrayLike, radius: float) -> OccupancyMap:
    """``grid`` with the unknown cells within ``radius`` of ``positions`` (N, 2, map frame, m)
    marked free: the robot's body has been there. The Kinect sees nothing nearer than
    0.5 m, so without this the floor under the start pose stays unknown and is a frontier
    no viewpoint can see."""
    pts = np.asarray(positions, dtype=float).reshape(-1, 2)
    if pts.size == 0:
        return grid
    cells = world_to_map(grid, pts)
    cells = cells[is_inside(grid, cells)]
    if cells.size == 0:
        return grid
    mask = np.zeros(grid.data.shape, dtype=bool)
    mask[cells[:, 1], cells[:, 0]] = True
    r = max(0, int(radius / grid.resolution))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    mask = ndimage.binary_dilation(mask, structure=np.hypot(yy, xx) <= r + 0.5)
    data = grid.data.copy()
    data[mask & (data < 0)] = 0
    return OccupancyMap(data, grid.resolution, grid.origin, grid.frame_id)


def group_frontier_cells(cells: npt.NDArray[np.bool_], gap: int = 0
                         ) -> tuple[npt.NDArray[np.int32], int]:
    """Label frontier cells 8-connected, pieces up to ``gap`` cells apart joined (the edge of
    what a narrow scan saw is ragged: one frontier breaks into short pieces). Returns the
    label image (0 off the frontier cells) and the number of frontiers."""
    joined = ndimage.binary_dilation(cells, structure=_EIGHT, iterations=gap) if gap else cells
    labels, count = ndimage.label(joined, structure=_EIGHT)
    labels = np.where(cells, labels, 0).astype(np.int32)
    present = np.unique(labels[labels > 0])
    if present.size != count:  # (cannot happen: every joined piece holds a frontier cell)
        remap = np.zeros(count + 1, dtype=np.int32)
        remap[present] = np.arange(1, present.size + 1, dtype=np.int32)
        labels, count = remap[labels], int(present.size)
    return labels, int(count)


def _padded(grid: OccupancyMap, passable: npt.NDArray[np.bool_] | None, pad: int
            ) -> tuple[OccupancyMap, npt.NDArray[np.bool_] | None]:
    """``grid`` with ``pad`` unknown cells around it (and ``passable`` with impassable ones)."""
    data = np.pad(grid.data, pad, constant_values=-1)
    yaw = grid.origin[2]
    c, s = math.cos(yaw), math.sin(yaw)
    dx = dy = -pad * grid.resolution
    origin = (grid.origin[0] + c * dx - s * dy, grid.origin[1] + s * dx + c * dy, yaw)
    if passable is not None:
        passable = np.pad(passable, pad, constant_values=False)
    return OccupancyMap(data, grid.resolution, origin, grid.frame_id), passable


def search_frontiers(grid: OccupancyMap, robot: Sequence[float], config: ExploreConfig,
                     passable: npt.NDArray[np.bool_] | None = None,
                     avoid: Sequence[Sequence[float]] = ()) -> FrontierSearch:
    """Every reachable frontier of ``grid`` seen from the robot at ``robot`` (x, y, yaw),
    cheapest first.

    ``passable``: where the robot's centre may go (default `reachable_mask`); a caller with
    a costmap passes its non-lethal, non-inscribed cells here. ``avoid``: spots (x, y) the
    robot could not get to; no goal (viewpoint, entry) lies within ``avoid_radius`` of one.
    The ``distance`` field refers to the grid padded with 2 unknown cells on every side.
    """
    res = grid.resolution
    # the map ends where the scans' end points did: free cells on its border face the
    # unknown beyond it (a corridor seen down its length), so pad it with unknown cells
    pad = 2
    grid, passable = _padded(grid, passable, pad)
    if passable is None:
        passable = reachable_mask(grid, config)
    rx, ry, ryaw = (float(v) for v in robot)
    start = world_to_map(grid, np.array([rx, ry]))
    dist = distance_field(passable, (int(start[0]), int(start[1])), res)
    labels, count = group_frontier_cells(frontier_cells(grid, config), _MERGE_GAP_CELLS)
    if count == 0:
        return FrontierSearch((), 0, 0, dist)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)[1:] * res
    # cells from which the robot can look at a frontier: within its radius + 2 cells
    # goals keep ``goal_clearance`` from known obstacles: the collision monitor and the IR
    # cones slow Eddie to a crawl beside a wall, and the controller gives up
    _, occupied, _ = _classes(grid, config)
    clearance = (ndimage.distance_transform_edt(~occupied) * res if occupied.any()
                 else np.full(occupied.shape, np.inf))
    # ... and keep the robot's footprint off unknown cells, which may hide a wall or a door leaf
    unknown = grid.data < 0
    unknown_clear = (ndimage.distance_transform_edt(~unknown) * res if unknown.any()
                     else np.full(unknown.shape, np.inf))
    goal_ok = (np.isfinite(dist) & (clearance >= config.goal_clearance)
               & (unknown_clear >= config.robot_radius))
    if len(avoid) and config.avoid_radius > 0.0:
        spots = world_to_map(grid, np.asarray(avoid, dtype=np.float64).reshape(-1, 2))
        marks = np.zeros(goal_ok.shape, dtype=bool)
        inside = is_inside(grid, spots)
        marks[spots[inside, 1], spots[inside, 0]] = True
        if marks.any():
            goal_ok &= ndimage.distance_transform_edt(~marks) * res > config.avoid_radius
    reach_cells = max(1, math.ceil(max(config.robot_radius, config.goal_clearance) / res) + 2)
    yy, xx = np.mgrid[-reach_cells:reach_cells + 1, -reach_cells:reach_cells + 1]
    disk = np.hypot(yy, xx) <= reach_cells
    near = ndimage.grey_dilation(labels, footprint=disk)
    access = goal_ok & (near > 0)
    best = np.full(count + 1, np.inf)
    best_flat = np.full(count + 1, -1, dtype=np.int64)
    acc_flat = np.flatnonzero(access)
    if acc_flat.size:
        acc_lab = near.ravel()[acc_flat]
        acc_d = dist.ravel()[acc_flat]
        order = np.lexsort((acc_d, acc_lab))  # by label, then distance
        lab_sorted = acc_lab[order]
        first = np.ones(lab_sorted.size, dtype=bool)
        first[1:] = lab_sorted[1:] != lab_sorted[:-1]
        best[lab_sorted[first]] = acc_d[order][first]
        best_flat[lab_sorted[first]] = acc_flat[order][first]
    # where to stand to look at each frontier: among the reachable cells between the standoff
    # and half the sensor's range from it (the nearest frontier by straight line decides
    # which frontier a cell looks at), the one with the least path length plus
    # _CLOSER_WEIGHT per metre beyond the standoff
    standoff = max(config.standoff, config.sensor_min_range + res)
    view_max = max(standoff + 2 * res, 0.5 * config.sensor_max_range)
    # distance to the nearest frontier through known free space (not through walls: a
    # frontier behind a wall cannot be seen from the other side), and which one it is
    free, _, _ = _classes(grid, config)
    fr, fc = np.nonzero(labels)
    edt, owner = _dijkstra(np.ascontiguousarray(free | (labels > 0)), fr.astype(np.int64),
                           fc.astype(np.int64), np.zeros(fr.size), labels[fr, fc].astype(np.int64))
    edt = edt * res
    candidate = goal_ok & (edt >= standoff) & (edt <= view_max)
    view_d = np.full(count + 1, np.inf)
    view_flat = np.full(count + 1, -1, dtype=np.int64)
    cand_flat = np.flatnonzero(candidate)
    if cand_flat.size:
        c_lab = owner.ravel()[cand_flat]
        # nearer the standoff is better: a step closer costs a step but shows more beyond
        c_d = dist.ravel()[cand_flat] + _CLOSER_WEIGHT * (edt.ravel()[cand_flat] - standoff)
        order = np.lexsort((c_d, c_lab))
        lab_sorted = c_lab[order]
        first = np.ones(lab_sorted.size, dtype=bool)
        first[1:] = lab_sorted[1:] != lab_sorted[:-1]
        view_d[lab_sorted[first]] = c_d[order][first]
        view_flat[lab_sorted[first]] = cand_flat[order][first]
    objects = ndimage.find_objects(labels)
    too_small = unreachable = 0
    found: list[Frontier] = []
    for k in range(1, count + 1):
        if sizes[k - 1] < config.min_frontier_size:
            too_small += 1
            continue
        if not np.isfinite(best[k]):
            unreachable += 1
            continue
        sl = objects[k - 1]
        assert sl is not None
        rows, cols = np.nonzero(labels[sl] == k)
        rows = rows + sl[0].start
        cols = cols + sl[1].start
        cells = np.stack([cols, rows], axis=1).astype(np.int64)
        pts = map_to_world(grid, cells)
        centroid = pts.mean(axis=0)
        er, ec = divmod(int(best_flat[k]), grid.width)
        entry = map_to_world(grid, np.array([[ec, er]]))[0]
        if view_flat[k] >= 0:
            vr, vc = divmod(int(view_flat[k]), grid.width)
        else:
            vr, vc = _walk_back(dist, (er, ec), cells, standoff / res)
        view = map_to_world(grid, np.array([[vc, vr]]))[0]
        # face where the camera sees the most of the unknown: towards the centroid, or
        # one of eight headings
        to_centroid = math.atan2(centroid[1] - view[1], centroid[0] - view[0])
        best_gain, yaw = -1.0, to_centroid
        for heading in (to_centroid, *(k * math.pi / 4 for k in range(-3, 5))):
            g = information_gain(grid, (view[0], view[1], heading), config)
            if g > best_gain + 1e-9:
                best_gain, yaw = g, heading
        gain = best_gain
        travel = float(dist[vr, vc])
        bearing = math.atan2(view[1] - ry, view[0] - rx)
        turn = abs(_wrap(yaw - ryaw)) if travel < 0.3 else (
            abs(_wrap(bearing - ryaw)) + abs(_wrap(yaw - bearing)))
        found.append(Frontier(
            points=pts, size=float(sizes[k - 1]),
            centroid=(float(centroid[0]), float(centroid[1])),
            entry=(float(entry[0]), float(entry[1])),
            viewpoint=(float(view[0]), float(view[1]), yaw),
            distance=travel, gain=gain, turn=turn,
            cost=frontier_cost(travel, turn, gain, config)))
    found.sort(key=lambda f: f.cost)
    return FrontierSearch(tuple(found), too_small, unreachable, dist)
