"""The explore node's way home, on hand-made maps (no simulator)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from eddiebot.core.context import Context
from eddiebot.explore.node import ExploreNode
from eddiebot.maps import OccupancyMap


@pytest.fixture
def node() -> Iterator[ExploreNode]:
    context = Context()
    n = ExploreNode(context=context)
    yield n
    n.destroy_node()
    context.shutdown()


def test_an_unseen_start_is_approached_from_a_pose_facing_it(node: ExploreNode) -> None:
    d = np.zeros((80, 80), np.int8)  # 4 x 4 m known free, walls around
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 100
    d[30:50, 30:50] = -1  # the floor under the start (2, 2) never seen
    node.grid = OccupancyMap(d, 0.05)
    node.initial_pose = (2.0, 2.0, 0.0)
    pose = node._staging_pose()
    assert pose is not None
    x, y, yaw = pose
    assert math.hypot(x - 2.0, y - 2.0) == pytest.approx(1.2, abs=0.3)
    assert abs(math.remainder(math.atan2(2.0 - y, 2.0 - x) - yaw, 2 * math.pi)) < 1e-6
    assert d[int(y / 0.05), int(x / 0.05)] == 0  # on known floor
    # a start the map knows as free is driven to directly
    node.grid = OccupancyMap(np.where(d < 0, 0, d).astype(np.int8), 0.05)
    assert node._staging_pose() is None


def test_a_retry_goes_back_along_the_driven_path_first(node: ExploreNode) -> None:
    node.path = [(0.1 * i, 0.0, float(i)) for i in range(31)]  # 3 m east along y = 0
    x, y, yaw = node._path_back()  # type: ignore[misc]
    assert (x, y) == pytest.approx((1.5, 0.0), abs=0.11)
    assert abs(abs(yaw) - math.pi) < 1e-6  # facing the way the robot came
    node.path = node.path[:5]
    assert node._path_back() is None
