import time

import pytest

from eddiebot.core import Context, Duration, Node, SingleThreadedExecutor
from eddiebot.core.action import (
    ActionClient,
    ActionServer,
    CancelResponse,
    GoalResponse,
    GoalStatus,
    sleep,
)
from eddiebot.msgs import get_action
from eddiebot.msgs.action_msgs import GoalStatusArray

Wait = get_action("nav2_msgs/action/Wait")
Spin = get_action("nav2_msgs/action/Spin")
S = 1_000_000_000


@pytest.fixture
def ctx():
    c = Context(use_sim_time=True)
    yield c
    c.shutdown()


def _wait_goal(seconds):
    return Wait.Goal(time=Duration.from_seconds(seconds).to_msg())


def _make_wait_server(node, **kwargs):
    """A coroutine server that waits goal.time on the node clock, feedback every second."""

    async def execute(handle):
        total = Duration.from_msg(handle.request.time).nanoseconds
        start = node.now().nanoseconds
        while node.now().nanoseconds - start < total:
            if handle.is_cancel_requested:
                handle.canceled()
                return Wait.Result(error_msg="canceled")
            left = total - (node.now().nanoseconds - start)
            handle.publish_feedback(Wait.Feedback(time_left=Duration(left).to_msg()))
            await sleep(node, min(1.0, left / S))
        handle.succeed()
        return Wait.Result(total_elapsed_time=Duration(node.now().nanoseconds - start).to_msg())

    return ActionServer(node, Wait, "wait", execute, **kwargs)


def test_wire_layout_matches_ros2(ctx):
    node = Node("behavior_server", namespace="robot", context=ctx)
    _make_wait_server(node)
    assert {"/robot/wait/_action/send_goal", "/robot/wait/_action/cancel_goal",
            "/robot/wait/_action/get_result"} <= set(ctx.services)
    assert "/robot/wait/_action/feedback" in ctx.topics
    assert ctx.topics["/robot/wait/_action/feedback"].type_name == "nav2_msgs/action/Wait_FeedbackMessage"
    assert ctx.topics["/robot/wait/_action/status"].type_name == "action_msgs/msg/GoalStatusArray"


def test_coroutine_goal_on_sim_time_feedback_and_result(ctx):
    ex = SingleThreadedExecutor(context=ctx)
    server_node = Node("server", context=ctx)
    client_node = Node("client", context=ctx)
    _make_wait_server(server_node)
    client = ActionClient(client_node, Wait, "wait")
    ex.add_node(server_node)
    ex.add_node(client_node)
    assert client.wait_for_server(timeout_sec=0.1)
    statuses = []
    client_node.create_subscription(
        GoalStatusArray, "/wait/_action/status",
        lambda m: statuses.extend(int(s.status) for s in m.status_list[-1:]), 10)
    feedback = []
    t0 = time.monotonic()
    goal_future = client.send_goal_async(_wait_goal(10.0), feedback_callback=feedback.append)
    ex.spin_until_future_complete(goal_future, timeout_sec=5)
    handle = goal_future.result()
    assert handle.accepted
    result_future = handle.get_result_async()
    ex.spin_until_future_complete(result_future, timeout_sec=5)
    wall = time.monotonic() - t0
    response = result_future.result()
    assert response.status == GoalStatus.STATUS_SUCCEEDED
    assert Duration.from_msg(response.result.total_elapsed_time).to_seconds() == pytest.approx(10.0)
    assert ctx.sim_clock.now_ns() == 10 * S
    assert wall < 2.0  # ten simulated seconds, no wall sleeping
    assert [round(Duration.from_msg(f.feedback.time_left).to_seconds()) for f in feedback] == list(
        range(10, 0, -1))
    assert handle.status == GoalStatus.STATUS_SUCCEEDED
    ex.spin_until_idle()
    assert statuses[0] == GoalStatus.STATUS_ACCEPTED
    assert GoalStatus.STATUS_EXECUTING in statuses
    assert statuses[-1] == GoalStatus.STATUS_SUCCEEDED


def test_goal_rejected(ctx):
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("n", context=ctx)
    seen = []

    def goal_cb(goal):
        seen.append(goal)
        return GoalResponse.REJECT if Duration.from_msg(goal.time).to_seconds() > 5 else GoalResponse.ACCEPT

    _make_wait_server(node, goal_callback=goal_cb)
    client = ActionClient(node, Wait, "wait")
    ex.add_node(node)
    assert client.send_goal(_wait_goal(60.0)) is None
    response = client.send_goal(_wait_goal(2.0))
    assert response.status == GoalStatus.STATUS_SUCCEEDED
    assert len(seen) == 2


def test_cancel_accepted_and_rejected(ctx):
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("n", context=ctx)
    allow = {"cancel": False}
    _make_wait_server(node, cancel_callback=lambda h: CancelResponse.ACCEPT if allow["cancel"]
                      else CancelResponse.REJECT)
    client = ActionClient(node, Wait, "wait")
    ex.add_node(node)
    f = client.send_goal_async(_wait_goal(30.0))
    ex.spin_until_future_complete(f)
    handle = f.result()
    ex.spin_for(2.0)
    cancel = handle.cancel_goal_async()
    ex.spin_until_future_complete(cancel)
    assert cancel.result().return_code == 1  # ERROR_REJECTED
    allow["cancel"] = True
    cancel = handle.cancel_goal_async()
    ex.spin_until_future_complete(cancel)
    assert cancel.result().return_code == 0
    assert len(cancel.result().goals_canceling) == 1
    result = handle.get_result_async()
    ex.spin_until_future_complete(result)
    assert result.result().status == GoalStatus.STATUS_CANCELED
    assert result.result().result.error_msg == "canceled"
    assert ctx.sim_clock.now_ns() < 4 * S
    # cancelling a finished goal
    cancel = handle.cancel_goal_async()
    ex.spin_until_future_complete(cancel)
    assert cancel.result().return_code == 3  # ERROR_GOAL_TERMINATED


def test_plain_function_execute_and_unset_state_aborts(ctx):
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("n", context=ctx)

    def execute(handle):
        handle.publish_feedback(Spin.Feedback(angular_distance_traveled=float(handle.request.target_yaw)))
        if handle.request.target_yaw > 3.0:
            return Spin.Result(error_code=701)  # forgot to set a state → aborted
        handle.succeed()
        return Spin.Result(error_msg="ok")

    ActionServer(node, Spin, "spin", execute)
    client = ActionClient(node, Spin, "spin")
    ex.add_node(node)
    fb = []
    ok = client.send_goal(Spin.Goal(target_yaw=1.5), feedback_callback=fb.append)
    assert ok.status == GoalStatus.STATUS_SUCCEEDED and ok.result.error_msg == "ok"
    assert fb[0].feedback.angular_distance_traveled == pytest.approx(1.5)
    bad = client.send_goal(Spin.Goal(target_yaw=4.0))
    assert bad.status == GoalStatus.STATUS_ABORTED and bad.result.error_code == 701


def test_execute_raising_aborts_and_unknown_result(ctx):
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("n", context=ctx)

    def execute(handle):
        raise RuntimeError("motor fault")

    ActionServer(node, Spin, "spin", execute)
    client = ActionClient(node, Spin, "spin")
    ex.add_node(node)
    assert client.send_goal(Spin.Goal()).status == GoalStatus.STATUS_ABORTED
    req = Spin.GetResult.Request()  # a goal id nobody sent
    f = client._get_result.call_async(req)
    ex.spin_until_future_complete(f)
    assert f.result().status == GoalStatus.STATUS_UNKNOWN


def test_results_expire_after_result_timeout(ctx):
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("n", context=ctx)
    server = _make_wait_server(node, result_timeout=5.0)
    client = ActionClient(node, Wait, "wait")
    ex.add_node(node)
    f = client.send_goal_async(_wait_goal(1.0))
    ex.spin_until_future_complete(f)
    handle = f.result()
    ex.spin_for(3.0)
    assert len(server.goal_handles) == 1
    r = handle.get_result_async()
    ex.spin_until_future_complete(r)
    assert r.result().status == GoalStatus.STATUS_SUCCEEDED
    ex.spin_for(5.0)
    handle._result_future = None
    r = handle.get_result_async()
    ex.spin_until_future_complete(r)
    assert r.result().status == GoalStatus.STATUS_UNKNOWN
    assert server.goal_handles == []


def test_two_goals_run_concurrently_on_one_thread(ctx):
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("n", context=ctx)
    _make_wait_server(node)
    client = ActionClient(node, Wait, "wait")
    ex.add_node(node)
    futures = [client.send_goal_async(_wait_goal(s)) for s in (4.0, 2.0)]
    for f in futures:
        ex.spin_until_future_complete(f)
    results = [f.result().get_result_async() for f in futures]
    ex.spin_until_future_complete(results[1])
    assert ctx.sim_clock.now_ns() == 2 * S and not results[0].done()
    ex.spin_until_future_complete(results[0])
    assert ctx.sim_clock.now_ns() == 4 * S
