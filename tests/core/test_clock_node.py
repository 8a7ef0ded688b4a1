from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.clock_node import ClockFollower, ClockPublisher, disable_rosout, enable_rosout
from eddiebot.core.time import stamp_to_ns
from eddiebot.msgs.rcl_interfaces import Log
from eddiebot.msgs.rosgraph_msgs import Clock

MS = 1_000_000


def test_clock_publisher_throttles_and_publishes_final_time():
    ctx = Context(use_sim_time=True)
    ex = SingleThreadedExecutor(context=ctx)
    sim = Node("sim", context=ctx)
    sim.create_timer(0.001, lambda: None)  # 1 kHz physics
    got = []
    viewer = Node("viewer", context=ctx)
    viewer.create_subscription(Clock, "/clock", lambda m: got.append(stamp_to_ns(m.clock)), 1000)
    clock_pub = ClockPublisher(sim, ex, clock_period=0.01)
    ex.add_node(sim)
    ex.add_node(viewer)
    ex.spin_until(1_005 * MS - 500_000)  # ends between two physics ticks
    ex.spin_until_idle()
    assert got[0] == 0
    assert all(b - a >= 10 * MS for a, b in zip(got[1:-2], got[2:-1]))
    assert 99 <= len(got) <= 103
    assert got[-1] == 1_005 * MS - 500_000  # the final time always goes out
    assert clock_pub.pending_ns is None
    ctx.shutdown()


def test_clock_follower_sets_sim_clock():
    owner = Context(use_sim_time=True)
    follower_ctx = Context(use_sim_time=True)
    src = Node("src", context=owner)
    pub = src.create_publisher(Clock, "/clock", 1)
    follower = Node("follower", context=follower_ctx)
    f = ClockFollower(follower)
    ex = SingleThreadedExecutor(context=follower_ctx, drive_sim_time=False)
    ex.add_node(follower)
    msg = Clock()
    msg.clock.sec = 42
    # hand the message over as a transport would
    follower_ctx.deliver_remote("/clock", "rosgraph_msgs/msg/Clock", msg)
    ex.spin_once(timeout_sec=0)
    assert follower_ctx.sim_clock.now_ns() == 42_000_000_000
    assert f.received == 1
    pub.destroy()
    owner.shutdown()
    follower_ctx.shutdown()


def test_rosout_hook_publishes_log_lines():
    ctx = Context(use_sim_time=True)
    ex = SingleThreadedExecutor(context=ctx)
    enable_rosout(ctx)
    lines = []
    viewer = Node("viewer", context=ctx)
    viewer.create_subscription(Log, "/rosout", lines.append, 100)
    node = Node("amcl", namespace="robot", context=ctx)
    ex.add_node(node)
    ex.add_node(viewer)
    node.get_logger().warning("no map received")
    ex.spin_until_idle()
    assert [(m.level, m.name, m.msg) for m in lines] == [(30, "robot.amcl", "no map received")]
    disable_rosout(ctx)
    node.get_logger().error("quiet")
    ex.spin_until_idle()
    assert len(lines) == 1
    ctx.shutdown()
