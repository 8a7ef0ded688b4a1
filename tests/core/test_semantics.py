"""Runtime semantics rclpy users rely on: time jumps, bounded ready queues, group hand-off,
service callbacks that raise."""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import pytest

from eddiebot.core import (
    Buffer,
    Context,
    Duration,
    JumpThreshold,
    MultiThreadedExecutor,
    MutuallyExclusiveCallbackGroup,
    Node,
    QoSProfile,
    SingleThreadedExecutor,
    Time,
    TimeJump,
)
from eddiebot.core.clock_node import ClockFollower
from eddiebot.core.time import SimClock
from eddiebot.msgs.geometry_msgs import TransformStamped
from eddiebot.msgs.rosgraph_msgs import Clock as ClockMsg
from eddiebot.msgs.std_msgs import Int32
from eddiebot.msgs.std_srvs import SetBool

S = 1_000_000_000


@pytest.fixture
def ctx() -> Any:
    c = Context(use_sim_time=True)
    yield c
    c.shutdown()


def _wait(cond: Any, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.001)
    return cond()


# -- time jumps -----------------------------------------------------------------------------
def test_jump_callbacks_fire_on_reset_past_their_threshold() -> None:
    clock = SimClock(10 * S)
    seen: list[tuple[str, int]] = []
    clock.create_jump_callback(JumpThreshold(None, Duration(-2 * S)),
                               pre_callback=lambda: seen.append(("pre", clock.now_ns())),
                               post_callback=lambda j: seen.append(("post", j.delta.nanoseconds)))
    clock.reset(9 * S)  # 1 s back: under the 2 s threshold
    clock.reset(5 * S)  # 4 s back
    clock.set_ns(20 * S)  # an ordinary move forward is no jump
    assert seen == [("pre", 9 * S), ("post", -4 * S)]
    with pytest.raises(ValueError, match="min_backward"):
        JumpThreshold(None, Duration(S))


def test_timers_restart_when_sim_time_jumps_back(ctx: Context) -> None:
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("looping", context=ctx)
    ex.add_node(node)
    calls: list[int] = []
    node.create_timer(0.1, lambda: calls.append(ctx.sim_clock.now_ns()))
    ex.spin_for(10.0)
    assert len(calls) == 100
    ctx.sim_clock.reset(0)  # a bag played with --loop --clock starts over
    ex.spin_for(10.0)
    # without the reset the timer would wait for 10 s of sim time: 0 calls
    assert len(calls) == 200
    assert calls[100] == round(0.1 * S)


def test_timer_keeps_its_schedule_on_a_small_jump_back(ctx: Context) -> None:
    node = Node("steady", context=ctx)
    timer = node.create_timer(1.0, lambda: None)
    ctx.sim_clock.set_ns(5 * S)
    timer.execute()
    assert timer.next_call_ns == 6 * S
    ctx.sim_clock.reset(5 * S + S // 2)  # forward inside the period: nothing to do
    ctx.sim_clock.reset(5 * S + S // 4)  # back, but not before the last call
    assert timer.next_call_ns == 6 * S
    ctx.sim_clock.reset(2 * S)
    assert timer.next_call_ns == 3 * S


def test_clock_follower_going_back_resets_timers(ctx: Context) -> None:
    ex = SingleThreadedExecutor(context=ctx, drive_sim_time=False)
    node = Node("follower", context=ctx)
    ex.add_node(node)
    follower = ClockFollower(node)
    pub = Node("bag", context=ctx).create_publisher(ClockMsg, "/clock", 1)
    calls: list[int] = []
    node.create_timer(1.0, lambda: calls.append(ctx.sim_clock.now_ns()))
    for t in (50, 100, 150):  # 0.5 s .. 1.5 s
        pub.publish(ClockMsg(clock=Time(t * S // 100).to_msg()))
        ex.spin_until_idle()
    assert calls == [S]
    pub.publish(ClockMsg(clock=Time(S // 10).to_msg()))  # loop: back to 0.1 s
    ex.spin_until_idle()
    pub.publish(ClockMsg(clock=Time(S + S // 10).to_msg()))
    ex.spin_until_idle()
    assert follower.received == 5
    assert calls == [S, S + S // 10]


def _tf(stamp_ns: int, x: float, child: str = "base_link", parent: str = "odom") -> Any:
    t = TransformStamped()
    t.header.stamp = Time(stamp_ns).to_msg()
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x = x
    t.transform.rotation.w = 1.0
    return t


def test_tf_buffer_is_cleared_when_time_jumps_back(ctx: Context) -> None:
    node = Node("tf_user", context=ctx)
    buf = Buffer(node=node)
    ctx.sim_clock.set_ns(5 * S)
    buf.set_transform(_tf(5 * S, 1.0), "a")
    buf.set_transform_static(_tf(0, 0.5, "laser", "base_link"), "a")
    ctx.sim_clock.reset(S)
    assert buf.all_frames() == ["base_link", "laser"]  # static transforms stay
    buf.set_transform(_tf(S, 2.0), "a")
    latest = buf.lookup_transform("odom", "base_link", Time())
    assert latest.transform.translation.x == 2.0  # not the stale 5 s transform


def test_tf_listener_buffer_watches_the_node_clock(ctx: Context) -> None:
    from eddiebot.core import TransformListener

    node = Node("listener", context=ctx)
    buf = Buffer()
    TransformListener(buf, node)
    ctx.sim_clock.set_ns(3 * S)
    buf.set_transform(_tf(3 * S, 1.0), "a")
    ctx.sim_clock.reset(0)
    assert buf.all_frames() == []


def test_jump_handle_post_callback_gets_the_jump() -> None:
    clock = SimClock(4 * S)
    jumps: list[TimeJump] = []
    handle = clock.create_jump_callback(JumpThreshold(Duration(1), Duration(-1)),
                                        post_callback=jumps.append)
    clock.reset(6 * S)
    handle.unregister()
    clock.reset(0)
    assert [j.delta.nanoseconds for j in jumps] == [2 * S]


# -- ready queue ----------------------------------------------------------------------------
@pytest.mark.parametrize("depth", [1, 5])
def test_ready_queue_is_bounded_by_subscription_depth(ctx: Context, depth: int) -> None:
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("flooded", context=ctx)
    ex.add_node(node)
    got: list[int] = []
    node.create_subscription(Int32, "/flood", lambda m: got.append(m.data), QoSProfile(depth=depth))
    pub = node.create_publisher(Int32, "/flood", 10)
    for i in range(20_000):
        pub.publish(Int32(data=i))
    assert len(ex._ready) == depth
    assert ex.spin_until_idle() == depth
    assert got == list(range(20_000 - depth, 20_000))


def test_ready_queue_bound_holds_before_the_node_has_an_executor(ctx: Context) -> None:
    node = Node("late", context=ctx)
    got: list[int] = []
    node.create_subscription(Int32, "/x", lambda m: got.append(m.data), QoSProfile(depth=2))
    pub = node.create_publisher(Int32, "/x", 10)
    for i in range(1000):
        pub.publish(Int32(data=i))
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    assert ex.spin_until_idle() == 2
    assert got == [998, 999]
    pub.publish(Int32(data=7))
    ex.spin_until_idle()
    assert got == [998, 999, 7]


# -- multi-threaded hand-off ----------------------------------------------------------------
def test_blocked_work_is_handed_on_when_its_group_frees() -> None:
    ctx = Context()
    ex = MultiThreadedExecutor(num_threads=2, context=ctx)
    try:
        node = Node("mt", context=ctx)
        ex.add_node(node)
        group = MutuallyExclusiveCallbackGroup()
        release = threading.Event()
        order: list[str] = []

        def slow(msg: Any) -> None:
            order.append(f"slow {msg.data}")
            release.wait(10)

        node.create_subscription(Int32, "/a", slow, 10, callback_group=group)
        node.create_subscription(Int32, "/b", lambda m: order.append(f"fast {m.data}"), 10,
                                 callback_group=group)
        node.create_publisher(Int32, "/a", 10).publish(Int32(data=1))
        assert ex.spin_once(timeout_sec=1.0)  # the slow callback holds the group
        assert _wait(lambda: order == ["slow 1"])
        node.create_publisher(Int32, "/b", 10).publish(Int32(data=2))
        assert not ex.spin_once(timeout_sec=1.0)  # its group is busy: it waits beside it
        assert len(ex._ready) == 0
        release.set()
        # nobody spins now: the finishing callback itself puts the waiting work back
        assert _wait(lambda: len(ex._ready) == 1)
        assert ex.spin_once(timeout_sec=1.0)
        assert _wait(lambda: order == ["slow 1", "fast 2"])
    finally:
        ex.shutdown()
        ctx.shutdown()


def test_multi_threaded_spin_runs_waiting_work_of_a_freed_group() -> None:
    ctx = Context()
    ex = MultiThreadedExecutor(num_threads=3, context=ctx)
    try:
        node = Node("mt_spin", context=ctx)
        ex.add_node(node)
        group = MutuallyExclusiveCallbackGroup()
        got: list[int] = []
        lock = threading.Lock()

        def cb(msg: Any) -> None:
            with lock:
                got.append(msg.data)

        node.create_subscription(Int32, "/n", cb, QoSProfile(depth=1000), callback_group=group)
        pub = node.create_publisher(Int32, "/n", 10)
        spinner = threading.Thread(target=ex.spin, daemon=True)
        spinner.start()
        for i in range(300):
            pub.publish(Int32(data=i))
        assert _wait(lambda: len(got) == 300)
        assert sorted(got) == list(range(300))
    finally:
        ex.shutdown()
        ctx.shutdown()


# -- services that raise --------------------------------------------------------------------
def test_service_that_raises_is_logged_and_keeps_serving(
    ctx: Context, caplog: pytest.LogCaptureFixture
) -> None:
    node = Node("server", namespace="/robot", context=ctx)
    calls: list[bool] = []

    def answer(req: Any, res: Any) -> Any:
        calls.append(req.data)
        if req.data:
            raise RuntimeError("motor board not answering")
        res.success = True
        return res

    node.create_service(SetBool, "switch", answer)
    client = Node("caller", context=ctx).create_client(SetBool, "/robot/switch")
    with caplog.at_level(logging.ERROR), pytest.raises(RuntimeError, match="motor board"):
        client.call(SetBool.Request(data=True), timeout_sec=5)
    lines = [r.getMessage() for r in caplog.records if r.levelno == logging.ERROR]
    assert len(lines) == 1
    assert "/robot/server" in lines[0] and "/robot/switch" in lines[0]
    assert "RuntimeError" in lines[0]
    assert client.call(SetBool.Request(data=False), timeout_sec=5).success
    assert calls == [True, False]


def test_service_that_raises_on_a_spinning_executor_fails_the_call_at_once() -> None:
    ctx = Context()
    ex = SingleThreadedExecutor(context=ctx)
    try:
        node = Node("spun_server", context=ctx)
        ex.add_node(node)

        def answer(req: Any, res: Any) -> Any:
            if req.data:
                raise ValueError("bad request")
            res.success = True
            return res

        node.create_service(SetBool, "/spun", answer)
        spinner = threading.Thread(target=ex.spin, daemon=True)
        spinner.start()
        assert _wait(ex.is_spinning)
        client = Node("spun_caller", context=ctx).create_client(SetBool, "/spun")
        future = client.call_async(SetBool.Request(data=True))
        assert future.wait(10)
        assert isinstance(future.exception(), ValueError)
        assert client.call(SetBool.Request(data=False), timeout_sec=10).success
    finally:
        ex.shutdown()
        ctx.shutdown()


def test_every_request_waiting_for_a_busy_group_is_answered() -> None:
    from eddiebot.msgs.std_srvs import Trigger

    ctx = Context()
    ex = MultiThreadedExecutor(num_threads=3, context=ctx)
    try:
        node = Node("busy_server", context=ctx)
        ex.add_node(node)
        group = MutuallyExclusiveCallbackGroup()
        release = threading.Event()
        started = threading.Event()

        def slow(msg: Any) -> None:
            started.set()
            release.wait(10)

        served: list[int] = []

        def answer(req: Any, res: Any) -> Any:
            served.append(1)
            res.success = True
            return res

        node.create_subscription(Int32, "/hold", slow, 10, callback_group=group)
        node.create_service(Trigger, "/busy", answer, callback_group=group)
        spinner = threading.Thread(target=ex.spin, daemon=True)
        spinner.start()
        node.create_publisher(Int32, "/hold", 10).publish(Int32(data=1))
        assert started.wait(10)
        client = Node("busy_caller", context=ctx).create_client(Trigger, "/busy")
        futures = [client.call_async(Trigger.Request()) for _ in range(3)]
        release.set()
        assert all(f.wait(10) for f in futures)
        assert len(served) == 3
    finally:
        ex.shutdown()
        ctx.shutdown()
