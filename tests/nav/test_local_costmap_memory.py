"""Eddie's local costmap keeps the walls beside and behind the robot through a clear.

The default BT's FollowPath recovery clears the whole local costmap
(``ClearEntireCostmap`` on ``local_costmap/clear_entirely_local_costmap``) and its
recoveries back up. Eddie's sensors all look ahead (Kinect 57°, PING))) and IR at ±45° at
most), so an obstacle layer alone never sees again the jamb the robot has just passed: in the
office's kitchen door MPPI then backed into the west jamb at (16.06, 8.56) with the local
costmap holding no lethal cell within 0.47 m of the robot (docs/benchmarks/nav.md#nav-worlds-maps).
The map's walls come back with the static layer."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from eddiebot.nav.config import load_nav2_config
from eddiebot.nav.costmap.footprint import transform_footprint
from eddiebot.nav.costmap.layers.obstacle import ObstacleLayer, scan_observation
from eddiebot.sim.ground_truth import footprint_map
from eddiebot.sim.worlds import load_world

CONFIG = Path(__file__).resolve().parents[2] / "config" / "nav2.yaml"
#: in the kitchen door, facing east-south-east, 0.07 m from the west jamb's corner behind it
POSE = (16.355, 8.548, -0.24)
JAMB = (16.06, 8.56)


def _lethal_near(cm, x: float, y: float, radius: float) -> int:
    m = cm.master
    rows, cols = np.nonzero(m.data >= 254)
    wx = m.origin_x + (cols + 0.5) * m.resolution
    wy = m.origin_y + (rows + 0.5) * m.resolution
    return int(np.count_nonzero(np.hypot(wx - x, wy - y) < radius))


def _backup_hits_lethal(cm, distance: float = 0.15) -> bool:
    """The BackUp behaviour's check: the footprint outline over a lethal cell on the way."""
    m = cm.master
    x, y, yaw = POSE
    for s in np.arange(0.0, distance + 1e-9, 0.01):
        pose = (x - s * math.cos(yaw), y - s * math.sin(yaw), yaw)
        for px, py in transform_footprint(pose, cm.footprint):
            c = m.world_to_map(float(px), float(py))
            if c is not None and m.get_cost(*c) >= 254:
                return True
    return False


def test_walls_behind_survive_a_clear_entirely() -> None:
    cm = load_nav2_config(CONFIG).local_costmap
    assert cm is not None
    cm.set_static_map(footprint_map(load_world("office")))  # what /map delivers
    cm.update_map(POSE)
    # the Kinect's scan ahead: the corridor's far wall 2 m off, nothing near
    x, y, yaw = POSE
    scan = scan_observation(np.full(60, 2.0), -0.5, 1.0 / 60, 0.45, 4.0,
                            (x + 0.1 * math.cos(yaw), y + 0.1 * math.sin(yaw), 0.61, yaw))
    for layer in cm.layers:
        if isinstance(layer, ObstacleLayer):
            layer.add_observation("scan", scan)
    cm.update_map(POSE)
    cm.clear_entirely()
    cm.update_map(POSE)
    # the jamb's corner cells are back as lethal, and the BackUp check sees them (0.15 m back)
    assert _lethal_near(cm, *JAMB, 0.08) >= 3
    assert _backup_hits_lethal(cm)
