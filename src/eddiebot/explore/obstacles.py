"""Obstacles the costmap knows and the SLAM map lacks, added to the grid frontiers are searched on.

The SLAM map is made from the scan, a band of depth rows at the Kinect's height: what stands
lower (the office's 0.45 m chairs) is not in it. The global costmap's obstacle layer marks
from the depth cloud as well (``observation_sources: scan points``), so its lethal cells
hold those obstacles; `add_costmap_obstacles` marks them occupied on a copy of the map, and
the frontier search keeps its goals clear of them (``search_frontiers(obstacles=...)``).
Its wavefront does not take them as walls: the global costmap keeps the marks of a person
walking the corridor until a later ray clears them, and such a trail would cut the floor
in two (office seed 1: the north rooms' frontiers all "unreachable" once the corridor's
walker had left one).
"""

from __future__ import annotations

import math

import numpy as np

from eddiebot.maps import OccupancyMap, is_inside, map_to_world, world_to_map

__all__ = ["LETHAL_OCCUPANCY", "add_costmap_obstacles"]

#: ``nav2_costmap_2d``'s LETHAL_OBSTACLE (254) as published in an OccupancyGrid (100);
#: INSCRIBED_INFLATED_OBSTACLE becomes 99 and is not an obstacle of its own.
LETHAL_OCCUPANCY = 100


def add_costmap_obstacles(grid: OccupancyMap, costmap: OccupancyMap,
                          lethal: int = LETHAL_OCCUPANCY) -> OccupancyMap:
    """``grid`` with every cell holding the centre of a ``costmap`` cell of value ≥ ``lethal``
    marked occupied (100). Both grids are in the same frame (the costmap's ``global_frame``
    is the map's); they may differ in origin, size and resolution (a coarser costmap marks
    the map cells its cell covers). A costmap in another frame, or rotated against the map,
    is an error: the caller chooses which costmap to read."""
    if costmap.frame_id and grid.frame_id and costmap.frame_id != grid.frame_id:
        raise ValueError(f"costmap frame {costmap.frame_id!r} is not the map's "
                         f"({grid.frame_id!r})")
    if abs(math.remainder(costmap.origin[2] - grid.origin[2], 2 * math.pi)) > 1e-6:
        raise ValueError("costmap and map origins are rotated against each other")
    rows, cols = np.nonzero(costmap.data >= lethal)
    if rows.size == 0:
        return grid
    # sub-cells: a costmap cell coarser than the map's covers several map cells
    k = max(1, math.ceil(costmap.resolution / grid.resolution - 1e-9))
    offsets = (np.arange(k) + 0.5) / k - 0.5
    ox, oy = np.meshgrid(offsets, offsets)
    idx = (np.stack([cols, rows], axis=1).astype(float)[:, None, :]
           + np.stack([ox.ravel(), oy.ravel()], axis=1)[None])
    pts = map_to_world(costmap, idx.reshape(-1, 2))
    cells = world_to_map(grid, pts)
    cells = cells[is_inside(grid, cells)]
    if cells.size == 0:
        return grid
    data = grid.data.copy()
    data[cells[:, 1], cells[:, 0]] = 100
    return OccupancyMap(data, grid.resolution, grid.origin, grid.frame_id)
