"""The player node: timing, rate, latched topics, /clock, loops, start offset, foreign types
(all on a simulated clock)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from _support.bags import EXCLUDE, NS, T0, read_bag
from eddiebot.bag import (
    Player,
    RecorderNode,
)
from eddiebot.core import (
    Context,
    Node,
    SingleThreadedExecutor,
    qos_profile_latched,
)
from eddiebot.msgs.nav_msgs import OccupancyGrid, Odometry
from eddiebot.msgs.sensor_msgs import LaserScan


def test_record_play_record_is_identical(recorded: Path, tmp_path: Path) -> None:
    ctx = Context(use_sim_time=True)
    player = Player(recorded, context=ctx, shutdown_when_done=True)
    again = tmp_path / "again"
    rec = RecorderNode(context=ctx, parameter_overrides={"output": str(again), "all": True,
                                                         "exclude": EXCLUDE})
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.add_node(rec)
    ex.spin_for(10.0)
    assert player.done
    assert player.published == 40
    rec.destroy_node()
    original = read_bag(recorded)
    replayed = read_bag(again)
    assert len(replayed) == len(original) == 40
    assert replayed == original  # same CDR bytes, same order, same timestamps


def test_play_rate_scales_timing(recorded: Path) -> None:
    ctx = Context(use_sim_time=True)
    player = Player(recorded, context=ctx, rate=2.0, topics=["/odom"])
    got: list[int] = []
    sink = Node("sink", context=ctx)
    sink.create_subscription(Odometry, "/odom", lambda _m: got.append(ctx.sim_clock.now_ns()), 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.add_node(sink)
    ex.spin_for(5.0)
    # first odom at t0 + 0.1 s is the start; then every 0.05 s
    assert len(got) == 20
    assert np.diff(got).tolist() == [NS // 20] * 19


def test_transient_local_replayed_latched(recorded: Path) -> None:
    ctx = Context(use_sim_time=True)
    player = Player(recorded, context=ctx, topics=["/map"])
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.spin_for(3.0)
    assert player.done
    late: list[OccupancyGrid] = []
    sink = Node("late", context=ctx)
    sink.create_subscription(OccupancyGrid, "/map", late.append, qos_profile_latched)
    ex.add_node(sink)
    ex.spin_once(timeout_sec=0)
    assert len(late) == 1
    assert late[0].data.tolist() == [0, 100, -1, 0] * 3


def test_play_publishes_clock_and_loops(recorded: Path) -> None:
    from eddiebot.msgs.rosgraph_msgs import Clock

    ctx = Context(use_sim_time=True)
    player = Player(recorded, context=ctx, topics=["/scan"], publish_clock=True,
                    clock_frequency=0.0, loop=True)
    clocks: list[int] = []
    scans: list[LaserScan] = []
    sink = Node("sink", context=ctx)
    sink.create_subscription(
        Clock, "/clock", lambda m: clocks.append(m.clock.sec * NS + m.clock.nanosec), 100)
    sink.create_subscription(LaserScan, "/scan", scans.append, 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.add_node(sink)
    ex.spin_for(4.5)
    assert player.loops >= 2
    assert len(scans) >= 20
    assert clocks[0] == T0 + 2 * NS // 10  # bag time of the first /scan
    assert not player.done


def test_play_from_start_offset(recorded: Path) -> None:
    ctx = Context(use_sim_time=True)
    player = Player(recorded, context=ctx, start_offset=1.0, topics=["/odom"])
    got: list[int] = []
    sink = Node("sink", context=ctx)
    sink.create_subscription(Odometry, "/odom", lambda m: got.append(m.header.stamp.sec * NS
                                                                     + m.header.stamp.nanosec), 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.add_node(sink)
    ex.spin_for(3.0)
    # the bag's /odom starts at t0 + 0.1 s; one second later is t0 + 1.1 s
    assert got == [T0 + k * NS // 10 for k in range(11, 21)]


def test_play_type_unknown_here_uses_the_bags_definition(tmp_path: Path) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from eddiebot.msgs import get_message

    other = get_typestore(Stores.EMPTY)
    other.register(get_types_from_msg("int32 a\nstring b\n", "vizbagtest_msgs/msg/Foo"))
    foo = other.types["vizbagtest_msgs/msg/Foo"]
    bag = tmp_path / "foreign"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/foo", "vizbagtest_msgs/msg/Foo", typestore=other)
        for k in range(3):
            w.write(conn, T0 + k, bytes(other.serialize_cdr(foo(a=k, b="x"),
                                                            "vizbagtest_msgs/msg/Foo")))
    ctx = Context(use_sim_time=True)
    player = Player(bag, context=ctx)
    got: list[object] = []
    sink = Node("sink", context=ctx)
    sink.create_subscription(get_message("vizbagtest_msgs/msg/Foo"), "/foo", got.append, 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.add_node(sink)
    ex.spin_for(1.0)
    assert [m.a for m in got] == [0, 1, 2]  # type: ignore[attr-defined]
