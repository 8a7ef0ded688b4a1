"""NavFn on a winding path longer than upstream's descent bound (4 x the larger map side)."""

from __future__ import annotations

import numpy as np
from navtest_helpers import make_costmap

from eddiebot.nav.planners import NavfnConfig, NavfnPlanner
from eddiebot.nav.types import path_length


def test_serpentine_path_is_extracted_whole() -> None:
    # 6 m x 6 m at 0.05 m: walls at 2 m and 4 m with gaps at alternate ends -> a serpentine of
    # three 5.5 m legs (about 19 m, 380 cells), where upstream's bound stops the descent after
    # 4 x 120 cycles of half a cell (240 cells)
    occ = np.zeros((120, 120), dtype=np.int8)
    occ[[0, -1], :] = 100
    occ[:, [0, -1]] = 100
    occ[40, :110] = 100
    occ[80, 10:] = 100
    cm = make_costmap(occ, robot_radius=0.1, inflation_radius=0.2)
    start, goal = (0.5, 0.5, 0.0), (5.5, 5.5, 0.0)
    path = NavfnPlanner(NavfnConfig(tolerance=0.0)).create_plan(start, goal, cm.master)
    assert np.hypot(*(path[0, :2] - start[:2])) < 0.1
    assert np.hypot(*(path[-1, :2] - goal[:2])) < 0.1
    assert 16.0 < path_length(path) < 22.0
    # never through a wall
    cells = np.floor(path[:, :2] / 0.05).astype(int)
    assert not occ[cells[:, 1], cells[:, 0]].any()
