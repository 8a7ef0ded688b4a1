"""The explore node's way home, on hand-made maps (no simulator)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.explore.node import ExploreNode
from eddiebot.maps import OccupancyMap


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


def test_a_retry_retraces_the_path_driven_while_exploring(node: ExploreNode) -> None:
    # out: 3 m east, then 2 m north (through a door at x = 3); home so far: 1 m back south,
    # then 0.6 m off the driven path to the west, where the controller gave up
    out = [(0.1 * i, 0.0, 0.0) for i in range(31)] + [(3.0, 0.1 * i, 0.0) for i in range(1, 21)]
    node.path = list(out)
    node._outbound = len(out)
    node.path += [(3.0, 2.0 - 0.1 * i, 0.0) for i in range(1, 11)] + [(2.4, 1.0, 0.0)]
    points = node._retrace(2.0)
    # from the driven path's point nearest the robot, (3, 1), towards the start, 1 m apart,
    # each facing the way home along it
    assert [p[:2] for p in points] == [pytest.approx(p, abs=0.11) for p in ((3.0, 0.0), (2.0, 0.0))]
    assert abs(math.remainder(points[0][2] + math.pi / 2, 2 * math.pi)) < 1e-6
    assert abs(abs(points[1][2]) - math.pi) < 1e-6
    assert len(node._retrace(4.0)) == 4
    # far from the driven path: nothing to retrace
    node.path.append((1.5, 1.5, 0.0))
    assert node._retrace(2.0) == []


def test_a_goal_failed_for_want_of_the_robot_pose_keeps_its_frontier(node: ExploreNode) -> None:
    from types import SimpleNamespace

    from eddiebot.explore.frontiers import Frontier

    sent: list = []
    node._send = lambda client, goal, on_result: sent.append(on_result)  # type: ignore[method-assign]
    node.grid = OccupancyMap(np.zeros((40, 40), np.int8), 0.05)
    f = Frontier(points=np.zeros((1, 2)), size=1.0, centroid=(1.5, 1.5), entry=(1.0, 1.0),
                 viewpoint=(1.0, 1.0, 0.0), distance=1.0, gain=2.0, turn=0.0, cost=0.0)

    def fail(code: int) -> None:
        node._go_to(f, 7, 0.0)
        sent[-1](SimpleNamespace(status=6, result=SimpleNamespace(error_code=code)))

    fail(102)  # FollowPath's TF_ERROR: the pose was lost, not the way
    fail(202)  # ComputePathToPose's TF_ERROR
    assert len(node.blacklist) == 0 and node.transient_failures == 2
    assert node._resume_at is not None  # planning again after a pause
    fail(105)  # failed to make progress: the frontier is given up (for now)
    assert len(node.blacklist) == 1 and node.blacklist.contains((1.5, 1.5))


def test_a_goal_given_up_for_no_progress_is_replaced_by_one_away_from_its_spot(
        node: ExploreNode) -> None:
    from types import SimpleNamespace

    d = np.full((100, 200), -1, np.int8)  # a known room, its east side unknown
    d[20:80, 10:100] = 0
    d[20, 10:100] = d[79, 10:100] = 100
    d[20:80, 10] = 100
    node.grid = OccupancyMap(d, 0.05)
    node._send = lambda client, goal, on_result: None  # type: ignore[method-assign]
    pose = (1.0, 2.5, 0.0)
    node._explore(pose, 0.0)
    first = node.goals[-1].viewpoint
    node._goal_handle = SimpleNamespace(cancel_goal_async=lambda: None)
    node._explore(pose, 1.0)  # the robot gets no closer ...
    assert len(node.goals) == 1
    node._explore(pose, 1.0 + node.config.progress_timeout + 1.0)  # ... for progress_timeout
    assert node.goals[0].outcome == "no progress"
    assert len(node.goals) == 2  # a new goal at once, away from the spot given up
    again = node.goals[-1].viewpoint
    assert math.dist(again[:2], first[:2]) > node.config.avoid_radius
