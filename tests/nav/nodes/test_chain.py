"""Planner + controller + velocity smoother + collision monitor around the stub robot."""

import math

import numpy as np

from eddiebot.core.action import ActionClient
from eddiebot.msgs.nav2_msgs import ComputePathToPose, FollowPath
from eddiebot.nav.nodes._common import pose_stamped

CHAIN = ("map_server", "planner_server", "controller_server", "velocity_smoother", "collision_monitor")


def _wait(stack, future, limit_s=60.0, step=0.1):
    t = 0.0
    while not future.done() and t < limit_s:
        stack.spin(step)
        t += step
    assert future.done(), "no answer"
    return future.result()


def test_plan_and_follow(make_stack):
    stack = make_stack(servers=CHAIN)
    plan = ActionClient(stack.probe, ComputePathToPose, "/compute_path_to_pose")
    follow = ActionClient(stack.probe, FollowPath, "/follow_path")
    goal = ComputePathToPose.Goal(goal=pose_stamped(4.5, 4.5, 0.0, "map"))
    handle = _wait(stack, plan.send_goal_async(goal))
    assert handle.accepted
    res = _wait(stack, handle.get_result_async())
    assert res.result.error_code == 0, res.result.error_msg
    assert len(res.result.path.poses) > 10
    t0 = stack.probe.now().nanoseconds
    h2 = _wait(stack, follow.send_goal_async(FollowPath.Goal(path=res.result.path)))
    r2 = _wait(stack, h2.get_result_async(), 60.0)
    assert r2.result.error_code == 0, r2.result.error_msg
    x, y, _ = stack.robot.pose
    assert math.hypot(x - 4.5, y - 4.5) < 0.3
    print("follow took", (stack.probe.now().nanoseconds - t0) * 1e-9)



def test_cloud_xyz_reads_float32_fields():
    from eddiebot.msgs.sensor_msgs import PointCloud2, PointField
    from eddiebot.nav.nodes._costmap import cloud_xyz

    pts = np.array([[1.0, 2.0, 3.0, 0.0], [np.nan, 0.0, 0.0, 0.0], [4.0, 5.0, 6.0, 0.0]],
                   dtype=np.float32)
    msg = PointCloud2(height=1, width=3, point_step=16, row_step=48, is_bigendian=False,
                      fields=[PointField(name=n, offset=4 * i, datatype=7, count=1)
                              for i, n in enumerate("xyz")],
                      data=pts.view(np.uint8).reshape(-1))
    assert cloud_xyz(msg).tolist() == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
