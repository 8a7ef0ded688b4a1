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
from scipy import ndimage

from eddiebot.explore.config import ExploreConfig
from eddiebot.explore.gain import _pose_gains, information_gain, looked_mask
from eddiebot.explore.wavefront import _dijkstra, distance_field
from eddiebot.maps import OccupancyMap, is_inside, map_to_world, world_to_map

__all__ = [
    "Frontier",
    "FrontierSearch",
    "distance_field",
    "frontier_cells",
    "frontier_cost",
    "group_frontier_cells",
    "information_gain",
    "looked_mask",
    "mark_swept",
    "reachable_mask",
    "search_frontiers",
]

#: Frontier pieces up to 2·this cells apart are one frontier (the edge of what a 57° scan
#: saw is ragged); 0: plain 8-connected groups, as explore_lite.
_MERGE_GAP_CELLS = 1
#: Viewpoint choice: metres of path worth one metre nearer the standoff distance.
_CLOSER_WEIGHT = 1.5
#: Viewpoint choice: candidate spots per frontier, their spacing (m), and the rays a
#: candidate's gain is computed over.
_VIEW_CANDIDATES = 10
_SPOT_SPACING = 0.5
_COARSE_RAYS = 24
#: Viewpoint choice: a pose is a frontier's viewpoint only if it shows at least this share
#: of the most any candidate pose of that frontier shows.
_GAIN_SHARE = 0.5
#: Viewpoint choice after a goal made no progress: a disc this wide (radius, m) where the
#: robot stood blocked; a viewpoint whose shortest path grows by more than this (m) when the
#: disc is closed passes there (grid paths tie, so one beside the disc grows by nothing).
_BLOCK_RADIUS = 0.3
_DETOUR_SLACK = 0.03
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


def frontier_cost(distance: float, turn: float, gain: float, config: ExploreConfig) -> float:
    """``potential_scale``·distance (m) + ``orientation_scale``·turn (rad) −
    ``gain_scale``·gain (m²): lower is better."""
    return (config.potential_scale * distance + config.orientation_scale * turn
            - config.gain_scale * gain)


def _wrap_abs(v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """|angle| wrapped into [0, pi]."""
    return np.abs((v + math.pi) % (2 * math.pi) - math.pi)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _spread(flat: npt.NDArray[np.int64], score: npt.NDArray[np.float64], width: int,
            spacing: float, limit: int) -> list[tuple[int, int]]:
    """Up to ``limit`` of the cells ``flat`` (flat indices into a grid ``width`` wide), the
    best ``score`` first, each at least ``spacing`` cells from those taken: (row, col)."""
    taken: list[tuple[int, int]] = []
    for i in np.argsort(score, kind="stable"):
        r, c = divmod(int(flat[i]), width)
        if all((r - r0) ** 2 + (c - c0) ** 2 >= spacing**2 for r0, c0 in taken):
            taken.append((r, c))
            if len(taken) >= limit:
                break
    return taken


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


def _score_stands(grid: OccupancyMap, stands: list[tuple[int, int]],
                  dist: npt.NDArray[np.float64], centroid: npt.NDArray[np.float64],
                  robot: tuple[float, float, float], config: ExploreConfig,
                  looked_cells: npt.NDArray[np.uint32] | None,
                  ) -> tuple[npt.NDArray[np.float64], ...]:
    """Nine headings at each spot (towards the centroid and every 45°) and their gain, path
    length, turning and frontier cost: (poses (N, 3), gains, travels, turns, costs)."""
    rx, ry, ryaw = robot
    views = map_to_world(grid, np.array([[c, r] for r, c in stands]))
    heads = []
    for view in views:
        to_centroid = math.atan2(centroid[1] - view[1], centroid[0] - view[0])
        for heading in (to_centroid, *(j * math.pi / 4 for j in range(-3, 5))):
            heads.append((view[0], view[1], heading))
    poses = np.array(heads)
    gains = _pose_gains(grid, poses, config, looked_cells, n_rays=_COARSE_RAYS)
    travels = np.repeat([float(dist[r, c]) for r, c in stands], 9)
    bearings = np.arctan2(poses[:, 1] - ry, poses[:, 0] - rx)
    turns = np.where(travels < 0.3, _wrap_abs(poses[:, 2] - ryaw),
                     _wrap_abs(bearings - ryaw) + _wrap_abs(poses[:, 2] - bearings))
    costs = (config.potential_scale * travels + config.orientation_scale * turns
             - config.gain_scale * gains)
    return poses, gains, travels, turns, costs


def search_frontiers(grid: OccupancyMap, robot: Sequence[float], config: ExploreConfig,
                     passable: npt.NDArray[np.bool_] | None = None,
                     avoid: Sequence[Sequence[float]] = (),
                     looked: Sequence[Sequence[float]] | npt.NDArray[np.float64] | None = None,
                     blocked: Sequence[Sequence[float]] = (),
                     obstacles: npt.NDArray[np.bool_] | None = None,
                     near_views: bool = False) -> FrontierSearch:
    """Every reachable frontier of ``grid`` seen from the robot at ``robot`` (x, y, yaw),
    cheapest first.

    ``obstacles``: cells (``grid``'s shape) holding obstacles the map lacks (a costmap's
    lethal cells: what the depth cloud sees below the scan). Goals keep ``goal_clearance``
    (and viewpoints ``preferred_clearance``) from them as from the map's; the wavefront
    still passes them, since a costmap also keeps marks of a person who walked on until a
    ray clears them, and such a trail must not cut the floor in two.

    ``passable``: where the robot's centre may go (default `reachable_mask`); a caller with
    a costmap passes its non-lethal, non-inscribed cells here. ``avoid``: spots (x, y) the
    robot could not get to; no goal (viewpoint, entry) lies within ``avoid_radius`` of one.
    ``near_views``: a frontier that no spot of the standoff band shows anything of is
    looked at from spots nearer than the standoff: a corridor's unknown middle (the
    Kinect's no-return beams along it clear nothing) lies within the standoff of every
    spot beside it and is seen across from there, not along from its end. The explore
    node asks for it only when no frontier would be left to visit without it.
    ``looked``: the robot's poses (N, 3) so far; see `looked_mask`. ``blocked``: spots
    (x, y) where the robot stood blocked on the way to a goal (an obstacle the map does not
    show, below the scan: a chair seen only by the range sensors).

    A frontier's viewpoint is taken, in this order of preference, from the candidate spots
    (a) with ``preferred_clearance`` from known obstacles whose shortest path does not go
    round a ``blocked`` spot by more than ``_DETOUR_SLACK`` (the planner's path to them
    does not pass there), (b) with such a path, (c) with that clearance, (d) any: a spot
    with room on every side is one the controller reaches and turns on without the base's
    range veto or the collision monitor holding it, unlike a spot in a door's gap or
    beside a desk.
    The ``distance`` field refers to the grid padded with 2 unknown cells on every side.
    """
    res = grid.resolution
    # the map ends where the scans' end points did: free cells on its border face the
    # unknown beyond it (a corridor seen down its length), so pad it with unknown cells
    pad = 2
    grid, passable = _padded(grid, passable, pad)
    if obstacles is not None:
        obstacles = np.pad(obstacles, pad, constant_values=False)
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
    if obstacles is not None:
        occupied = occupied | obstacles
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
    # among the frontiers kept: a few unknown cells amid known floor (a scan's gap) are too
    # small to visit, and must not claim the spots that look at a real frontier
    free, _, _ = _classes(grid, config)
    kept = np.concatenate(([False], sizes >= config.min_frontier_size))
    fr, fc = np.nonzero(kept[labels])
    edt, owner = _dijkstra(np.ascontiguousarray(free | (labels > 0)), fr.astype(np.int64),
                           fc.astype(np.int64), np.zeros(fr.size), labels[fr, fc].astype(np.int64))
    edt = edt * res
    candidate = goal_ok & (edt >= standoff) & (edt <= view_max)
    cand_flat = np.flatnonzero(candidate)
    cand_owner = owner.ravel()[cand_flat]
    cand_roomy = clearance.ravel()[cand_flat] >= config.preferred_clearance
    cand_direct = np.ones(cand_flat.size, dtype=bool)
    # spots nearer than the standoff (``near_views``; the gain counts past the sensor's
    # minimum range only)
    near_flat = np.flatnonzero(goal_ok & (edt < standoff)) if near_views else cand_flat[:0]
    near_owner = owner.ravel()[near_flat]
    near_score = dist.ravel()[near_flat] + _CLOSER_WEIGHT * (standoff - edt.ravel()[near_flat])
    if len(blocked):
        spots = world_to_map(grid, np.asarray(blocked, dtype=np.float64).reshape(-1, 2))
        marks = np.zeros(passable.shape, dtype=bool)
        inside = is_inside(grid, spots)
        marks[spots[inside, 1], spots[inside, 0]] = True
        if marks.any():
            around = ndimage.distance_transform_edt(~marks) * res <= _BLOCK_RADIUS
            start_rc = (int(start[0]), int(start[1]))
            detour = distance_field(passable & ~around, start_rc, res)
            cand_direct = (detour.ravel()[cand_flat]
                           <= dist.ravel()[cand_flat] + _DETOUR_SLACK)
    tiers = (cand_roomy & cand_direct, cand_direct, cand_roomy)
    # nearer the standoff is better: a step closer costs a step but shows more beyond
    cand_score = dist.ravel()[cand_flat] + _CLOSER_WEIGHT * (edt.ravel()[cand_flat] - standoff)
    looked_cells = looked_mask(grid, looked, config) if looked is not None and len(looked) else None
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
        # where to stand and which way to face: a few reachable cells at the standoff
        # band, spread out (nearest by path first), each with nine headings, scored by
        # the frontier cost; a spot the camera has looked from along a heading gains
        # nothing more that way (`looked_mask`)
        mine = cand_owner == k
        for tier in tiers:
            if (mine & tier).any():
                mine = mine & tier
                break
        stands = _spread(cand_flat[mine], cand_score[mine], grid.width,
                         _SPOT_SPACING / res, _VIEW_CANDIDATES)
        if not stands:
            stands = [_walk_back(dist, (er, ec), cells, standoff / res)]
        poses, gains, travels, turns, costs = _score_stands(
            grid, stands, dist, centroid, (rx, ry, ryaw), config, looked_cells)
        if float(gains.max()) < config.min_gain and (near_owner == k).any():
            nearer = _spread(near_flat[near_owner == k], near_score[near_owner == k],
                             grid.width, _SPOT_SPACING / res, _VIEW_CANDIDATES)
            alt = _score_stands(grid, nearer, dist, centroid, (rx, ry, ryaw), config,
                                looked_cells)
            if float(alt[1].max()) > float(gains.max()):
                poses, gains, travels, turns, costs = alt
        # a pose that shows nothing is no viewpoint, however near; nor is one that shows
        # little of what another pose shows of the same frontier: the cheapest of those
        # showing at least _GAIN_SHARE of the best gain (else a near spot that sees a
        # sliver wins, the robot drives there, and the frontier stays)
        worth = gains >= max(config.min_gain, _GAIN_SHARE * float(gains.max()))
        j = int(np.argmin(np.where(worth, costs, costs + 1e6)))
        found.append(Frontier(
            points=pts, size=float(sizes[k - 1]),
            centroid=(float(centroid[0]), float(centroid[1])),
            entry=(float(entry[0]), float(entry[1])),
            viewpoint=(float(poses[j, 0]), float(poses[j, 1]), float(poses[j, 2])),
            distance=float(travels[j]), gain=float(gains[j]), turn=float(turns[j]),
            cost=float(costs[j])))
    found.sort(key=lambda f: f.cost)
    return FrontierSearch(tuple(found), too_small, unreachable, dist)
