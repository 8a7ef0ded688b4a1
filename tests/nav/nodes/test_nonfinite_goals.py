"""NaN / inf goals are refused at once with Nav2's error code, before the robot moves."""

import math

import pytest

from eddiebot.core.action import ActionClient, GoalStatus
from eddiebot.msgs.nav2_msgs import (
    ComputePathThroughPoses,
    ComputePathToPose,
    FollowWaypoints,
    NavigateThroughPoses,
    NavigateToPose,
)
from eddiebot.nav.nodes._common import pose_stamped

NAN, INF = float("nan"), float("inf")
BAD = [(NAN, 1.0, 0.0), (1.0, INF, 0.0), (2.0, 2.0, NAN), (-INF, 1.0, 0.0)]


def _result(stack, client, goal, limit_s=2.0):
    t0 = stack.probe.now().nanoseconds
    future = client.send_goal_async(goal)
    t = 0.0
    while not future.done() and t < limit_s:
        stack.spin(0.05)
        t += 0.05
    handle = future.result()
    assert handle.accepted
    res = handle.get_result_async()
    while not res.done() and t < limit_s:
        stack.spin(0.05)
        t += 0.05
    assert res.done(), "no answer"
    return res.result(), (stack.probe.now().nanoseconds - t0) * 1e-9


@pytest.fixture
def stack(make_stack):
    s = make_stack()
    assert s.manager.system_active
    return s


def test_navigate_to_pose_refuses_non_finite_goals(stack):
    client = ActionClient(stack.probe, NavigateToPose, "/navigate_to_pose")
    for x, y, yaw in BAD:
        res, took = _result(stack, client, NavigateToPose.Goal(pose=pose_stamped(x, y, yaw, "map")))
        assert res.status == GoalStatus.STATUS_ABORTED
        assert res.result.error_code == 204, res.result.error_msg  # GOAL_OUTSIDE_MAP
        assert "not finite" in res.result.error_msg
        assert took < 0.5
    assert math.hypot(*(stack.robot.pose[:2] - stack.robot.start[:2])) < 0.01


def test_navigate_through_poses_refuses_a_non_finite_pose(stack):
    client = ActionClient(stack.probe, NavigateThroughPoses, "/navigate_through_poses")
    goal = NavigateThroughPoses.Goal(poses=[pose_stamped(2.0, 1.0, 0.0, "map"),
                                            pose_stamped(2.0, 2.0, NAN, "map")])
    res, took = _result(stack, client, goal)
    assert res.status == GoalStatus.STATUS_ABORTED
    assert res.result.error_code == 304 and "pose 1" in res.result.error_msg
    assert took < 0.5


def test_follow_waypoints_refuses_non_finite_waypoints(stack):
    client = ActionClient(stack.probe, FollowWaypoints, "/follow_waypoints")
    goal = FollowWaypoints.Goal(poses=[pose_stamped(2.0, 1.0, 0.0, "map"),
                                       pose_stamped(INF, 2.0, 0.0, "map")])
    res, took = _result(stack, client, goal)
    assert res.status == GoalStatus.STATUS_ABORTED
    assert res.result.error_code == 602 and "[1]" in res.result.error_msg  # NO_VALID_WAYPOINTS
    assert took < 0.5
    assert math.hypot(*(stack.robot.pose[:2] - stack.robot.start[:2])) < 0.01


def test_planner_refuses_non_finite_goal_and_start(stack):
    client = ActionClient(stack.probe, ComputePathToPose, "/compute_path_to_pose")
    for x, y, yaw in BAD:
        res, _ = _result(stack, client, ComputePathToPose.Goal(goal=pose_stamped(x, y, yaw, "map")))
        assert res.status == GoalStatus.STATUS_ABORTED
        assert res.result.error_code == 204, res.result.error_msg  # GOAL_OUTSIDE_MAP
    res, _ = _result(stack, client, ComputePathToPose.Goal(
        goal=pose_stamped(2.0, 1.0, 0.0, "map"), start=pose_stamped(NAN, 1.0, 0.0, "map"),
        use_start=True))
    assert res.result.error_code == 203, res.result.error_msg  # START_OUTSIDE_MAP
    through = ActionClient(stack.probe, ComputePathThroughPoses, "/compute_path_through_poses")
    res, _ = _result(stack, through, ComputePathThroughPoses.Goal(
        goals=[pose_stamped(2.0, 1.0, 0.0, "map"), pose_stamped(2.0, INF, 0.0, "map")]))
    assert res.result.error_code == 304, res.result.error_msg
    # a finite goal still plans
    res, _ = _result(stack, client, ComputePathToPose.Goal(goal=pose_stamped(2.0, 1.5, 0.0, "map")))
    assert res.status == GoalStatus.STATUS_SUCCEEDED and len(res.result.path.poses) > 2
