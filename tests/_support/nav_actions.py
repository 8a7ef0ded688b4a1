"""Waiting on the stub navigation stack's futures, and a NavigateToPose goal sent and awaited."""

from eddiebot.core.action import ActionClient
from eddiebot.msgs.nav2_msgs import NavigateToPose
from eddiebot.nav.nodes._common import pose_stamped


def wait_for(stack, future, limit_s=60.0, step=0.1):
    t = 0.0
    while not future.done() and t < limit_s:
        stack.spin(step)
        t += step
    assert future.done(), f"no answer within {limit_s} s"
    return future.result()


def navigate(stack, x, y, yaw, limit_s=90.0, feedback=None):
    client = ActionClient(stack.probe, NavigateToPose, "/navigate_to_pose")
    handle = wait_for(stack, client.send_goal_async(
        NavigateToPose.Goal(pose=pose_stamped(x, y, yaw, "map")),
        feedback_callback=(feedback.append if feedback is not None else None)))
    assert handle.accepted
    return handle, wait_for(stack, handle.get_result_async(), limit_s)
