"""The 12 behaviour trees of Nav2 Jazzy's nav2_bt_navigator, as shipped: each loads, and
each runs a goal against the navigation servers and the stub robot."""

import math
from pathlib import Path

import pytest

from _support.nav_actions import wait_for
from eddiebot.core.action import ActionClient, GoalStatus
from eddiebot.msgs.nav2_msgs import NavigateThroughPoses, NavigateToPose
from eddiebot.nav.bt import BehaviorTreeFactory, TreeContext
from eddiebot.nav.bt.factory import parse_xml
from eddiebot.nav.nodes._common import pose_stamped

TREES = Path(__file__).resolve().parents[1] / "data" / "behavior_trees"
FILES = sorted(TREES.glob("*.xml"))
TO_POSE = [f.name for f in FILES if f.name.startswith(("navigate_to", "navigate_w", "nav_to"))]


def _tags(el):
    yield el.tag
    for c in el.children:
        yield from _tags(c)


def test_the_twelve_jazzy_trees_load_and_every_node_type_is_known():
    assert len(FILES) == 12
    factory = BehaviorTreeFactory()
    used = set()
    for f in FILES:
        tree = factory.create_tree_from_file(f, None, TreeContext())
        assert len(tree.nodes) >= 6, f.name
        used |= set(_tags(parse_xml(f.read_text(), str(f)))) - {"root", "BehaviorTree"}
    assert len(used) == 37
    assert used <= set(factory.builders)


def _goal(stack, action, goal, limit_s):
    client = ActionClient(stack.probe, action, "/" + ("navigate_to_pose" if action is
                                                       NavigateToPose else "navigate_through_poses"))
    handle = wait_for(stack, client.send_goal_async(goal))
    assert handle.accepted
    return handle, handle.get_result_async()


def _stack(make_stack, nav_stub_params, **kwargs):
    return make_stack(params=nav_stub_params(), **kwargs)


@pytest.mark.parametrize("name", TO_POSE)
def test_navigate_to_pose_trees_reach_the_goal(make_stack, nav_stub_params, name):
    stack = _stack(make_stack, nav_stub_params)
    goal = NavigateToPose.Goal(pose=pose_stamped(4.5, 1.2, 0.0, "map"),
                               behavior_tree=str(TREES / name))
    _, result = _goal(stack, NavigateToPose, goal, 90.0)
    res = wait_for(stack, result, 90.0)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    assert math.hypot(stack.robot.pose[0] - 4.5, stack.robot.pose[1] - 1.2) < 0.25


def test_navigate_through_poses_tree_passes_each_pose(make_stack, nav_stub_params):
    stack = _stack(make_stack, nav_stub_params)
    poses = [pose_stamped(4.5, 1.0, 0.0, "map"), pose_stamped(4.5, 4.5, math.pi / 2, "map")]
    goal = NavigateThroughPoses.Goal(
        poses=poses, behavior_tree=str(TREES / "navigate_through_poses_w_replanning_and_recovery.xml"))
    _, result = _goal(stack, NavigateThroughPoses, goal, 120.0)
    res = wait_for(stack, result, 120.0)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    assert math.hypot(stack.robot.pose[0] - 4.5, stack.robot.pose[1] - 4.5) < 0.25


def test_follow_point_keeps_following_until_cancelled(make_stack, nav_stub_params):
    stack = _stack(make_stack, nav_stub_params)
    goal = NavigateToPose.Goal(pose=pose_stamped(4.5, 1.0, 0.0, "map"),
                               behavior_tree=str(TREES / "follow_point.xml"))
    handle, result = _goal(stack, NavigateToPose, goal, 60.0)
    stack.spin(25.0)
    assert not result.done()  # KeepRunningUntilFailure: following never "succeeds"
    # TruncatePath distance="1.0": the robot stops about a metre short of the point
    gap = math.hypot(stack.robot.pose[0] - 4.5, stack.robot.pose[1] - 1.0)
    assert 0.6 < gap < 1.4, gap
    wait_for(stack, handle.cancel_goal_async(), 5.0)
    assert wait_for(stack, result, 5.0).status == GoalStatus.STATUS_CANCELED


def test_odometry_calibration_drives_three_squares(make_stack, nav_stub_params):
    stack = _stack(make_stack, nav_stub_params, box=None)
    goal = NavigateToPose.Goal(pose=pose_stamped(1.0, 1.0, 0.0, "map"),
                               behavior_tree=str(TREES / "odometry_calibration.xml"))
    _, result = _goal(stack, NavigateToPose, goal, 400.0)
    # the robot's motion cut into straight drives and turns in place, from its commands
    segments, kind, start = [], None, stack.robot.pose.copy()
    t = 0.0
    while not result.done() and t < 400.0:
        stack.spin(0.25)
        t += 0.25
        v, w = stack.robot.cmd
        now = "drive" if abs(v) > 1e-3 else "spin" if abs(w) > 1e-3 else None
        if now is not None and now != kind:
            if kind is not None:
                segments.append((kind, start, stack.robot.pose.copy()))
            kind, start = now, stack.robot.pose.copy()
    segments.append((kind, start, stack.robot.pose.copy()))
    assert result.done()
    assert result.result().status == GoalStatus.STATUS_SUCCEEDED, result.result().result.error_msg
    drives = [math.hypot(*(b[:2] - a[:2])) for k, a, b in segments if k == "drive"]
    turns = [math.degrees(b[2] - a[2]) for k, a, b in segments if k == "spin"]
    # Repeat num_cycles="3" of four DriveOnHeading 2.0 m and four Spin 1.570796
    assert len(drives) == 12 and len(turns) == 12, (drives, turns)
    assert all(1.9 < d < 2.15 for d in drives), drives
    assert all(80.0 < a < 100.0 for a in turns), turns
    print(f"three squares in {t:.0f} s sim; drives {min(drives):.2f}..{max(drives):.2f} m, "
          f"turns {min(turns):.1f}..{max(turns):.1f} deg")
