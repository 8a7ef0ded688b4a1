"""After an arrival the explore node waits for a map that shows what the robot saw."""

from __future__ import annotations

import numpy as np

from eddiebot.explore.node import ExploreNode
from eddiebot.maps import OccupancyMap, map_to_msg


def _send(node: ExploreNode, data: np.ndarray, t: float) -> None:
    node._on_map(map_to_msg(OccupancyMap(data, 0.05), frame_id="map", stamp_ns=round(t * 1e9)))


def test_an_arrival_waits_for_a_changed_map_not_the_same_map_sent_again(node: ExploreNode) -> None:
    # slam_toolbox sends the map every map_update_interval (2 s here) whether or not it
    # changed; the map that counts after an arrival is one that shows the new look
    seen = np.full((40, 40), -1, np.int8)
    seen[:20] = 0
    for t in (0.0, 2.0, 4.0):
        _send(node, seen, t)
    node._fresh_map_after = 4.5  # arrived
    _send(node, seen, 6.0)  # the same map again: the arrival's node is not in it yet
    assert node._waiting_for_map(6.1)
    more = seen.copy()
    more[20:25] = 0
    _send(node, more, 8.0)
    assert not node._waiting_for_map(8.1)


def test_the_wait_ends_after_a_map_period_and_a_half_when_nothing_changes(node: ExploreNode) -> None:
    # a robot that arrives without moving far enough for a new SLAM node: no map will change
    seen = np.zeros((40, 40), np.int8)
    for t in (0.0, 2.0, 4.0):
        _send(node, seen, t)
    node._fresh_map_after = 4.5
    assert node._waiting_for_map(4.5 + 3.4)
    assert not node._waiting_for_map(4.5 + 3.6)  # 1.5 x 2 s + 0.5 s
    # before the period is known, the bound is 10 s
    node._map_period_s = None
    assert node._waiting_for_map(4.5 + 9.0) and not node._waiting_for_map(4.5 + 10.1)
