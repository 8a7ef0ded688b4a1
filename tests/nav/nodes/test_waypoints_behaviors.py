"""Waypoint follower (wait and photo tasks), behaviour server actions, the CLI's file parsing."""

import math

import numpy as np
import pytest

from _support.nav_actions import wait_for
from eddiebot.cli.goal import error_name
from eddiebot.cli.waypoints import load_waypoints
from eddiebot.core.action import ActionClient, GoalStatus
from eddiebot.core.time import Duration
from eddiebot.msgs.geometry_msgs import Point
from eddiebot.msgs.nav2_msgs import BackUp, FollowWaypoints, Spin
from eddiebot.msgs.sensor_msgs import Image
from eddiebot.nav.nodes._common import pose_stamped


def test_follows_waypoints_and_saves_photos(make_stack, nav_stub_params, tmp_path):
    doc = nav_stub_params()
    doc["waypoint_follower"] = {"ros__parameters": {
        "waypoint_task_executor_plugin": "snapshot",
        "snapshot": {"plugin": "nav2_waypoint_follower::PhotoAtWaypoint",
                     "camera_image_topic_name": "/image_raw", "save_images_dir": str(tmp_path / "shots"),
                     "image_format": "png", "enabled": True}}}
    stack = make_stack(params=doc)
    img = Image(height=4, width=6, encoding="rgb8", step=18,
                data=np.arange(72, dtype=np.uint8))
    stack.probe.create_publisher(Image, "/image_raw", 1).publish(img)
    client = ActionClient(stack.probe, FollowWaypoints, "/follow_waypoints")
    goal = FollowWaypoints.Goal(poses=[pose_stamped(2.0, 1.0, 0.0, "map"),
                                       pose_stamped(2.0, 2.0, math.pi / 2, "map")])
    handle = wait_for(stack, client.send_goal_async(goal))
    res = wait_for(stack, handle.get_result_async(), 90.0)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    assert len(res.result.missed_waypoints) == 0
    shots = sorted((tmp_path / "shots").glob("*.png"))
    assert [p.name.split("_")[0] for p in shots] == ["0", "1"]
    import cv2

    back = cv2.imread(str(shots[0]))
    assert back.shape == (4, 6, 3) and back[0, 0, 2] == 0 and back[0, 0, 0] == 2  # RGB -> BGR
    assert math.hypot(stack.robot.pose[0] - 2.0, stack.robot.pose[1] - 2.0) < 0.3


def test_input_at_waypoint_waits_and_proceeds_on_input(make_stack, nav_stub_params):
    from eddiebot.msgs.std_msgs import Empty

    doc = nav_stub_params()
    doc["waypoint_follower"] = {"ros__parameters": {
        "stop_on_failure": False, "waypoint_task_executor_plugin": "input",
        "input": {"plugin": "nav2_waypoint_follower/InputAtWaypoint", "timeout": 3.7,
                  "input_topic": "/operator/ok"}}}
    stack = make_stack(params=doc)
    follower = stack.nodes["waypoint_follower"]
    ok = stack.probe.create_publisher(Empty, "/operator/ok", 1)
    client = ActionClient(stack.probe, FollowWaypoints, "/follow_waypoints")
    goal = FollowWaypoints.Goal(poses=[pose_stamped(1.6, 1.0, 0.0, "map"),
                                       pose_stamped(1.6, 1.6, math.pi / 2, "map")])
    handle = wait_for(stack, client.send_goal_async(goal))
    t = 0.0
    while follower.waiting_at is None and t < 60.0:
        stack.spin(0.1)
        t += 0.1
    assert follower.waiting_at == 0
    stack.spin(2.5)  # no input yet: still holding at waypoint 0, not moving on
    assert follower.waiting_at == 0
    ok.publish(Empty())
    stack.spin(0.3)
    assert follower.waiting_at is None
    # Waypoint 1 gets no input: after timeout (3 s: whole seconds, as upstream) it is missed
    # with TASK_EXECUTOR_FAILED and the run, not stopping on failure, succeeds.
    while follower.waiting_at is None and t < 120.0:
        stack.spin(0.1)
        t += 0.1
    assert follower.waiting_at == 1
    start = stack.nodes["waypoint_follower"].now().nanoseconds
    res = wait_for(stack, handle.get_result_async(), 30.0)
    waited = (stack.nodes["waypoint_follower"].now().nanoseconds - start) * 1e-9
    assert 2.8 <= waited <= 3.5
    assert res.status == GoalStatus.STATUS_SUCCEEDED
    assert [(m.index, m.error_code) for m in res.result.missed_waypoints] == \
        [(1, FollowWaypoints.Result.TASK_EXECUTOR_FAILED)]
    assert math.hypot(stack.robot.pose[0] - 1.6, stack.robot.pose[1] - 1.6) < 0.3


def test_spin_and_backup_behaviours(make_stack):
    stack = make_stack(servers=("controller_server", "behavior_server", "velocity_smoother",
                                "collision_monitor"), start=(3.0, 1.0, 0.0))
    stack.spin(1.0)  # local costmap published
    spin = ActionClient(stack.probe, Spin, "/spin")
    h = wait_for(stack, spin.send_goal_async(Spin.Goal(
        target_yaw=math.pi / 2, time_allowance=Duration.from_seconds(10).to_msg())))
    r = wait_for(stack, h.get_result_async(), 15.0)
    assert r.status == GoalStatus.STATUS_SUCCEEDED
    assert abs(math.remainder(stack.robot.pose[2] - math.pi / 2, 2 * math.pi)) < 0.15
    # back up towards the south wall (y = 0.1): 0.3 m is fine, 1.0 m would collide
    backup = ActionClient(stack.probe, BackUp, "/backup")
    h = wait_for(stack, backup.send_goal_async(BackUp.Goal(
        target=Point(x=-0.3, y=0.0, z=0.0), speed=0.1,
        time_allowance=Duration.from_seconds(10).to_msg())))
    r = wait_for(stack, h.get_result_async(), 15.0)
    assert r.status == GoalStatus.STATUS_SUCCEEDED, r.result.error_msg
    assert stack.robot.pose[1] == pytest.approx(0.7, abs=0.08)
    h = wait_for(stack, backup.send_goal_async(BackUp.Goal(
        target=Point(x=-1.0, y=0.0, z=0.0), speed=0.1,
        time_allowance=Duration.from_seconds(10).to_msg())))
    r = wait_for(stack, h.get_result_async(), 15.0)
    assert r.status == GoalStatus.STATUS_ABORTED
    assert r.result.error_code == BackUp.Result.COLLISION_AHEAD
    assert stack.robot.pose[1] > 0.1 + 0.23  # never touched the wall
    stack.spin(1.0)
    assert stack.robot.cmd == (0.0, 0.0)


def test_waypoint_file_and_error_names(tmp_path):
    f = tmp_path / "w.yaml"
    f.write_text("- {x: 1, y: 2}\n- {x: 3, y: 4, yaw: 1.5}\n")
    assert load_waypoints(f) == [(1.0, 2.0, 0.0, "map"), (3.0, 4.0, 1.5, "map")]
    f.write_text("- {x: 1}\n")
    with pytest.raises(ValueError, match="waypoint 0 needs x and y"):
        load_waypoints(f)
    assert error_name(206) == "GOAL_OCCUPIED"
    assert error_name(102) == "TF_ERROR"
