"""bt_navigator running Nav2's own XML trees against the navigation servers and the stub
robot: a goal reached with 1 Hz replanning, the recovery branch when the controller fails,
a goal's ``behavior_tree``, and tree files that do not load."""

import math
from pathlib import Path

from _support.nav_actions import wait_for
from eddiebot.core import Context
from eddiebot.core.action import ActionClient, GoalStatus
from eddiebot.core.lifecycle import TransitionCallbackReturn
from eddiebot.msgs.nav2_msgs import NavigateToPose
from eddiebot.nav.nodes._common import pose_stamped
from eddiebot.nav.nodes.bt_navigator import BtNavigator

TREES = Path(__file__).resolve().parents[1] / "data" / "behavior_trees"
DEFAULT = TREES / "navigate_to_pose_w_replanning_and_recovery.xml"


def _params(nav_stub_params, **bt):
    doc = nav_stub_params()
    section = doc.setdefault("bt_navigator", {}).setdefault("ros__parameters", {})
    section.update({"default_nav_to_pose_bt_xml": str(DEFAULT), **bt})
    return doc


def _run_goal(stack, x, y, yaw, tree="", limit_s=120.0):
    """Send a goal and spin in 0.1 s steps until its result, counting the distinct paths
    the tree put on its blackboard and the feedback."""
    nav = stack.nodes["bt_navigator"]
    client = ActionClient(stack.probe, NavigateToPose, "/navigate_to_pose")
    fb = []
    handle = wait_for(stack, client.send_goal_async(
        NavigateToPose.Goal(pose=pose_stamped(x, y, yaw, "map"), behavior_tree=tree),
        feedback_callback=fb.append))
    assert handle.accepted
    result = handle.get_result_async()
    paths, last = 0, None
    t0 = stack.probe.now().nanoseconds
    t = 0.0
    while not result.done() and t < limit_s:
        stack.spin(0.1)
        t += 0.1
        bb = nav.blackboard
        path = bb.get("path") if bb is not None else None
        if path is not None and path is not last and path.poses:
            paths += 1
            last = path
    assert result.done(), f"no result within {limit_s} s"
    took = (stack.probe.now().nanoseconds - t0) * 1e-9
    return result.result(), fb, paths, took


def test_nav2_default_tree_reaches_goal_replanning_at_1hz(make_stack, nav_stub_params):
    stack = make_stack(params=_params(nav_stub_params))
    assert stack.manager.system_active
    res, fb, paths, took = _run_goal(stack, 4.5, 4.5, math.pi / 2)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    assert math.hypot(stack.robot.pose[0] - 4.5, stack.robot.pose[1] - 4.5) < 0.25
    rate = paths / took
    print(f"reached in {took:.1f} s sim with {paths} plans ({rate:.2f} Hz)")
    assert took > 5.0
    assert 0.7 <= rate <= 1.2  # RateController hz="1.0"
    assert fb[-1].feedback.number_of_recoveries == 0
    assert max(f.feedback.distance_remaining for f in fb) > 4.0


def test_recovery_branch_runs_when_the_controller_fails(make_stack, nav_stub_params):
    doc = _params(nav_stub_params)
    pc = doc["controller_server"]["ros__parameters"]["progress_checker"]
    pc["movement_time_allowance"] = 2.0
    stack = make_stack(params=doc)
    stack.robot.block_forward = True  # turns in place and backs up, never advances
    res, fb, paths, took = _run_goal(stack, 4.5, 1.0, 0.0, limit_s=200.0)
    assert res.status == GoalStatus.STATUS_ABORTED
    assert res.result.error_code == 105, res.result.error_msg  # FAILED_TO_MAKE_PROGRESS
    recoveries = [f.feedback.number_of_recoveries for f in fb]
    print(f"aborted after {took:.1f} s sim, {recoveries[-1]} recoveries, {paths} plans")
    assert recoveries == sorted(recoveries)
    # six rounds of the RoundRobin: clear, Spin, Wait, BackUp, clear, Spin; Nav2 counts
    # Spin, Wait and BackUp
    assert recoveries[-1] == 4
    assert paths >= 7  # at least one plan per attempt of the pipeline


def test_goal_behavior_tree_field_selects_the_tree(make_stack, nav_stub_params):
    stack = make_stack(params=_params(nav_stub_params))
    res, _, paths, took = _run_goal(stack, 4.5, 1.0, 0.0,
                                    tree=str(TREES / "navigate_w_replanning_distance.xml"))
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    nav = stack.nodes["bt_navigator"]
    assert nav.blackboard is not None
    assert nav._trees["navigate_to_pose"][0].name == "navigate_w_replanning_distance.xml"
    # DistanceController distance="1.0" on a 3.5 m drive: the first plan and one a metre
    assert 3 <= paths <= 5


def test_goal_naming_a_missing_tree_is_aborted(make_stack, nav_stub_params):
    stack = make_stack(params=_params(nav_stub_params))
    res, _, _, _ = _run_goal(stack, 2.0, 1.0, 0.0, tree="/no/such/tree.xml", limit_s=5.0)
    assert res.status == GoalStatus.STATUS_ABORTED
    assert "/no/such/tree.xml: behaviour tree file not found" in res.result.error_msg
    assert math.hypot(*(stack.robot.pose[:2] - stack.robot.start[:2])) < 0.01


def test_misspelt_node_fails_configure_with_file_and_line(tmp_path):
    text = DEFAULT.read_text().replace('<Spin spin_dist="1.57"', '<Spinn spin_dist="1.57"')
    bad = tmp_path / "bad.xml"
    bad.write_text(text)
    line = next(i for i, s in enumerate(text.splitlines(), 1) if "<Spinn" in s)
    ctx = Context()
    try:
        nav = BtNavigator(context=ctx, parameter_overrides={"default_nav_to_pose_bt_xml": str(bad)})
        assert nav.trigger_configure() == TransitionCallbackReturn.FAILURE
        assert f"{bad}:{line}: unknown node type 'Spinn'; did you mean 'Spin'?" in nav.last_error
        port = tmp_path / "port.xml"
        port.write_text(DEFAULT.read_text().replace('wait_duration="5.0"', 'wait_durration="5.0"'))
        nav2 = BtNavigator("bt_navigator_2", context=ctx,
                           parameter_overrides={"default_nav_through_poses_bt_xml": str(port)})
        assert nav2.trigger_configure() == TransitionCallbackReturn.FAILURE
        assert "Wait: unknown port 'wait_durration'; did you mean 'wait_duration'?" \
            in nav2.last_error
        assert nav2.last_error.count(str(port)) == 1
    finally:
        ctx.shutdown()


def test_goal_waits_for_the_robot_pose_then_aborts(make_stack, nav_stub_params):
    stack = make_stack(params=_params(nav_stub_params, initial_pose_timeout=2.0))
    stack.robot.publish_tf = False  # odom -> base_footprint goes stale: no robot pose
    stack.spin(1.0)
    client = ActionClient(stack.probe, NavigateToPose, "/navigate_to_pose")
    # localisation comes back within initial_pose_timeout: the goal runs
    handle = wait_for(stack, client.send_goal_async(
        NavigateToPose.Goal(pose=pose_stamped(2.5, 1.0, 0.0, "map"))))
    stack.spin(1.0)
    stack.robot.publish_tf = True
    res = wait_for(stack, handle.get_result_async(), 60.0)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    # it does not: aborted with Nav2's reason after the timeout
    stack.robot.publish_tf = False
    stack.spin(1.0)
    t0 = stack.probe.now().nanoseconds
    handle = wait_for(stack, client.send_goal_async(
        NavigateToPose.Goal(pose=pose_stamped(1.0, 1.0, 0.0, "map"))))
    res = wait_for(stack, handle.get_result_async(), 10.0)
    took = (stack.probe.now().nanoseconds - t0) * 1e-9
    assert res.status == GoalStatus.STATUS_ABORTED
    assert "initial robot pose is not available (map -> base_footprint)" in res.result.error_msg
    assert 2.0 <= took < 3.0
