import math

import numpy as np
import pytest

from eddiebot.core import Context, Node, SingleThreadedExecutor, Time
from eddiebot.core.tf import (
    Buffer,
    ConnectivityException,
    ExtrapolationException,
    LookupException,
    StaticTransformBroadcaster,
    TimeoutException,
    TransformBroadcaster,
    TransformListener,
    make_transform,
    make_transform_2d,
)
from eddiebot.geometry import quaternion_to_yaw, se2_compose, se2_inverse

S = 1_000_000_000


def _yaw(msg):
    r = msg.transform.rotation
    return quaternion_to_yaw(r.x, r.y, r.z, r.w)


def _xy(msg):
    t = msg.transform.translation
    return t.x, t.y


def test_interpolates_halfway_between_two_stamps():
    buf = Buffer()
    buf.set_transform(make_transform_2d("odom", "base_link", 1 * S, 0.0, 0.0, 0.0))
    buf.set_transform(make_transform_2d("odom", "base_link", 2 * S, 2.0, 4.0, math.pi / 2))
    t = buf.lookup_transform("odom", "base_link", Time(1_500_000_000))
    assert _xy(t) == pytest.approx((1.0, 2.0))
    assert _yaw(t) == pytest.approx(math.pi / 4)
    assert t.header.frame_id == "odom" and t.child_frame_id == "base_link"
    assert (t.header.stamp.sec, t.header.stamp.nanosec) == (1, 500_000_000)
    # a quarter of the way, as int ns
    x, y, yaw = buf.lookup_pose2d("odom", "base_link", 1_250_000_000)
    assert (x, y, yaw) == pytest.approx((0.5, 1.0, math.pi / 8))


def test_chain_through_common_parent_matches_se2_algebra():
    buf = Buffer()
    map_odom = (1.0, -2.0, 0.3)
    odom_base = (4.0, 1.0, -1.1)
    base_laser = (0.2, 0.0, math.pi)
    base_cam = (0.1, 0.05, 0.5)
    buf.set_transform(make_transform_2d("map", "odom", 5 * S, *map_odom))
    buf.set_transform(make_transform_2d("odom", "base_link", 5 * S, *odom_base))
    buf.set_transform_static(make_transform_2d("base_link", "laser", 0, *base_laser))
    buf.set_transform_static(make_transform_2d("base_link", "camera", 0, *base_cam))
    # laser in map: down the chain
    expected = se2_compose(se2_compose(map_odom, odom_base), base_laser)
    got = buf.lookup_pose2d("map", "laser", 5 * S)
    assert got[:2] == pytest.approx(tuple(expected[:2]))
    assert math.cos(got[2] - expected[2]) == pytest.approx(1.0)
    # camera seen from the laser: through their common parent base_link
    expected = se2_compose(se2_inverse(base_laser), base_cam)
    got = buf.lookup_pose2d("laser", "camera", 0)
    assert got[:2] == pytest.approx(tuple(expected[:2]))
    assert math.cos(got[2] - expected[2]) == pytest.approx(1.0)
    # inverse direction: map seen from the laser
    msg = buf.lookup_transform("laser", "map", Time(5 * S))
    inv = se2_inverse(se2_compose(se2_compose(map_odom, odom_base), base_laser))
    assert _xy(msg) == pytest.approx(tuple(inv[:2]))


def test_full_3d_rotation_chain():
    buf = Buffer()
    # child rotated 90° about x, then a child of that translated along its own y
    s = math.sqrt(0.5)
    buf.set_transform_static(make_transform("a", "b", 0, 1.0, 0.0, 0.0, s, 0.0, 0.0, s))
    buf.set_transform_static(make_transform("b", "c", 0, 0.0, 2.0, 0.0))
    t = buf.lookup_transform("a", "c", Time())
    tr = t.transform.translation
    assert (tr.x, tr.y, tr.z) == pytest.approx((1.0, 0.0, 2.0))
    back = buf.lookup_transform("c", "a", Time())
    q = back.transform.rotation
    assert (q.x, q.y, q.z, abs(q.w)) == pytest.approx((-s, 0.0, 0.0, s))


def test_static_and_dynamic_mix_and_latest_common_time():
    buf = Buffer()
    buf.set_transform_static(make_transform_2d("base_link", "laser", 0, 0.3, 0.0, 0.0))
    for k in range(1, 6):  # odom → base_link at 1..5 s
        buf.set_transform(make_transform_2d("odom", "base_link", k * S, float(k), 0.0, 0.0))
    buf.set_transform(make_transform_2d("map", "odom", 2 * S, 0.0, 1.0, 0.0))
    buf.set_transform(make_transform_2d("map", "odom", 3 * S, 0.0, 2.0, 0.0))
    # laser in odom: static edge does not limit the time → latest odom data (5 s)
    t = buf.lookup_transform("odom", "laser", Time())
    assert t.header.stamp.sec == 5
    assert _xy(t) == pytest.approx((5.3, 0.0))
    # laser in map: map→odom ends at 3 s, so the latest common time is 3 s
    t = buf.lookup_transform("map", "laser", 0)
    assert t.header.stamp.sec == 3
    assert _xy(t) == pytest.approx((3.3, 2.0))
    assert buf.get_latest_common_time("map", "laser") == Time(3 * S)
    # static-only lookup at any time
    assert buf.can_transform("base_link", "laser", Time(123 * S))
    # odom→laser at 2.5 s: no need for map→odom
    assert buf.lookup_pose2d("odom", "laser", 2_500_000_000)[0] == pytest.approx(2.8)


def test_cache_time_prunes_old_data():
    buf = Buffer(cache_time=2.0)
    for k in range(10):
        buf.set_transform(make_transform_2d("odom", "base_link", k * S, float(k), 0.0, 0.0))
    assert buf.can_transform("odom", "base_link", Time(7 * S))
    with pytest.raises(ExtrapolationException, match="past"):
        buf.lookup_transform("odom", "base_link", Time(6 * S))
    # data older than the window is refused
    assert not buf.set_transform(make_transform_2d("odom", "base_link", 1 * S, 0.0, 0.0, 0.0))


def test_lookup_exception_lists_known_frames():
    buf = Buffer()
    buf.set_transform(make_transform_2d("odom", "base_link", S, 0.0, 0.0, 0.0))
    with pytest.raises(LookupException) as err:
        buf.lookup_transform("odom", "base_footprint", Time())
    msg = str(err.value)
    assert '"base_footprint"' in msg and "source_frame" in msg
    assert "base_link" in msg and "odom" in msg
    assert not buf.can_transform("nowhere", "odom")


def test_connectivity_exception_two_trees():
    buf = Buffer()
    buf.set_transform(make_transform_2d("odom", "base_link", S, 0.0, 0.0, 0.0))
    buf.set_transform(make_transform_2d("map", "landmark", S, 0.0, 0.0, 0.0))
    with pytest.raises(ConnectivityException, match="not part of the same tree") as err:
        buf.lookup_transform("map", "base_link", Time(S))
    assert '"base_link" is under "odom"' in str(err.value)
    with pytest.raises(ConnectivityException):
        buf.lookup_transform("map", "base_link", Time())


def test_extrapolation_messages_name_time_and_range():
    buf = Buffer()
    buf.set_transform(make_transform_2d("odom", "base_link", 10 * S, 0.0, 0.0, 0.0))
    buf.set_transform(make_transform_2d("odom", "base_link", 11 * S, 1.0, 0.0, 0.0))
    with pytest.raises(ExtrapolationException) as err:
        buf.lookup_transform("odom", "base_link", Time(12 * S))
    msg = str(err.value)
    assert "future" in msg and "12.000000" in msg and "11.000000" in msg
    with pytest.raises(ExtrapolationException) as err:
        buf.lookup_transform("base_link", "odom", Time(9_500_000_000))
    msg = str(err.value)
    assert "past" in msg and "9.500000" in msg and "10.000000" in msg
    # a single sample only answers its own stamp
    buf.set_transform(make_transform_2d("base_link", "wheel", 10 * S, 0.0, 0.1, 0.0))
    assert buf.can_transform("base_link", "wheel", Time(10 * S))
    assert not buf.can_transform("base_link", "wheel", Time(10 * S + 1))


def test_timeout_exception_after_waiting():
    buf = Buffer()
    buf.set_transform(make_transform_2d("odom", "base_link", S, 0.0, 0.0, 0.0))
    with pytest.raises(TimeoutException, match=r"within 0\.02 s") as err:
        buf.lookup_transform("odom", "base_link", Time(5 * S), timeout=0.02)
    assert isinstance(err.value.cause, ExtrapolationException)


def test_invalid_transforms_are_refused():
    buf = Buffer()
    assert not buf.set_transform(make_transform("a", "a", S))
    bad = make_transform("a", "b", S)
    bad.transform.rotation.w = 0.0
    assert not buf.set_transform(bad)
    assert buf.all_frames() == []
    # a leading slash is stripped
    assert buf.set_transform(make_transform("/a", "/b", S, 1.0))
    assert buf.all_frames() == ["a", "b"]
    assert buf.lookup_pose2d("/a", "b", 0)[0] == pytest.approx(1.0)


def test_reparented_frame_uses_parent_at_time():
    buf = Buffer()
    buf.set_transform(make_transform_2d("odom", "base_link", 1 * S, 1.0, 0.0, 0.0))
    buf.set_transform(make_transform_2d("map", "odom", 1 * S, 10.0, 0.0, 0.0))
    buf.set_transform(make_transform_2d("map", "odom", 3 * S, 20.0, 0.0, 0.0))
    buf.set_transform(make_transform_2d("odom", "base_link", 3 * S, 3.0, 0.0, 0.0))
    assert buf.lookup_pose2d("map", "base_link", 2 * S)[0] == pytest.approx(17.0)


def test_wait_for_transform_async_completes_on_arrival():
    buf = Buffer()
    fut = buf.wait_for_transform_async("odom", "base_link", Time(2 * S))
    assert not fut.done()
    buf.set_transform(make_transform_2d("odom", "base_link", 1 * S, 0.0, 0.0, 0.0))
    assert not fut.done()
    buf.set_transform(make_transform_2d("odom", "base_link", 3 * S, 2.0, 0.0, 0.0))
    assert fut.done()
    assert _xy(fut.result()) == pytest.approx((1.0, 0.0))


def test_listener_and_broadcasters_over_topics():
    ctx = Context(use_sim_time=True)
    ex = SingleThreadedExecutor(context=ctx)
    pub_node = Node("publisher", context=ctx)
    static = StaticTransformBroadcaster(pub_node)
    static.sendTransform(make_transform_2d("base_link", "laser", 0, 0.2, 0.0, 0.0))
    static.sendTransform(make_transform_2d("base_link", "imu", 0, 0.0, 0.1, 0.0))
    dyn = TransformBroadcaster(pub_node)
    dyn.sendTransform([make_transform_2d("odom", "base_link", S, 1.0, 0.0, 0.0)])
    # a late listener still gets all static frames (latched, accumulated in one message)
    sub_node = Node("listener", context=ctx)
    buf = Buffer()
    TransformListener(buf, sub_node)
    ex.add_node(pub_node)
    ex.add_node(sub_node)
    ex.spin_until_idle()
    assert buf.all_frames() == ["base_link", "imu", "laser"]  # /tf was sent before it joined
    assert static.pub.latched[-1].transforms.__len__() == 2
    dyn.sendTransform(make_transform_2d("odom", "base_link", 2 * S, 2.0, 0.0, 0.0))
    ex.spin_until_idle()
    x, y, _ = buf.lookup_pose2d("odom", "imu", 0)
    assert (x, y) == pytest.approx((2.0, 0.1))
    ctx.shutdown()


def test_timeout_spins_the_listener_executor():
    ctx = Context(use_sim_time=True)
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("tf_user", context=ctx)
    buf = Buffer()
    TransformListener(buf, node)
    dyn = TransformBroadcaster(node)
    ex.add_node(node)
    results = []

    def tick():
        dyn.sendTransform(make_transform_2d("odom", "base_link", node.now().nanoseconds, 1.0, 0.0, 0.0))

    def lookup():
        # blocking lookup inside a callback: the buffer spins the executor to receive /tf
        results.append(buf.lookup_transform("odom", "base_link", Time(), timeout=1.0))

    node.create_timer(0.1, tick)
    node.create_timer(0.1, lookup, oneshot=True)
    ex.spin_for(0.15)
    assert len(results) == 1
    ctx.shutdown()


def test_lookup_is_fast_enough():
    buf = Buffer()
    for k in range(200):
        buf.set_transform(make_transform_2d("odom", "base_link", k * S // 20, k * 0.01, 0.0, 0.0))
    buf.set_transform_static(make_transform_2d("base_link", "laser", 0, 0.1, 0.0, 0.0))
    times = np.linspace(1 * S, 9 * S, 2000).astype(np.int64)
    xs = [buf.lookup_pose2d("odom", "laser", int(t))[0] for t in times]
    assert xs[0] == pytest.approx(0.3)
    assert xs[-1] == pytest.approx(1.9)
