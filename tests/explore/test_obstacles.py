"""Costmap obstacles on the frontier search's grid: the depth cloud's chairs, below the scan."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from eddiebot.explore import ExploreConfig, search_frontiers
from eddiebot.explore.mission import CLOUD_SOURCE, _add_cloud_source
from eddiebot.explore.obstacles import add_costmap_obstacles
from eddiebot.maps import OccupancyMap

RES = 0.05


def room() -> OccupancyMap:
    """A known 4.45 x 2.9 m room (cols 11..99, rows 21..78) open to the unknown east."""
    d = np.full((100, 200), -1, np.int8)
    d[20:80, 10:100] = 0
    d[20, 10:100] = 100
    d[79, 10:100] = 100
    d[20:80, 10] = 100
    return OccupancyMap(d, RES, (0.0, 0.0, 0.0))


def costmap_with(cells: list[tuple[float, float]], value: int = 100, res: float = RES,
                 origin: tuple[float, float] = (-1.0, -0.5)) -> OccupancyMap:
    """A 12 x 8 m costmap, free but for ``value`` at the cells holding the points (m)."""
    d = np.zeros((int(8 / res), int(12 / res)), np.int8)
    for x, y in cells:
        d[int((y - origin[1]) / res), int((x - origin[0]) / res)] = value
    return OccupancyMap(d, res, (origin[0], origin[1], 0.0))


def test_lethal_costmap_cells_become_occupied_map_cells() -> None:
    grid = room()
    out = add_costmap_obstacles(grid, costmap_with([(3.02, 2.03), (3.52, 2.03)]))
    changed = np.argwhere(out.data != grid.data)
    assert sorted(map(tuple, changed)) == [(40, 60), (40, 70)]  # (row, col): 2.0 / 0.05
    assert out.data[40, 60] == 100
    # inscribed-inflated (99) and lower costs are not obstacles of their own
    assert add_costmap_obstacles(grid, costmap_with([(3.02, 2.03)], value=99)) is grid


def test_a_coarser_costmap_cell_marks_every_map_cell_it_covers() -> None:
    grid = room()
    out = add_costmap_obstacles(grid, costmap_with([(3.05, 2.05)], res=0.1, origin=(-1.0, -0.5)))
    rows, cols = np.nonzero(out.data != grid.data)
    assert (sorted(set(rows)), sorted(set(cols))) == ([40, 41], [60, 61])


def test_a_costmap_in_another_frame_is_refused() -> None:
    cm = costmap_with([(3.0, 2.0)])
    odom = OccupancyMap(cm.data, cm.resolution, cm.origin, frame_id="odom")
    with pytest.raises(ValueError, match="odom"):
        add_costmap_obstacles(room(), odom)


def test_viewpoints_keep_clear_of_an_obstacle_only_the_costmap_has() -> None:
    grid = room()
    config = ExploreConfig()
    robot = (1.0, 2.0, 0.0)
    before = search_frontiers(grid, robot, config).frontiers[0]
    vx, vy = before.viewpoint[:2]
    # a 0.45 m chair standing on the viewpoint the map alone gives
    chair = [(vx + dx, vy + dy) for dx in np.arange(-0.2, 0.25, RES) for dy in np.arange(-0.2, 0.25, RES)]
    merged = add_costmap_obstacles(grid, costmap_with(chair))
    after = search_frontiers(grid, robot, config, obstacles=merged.data >= 65).frontiers[0]
    clearance = ndimage.distance_transform_edt(merged.data < 65) * RES
    col, row = int(after.viewpoint[0] / RES), int(after.viewpoint[1] / RES)
    assert clearance[row, col] >= config.goal_clearance - 1e-9
    assert math.hypot(after.viewpoint[0] - vx, after.viewpoint[1] - vy) >= config.goal_clearance
    # without the costmap the same spot is still chosen: the chair made the difference
    assert search_frontiers(grid, robot, config).frontiers[0].viewpoint == before.viewpoint


def test_the_global_costmap_gets_the_depth_cloud_once() -> None:
    cm = {"plugins": ["static_layer", "obstacle_layer", "inflation_layer"],
          "static_layer": {"plugin": "nav2_costmap_2d::StaticLayer"},
          "obstacle_layer": {"plugin": "nav2_costmap_2d::ObstacleLayer",
                             "observation_sources": "scan", "scan": {"topic": "/scan"}}}
    _add_cloud_source(cm)
    layer = cm["obstacle_layer"]
    assert layer["observation_sources"] == "scan points"
    assert layer["points"] == CLOUD_SOURCE
    assert layer["points"]["max_obstacle_height"] < 0.70  # under the table tops
    _add_cloud_source(cm)
    assert layer["observation_sources"] == "scan points"
    # a costmap with a cloud source of its own keeps it
    voxel = {"plugins": ["voxel_layer"], "voxel_layer": {
        "plugin": "nav2_costmap_2d::VoxelLayer", "observation_sources": "cam",
        "cam": {"data_type": "PointCloud2", "topic": "/camera/points"}}}
    _add_cloud_source(voxel)
    assert voxel["voxel_layer"]["observation_sources"] == "cam"


def test_a_trail_of_costmap_marks_across_the_room_leaves_the_frontier_reachable() -> None:
    grid = room()
    config = ExploreConfig()
    robot = (1.0, 2.0, 0.0)
    # a person's marks left across the whole room, 2.5 m east of the robot
    trail = [(3.5, y) for y in np.arange(1.05, 3.95, RES)]
    marks = add_costmap_obstacles(grid, costmap_with(trail)).data >= 65
    search = search_frontiers(grid, robot, config, obstacles=marks)
    assert len(search.frontiers) == 1 and search.unreachable == 0
    f = search.frontiers[0]
    assert abs(f.viewpoint[0] - 3.5) >= config.goal_clearance - 1e-9
    # as walls on the map, the marks cut the room in two
    walled = search_frontiers(add_costmap_obstacles(grid, costmap_with(trail)), robot, config)
    assert len(walled.frontiers) == 0 and walled.unreachable == 1
