"""rosbag2 recording, playback, info and recovery of truncated bags, on a simulated clock."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from eddiebot.core import (
    Context,
    Node,
    QoSProfile,
    SingleThreadedExecutor,
    qos_profile_latched,
)
from eddiebot.msgs import deserialize, message_definition, serialize, type_hash
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav_msgs import OccupancyGrid, Odometry
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.viz.bag import (
    BagReader,
    BagWriter,
    Player,
    RecorderNode,
    bag_info,
    format_bag_info,
)

NS = 1_000_000_000
T0 = 5 * NS  # sim clock start: recordings do not begin at zero
#: Every node offers /parameter_events; these tests record only the talker's topics.
EXCLUDE = ["^/parameter_events$", "^/rosout$"]


class _Talker(Node):
    """Publishes /odom at 10 Hz and /scan at 5 Hz, latches /map once, and starts /cmd_vel
    (a topic that appears later) at t0 + 1 s."""

    def __init__(self, context: Context) -> None:
        super().__init__("talker", context=context)
        self.odom = self.create_publisher(Odometry, "/odom", 10)
        self.scan = self.create_publisher(LaserScan, "/scan", 5)
        self.map = self.create_publisher(OccupancyGrid, "/map", qos_profile_latched)
        self.cmd = None
        self.n = 0
        grid = OccupancyGrid()
        grid.info.width, grid.info.height, grid.info.resolution = 4, 3, 0.05
        grid.data = np.array([0, 100, -1, 0] * 3, dtype=np.int8)
        self.map.publish(grid)
        self.create_timer(0.1, self._tick)

    def _tick(self) -> None:
        self.n += 1
        odom = Odometry(child_frame_id="base_footprint")
        odom.header.frame_id = "odom"
        odom.header.stamp = self.get_clock().now().to_msg()
        odom.pose.pose.position.x = 0.01 * self.n
        self.odom.publish(odom)
        if self.n % 2 == 0:
            self.scan.publish(LaserScan(ranges=np.full(8, 1.0 + self.n, np.float32)))
        if self.n == 10:
            self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        if self.cmd is not None and self.n > 11:
            self.cmd.publish(Twist())


def _record(bag: Path, seconds: float = 2.0) -> None:
    ctx = Context(use_sim_time=True)
    ctx.sim_clock.set_ns(T0)
    talker = _Talker(ctx)
    rec = RecorderNode(context=ctx, parameter_overrides={"output": str(bag), "all": True,
                                                         "exclude": EXCLUDE,
                                                         "polling_interval": 0.05})
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(talker)
    ex.add_node(rec)
    ex.spin_for(seconds)
    rec.destroy_node()
    ctx.shutdown()


def _read(bag: Path) -> list[tuple[str, int, bytes]]:
    with BagReader(bag) as reader:
        return [(m.topic, m.timestamp, m.data) for m in reader.messages()]


@pytest.fixture
def recorded(tmp_path: Path) -> Path:
    bag = tmp_path / "run"
    _record(bag)
    return bag


def test_recording_opens_in_anyreader_with_our_definitions(recorded: Path) -> None:
    with AnyReader([recorded]) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert set(conns) == {"/odom", "/scan", "/map", "/cmd_vel"}
        odom = conns["/odom"]
        assert odom.msgtype == "nav_msgs/msg/Odometry"
        assert odom.msgdef.data == message_definition("nav_msgs/msg/Odometry")
        assert odom.digest == type_hash("nav_msgs/msg/Odometry")
        msgs: list[tuple[str, int, Any]] = [(c.topic, t, reader.deserialize(raw, c.msgtype))
                for c, t, raw in reader.messages(connections=[odom])]
    assert len(msgs) == 20
    # receive time on the sim clock: t0 + 0.1 s * k
    assert [t for _, t, _ in msgs] == [T0 + k * NS // 10 for k in range(1, 21)]
    assert msgs[4][2].pose.pose.position.x == pytest.approx(0.05)


def test_transient_local_offered_qos_in_metadata(recorded: Path) -> None:
    text = (recorded / "metadata.yaml").read_text()
    assert "transient_local" in text
    with BagReader(recorded) as reader:
        conns = {c.topic: c for c in reader.connections}
    assert conns["/map"].transient_local
    assert not conns["/odom"].transient_local


def test_infinite_qos_durations_as_rosbag2_writes_them(recorded: Path) -> None:
    import yaml

    meta = yaml.safe_load((recorded / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    qos_text = meta["topics_with_message_count"][0]["topic_metadata"]["offered_qos_profiles"]
    offered = qos_text if isinstance(qos_text, list) else yaml.safe_load(qos_text)
    for key in ("deadline", "lifespan", "liveliness_lease_duration"):
        assert offered[0][key] == {"sec": 9223372036, "nsec": 854775807}


def test_bag_info_counts(recorded: Path) -> None:
    info = bag_info(recorded)
    counts = {t.name: t.count for t in info.topics}
    # the map latched at t0; /cmd_vel exists from t0 + 1.0 s, publishes from 1.2 s
    assert counts == {"/odom": 20, "/scan": 10, "/map": 1, "/cmd_vel": 9}
    assert info.message_count == 40
    assert info.start_ns == T0
    assert info.end_ns == T0 + 2 * NS
    assert info.storage == "mcap"
    assert info.complete
    text = format_bag_info(info)
    assert "Topic: /odom" in text
    assert "Count: 20" in text
    assert "Duration:          2.000000000s" in text


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
    original = _read(recorded)
    replayed = _read(again)
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


def test_bag_writer_writes_message_objects(tmp_path: Path) -> None:
    bag = tmp_path / "direct"
    with BagWriter(bag) as w:
        for k in range(5):
            w.write_message("/cmd_vel", Twist(), T0 + k * NS)
        w.write_message("/map", OccupancyGrid(), T0, qos=qos_profile_latched)
    info = bag_info(bag)
    assert {t.name: t.count for t in info.topics} == {"/cmd_vel": 5, "/map": 1}
    assert info.duration_ns == 4 * NS
    with AnyReader([bag]) as reader:
        assert sum(1 for _ in reader.messages()) == 6


def test_split_by_duration(tmp_path: Path) -> None:
    bag = tmp_path / "split"
    with BagWriter(bag, max_bag_duration=1.0) as w:
        for k in range(25):
            w.write_message("/cmd_vel", Twist(), T0 + k * NS // 10)
    assert sorted(p.name for p in bag.glob("*.mcap")) == ["split_0.mcap", "split_1.mcap",
                                                          "split_2.mcap"]
    info = bag_info(bag)
    assert info.message_count == 25
    assert [t for _, t, _ in _read(bag)] == [T0 + k * NS // 10 for k in range(25)]


def test_truncated_bag_reports_and_recovers_prefix(recorded: Path, tmp_path: Path) -> None:
    # Many small chunks so a cut leaves whole chunks before it, as a crash after flushes.
    bag = tmp_path / "cut"
    with BagWriter(bag) as w:
        for k in range(200):
            w.write_message("/odom", Odometry(), T0 + k * NS // 100)
            if k % 20 == 19:
                w.flush()
    (mcap,) = bag.glob("*.mcap")
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    info = bag_info(bag)
    assert not info.complete
    (problem,) = info.problems
    assert problem.file == mcap
    assert problem.offset is not None
    assert 0 < problem.offset <= len(data) // 2
    assert 60 <= info.message_count < 200
    assert problem.message_index == info.message_count
    text = format_bag_info(info)
    assert "Damaged:" in text
    assert str(mcap) in text
    # the readable prefix is the original messages, in order
    got = _read(bag)
    assert [t for _, t, _ in got] == [T0 + k * NS // 100 for k in range(len(got))]
    assert all(d == serialize(Odometry()) for _, _, d in got)
    # playing it plays the prefix and says where it broke
    ctx = Context(use_sim_time=True)
    player = Player(bag, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.spin_for(5.0)
    assert player.done
    assert player.published == info.message_count
    assert player.problems == info.problems


def test_truncated_inside_unflushed_chunk(recorded: Path) -> None:
    """A recording cut inside its only (uncompressed) chunk still yields whole messages."""
    (mcap,) = recorded.glob("*.mcap")
    data = mcap.read_bytes()
    (recorded / "metadata.yaml").unlink()  # a crashed recorder never wrote it
    mcap.write_bytes(data[: len(data) // 2])
    info = bag_info(recorded)
    assert info.problems
    assert 5 < info.message_count < 40
    assert any("metadata.yaml" in n for n in info.notes)
    odom = [deserialize(d, "nav_msgs/msg/Odometry") for t, _, d in _read(recorded) if t == "/odom"]
    assert [round(o.pose.pose.position.x, 3) for o in odom] == [
        round(0.01 * (k + 1), 3) for k in range(len(odom))
    ]


def test_missing_metadata_reads_mcap_directly(recorded: Path) -> None:
    original = _read(recorded)
    (recorded / "metadata.yaml").unlink()
    info = bag_info(recorded)
    assert info.complete
    assert info.message_count == 40
    assert sorted(_read(recorded)) == sorted(original)


def test_recorder_topic_list_and_exclude(tmp_path: Path) -> None:
    ctx = Context(use_sim_time=True)
    talker = _Talker(ctx)
    bag = tmp_path / "some"
    rec = RecorderNode(context=ctx, parameter_overrides={
        "output": str(bag), "all": True, "exclude": ["^/sc", *EXCLUDE]})
    bag2 = tmp_path / "named"
    rec2 = RecorderNode("rec2", context=ctx, parameter_overrides={
        "output": str(bag2), "topics": ["/odom"]})
    ex = SingleThreadedExecutor(context=ctx)
    for n in (talker, rec, rec2):
        ex.add_node(n)
    ex.spin_for(0.5)
    rec.destroy_node()
    rec2.destroy_node()
    assert {t.name for t in bag_info(bag).topics} == {"/odom", "/map"}
    assert {t.name: t.count for t in bag_info(bag2).topics} == {"/odom": 5}


def test_sqlite3_bag_is_read(tmp_path: Path) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    from eddiebot.msgs import TYPESTORE

    bag = tmp_path / "db"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conn = w.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=TYPESTORE)
        for k in range(3):
            w.write(conn, T0 + k, serialize(Twist()))
    info = bag_info(bag)
    assert info.storage == "sqlite3"
    assert info.message_count == 3
    ctx = Context(use_sim_time=True)
    player = Player(bag, context=ctx)
    got: list[Twist] = []
    sink = Node("sink", context=ctx)
    sink.create_subscription(Twist, "/cmd_vel", got.append, QoSProfile(depth=10))
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.add_node(sink)
    ex.spin_for(1.0)
    assert len(got) == 3


class _FakeTransport:
    """A transport whose graph shows one remote publisher (as eddiebot.transport reports it)."""

    def __init__(self, entities: list[object]) -> None:
        from types import SimpleNamespace

        self.cache = SimpleNamespace(publishers=lambda topic=None: list(entities))

    def graph(self) -> dict[str, object]:
        return {"cache": self.cache, "remote_publishers": {}, "remote_subscriptions": {}}

    def __getattr__(self, name: str) -> object:
        return lambda *args, **kwargs: False


def test_recorder_finds_remote_topics_through_the_transport(tmp_path: Path) -> None:
    from types import SimpleNamespace

    from eddiebot.transport.keys import qos_to_keyexpr

    ctx = Context(use_sim_time=True)
    ctx.sim_clock.set_ns(T0)
    remote = SimpleNamespace(name="/remote/map", type_name="nav_msgs/msg/OccupancyGrid",
                             qos=qos_to_keyexpr(qos_profile_latched))
    ctx.attach_transport(_FakeTransport([remote]))  # type: ignore[arg-type]
    bag = tmp_path / "remote"
    rec = RecorderNode(context=ctx, parameter_overrides={"output": str(bag), "all": True,
                                                         "exclude": EXCLUDE})
    assert rec.recorded_topics == ["/remote/map"]
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    ctx.deliver_remote("/remote/map", "nav_msgs/msg/OccupancyGrid", OccupancyGrid())
    ex.spin_for(0.5)
    rec.destroy_node()
    with BagReader(bag) as reader:
        (conn,) = reader.connections
        assert conn.transient_local
        assert [m.timestamp for m in reader.messages()] == [T0]


def test_cli_bag_info_and_play(recorded: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from eddiebot.cli.main import main

    assert main(["bag", "info", str(recorded)]) == 0
    out = capsys.readouterr().out
    assert "Topic: /odom" in out
    assert "Messages:          40" in out
    assert main(["play", str(recorded), "--no-transport", "--rate", "1000"]) == 0
    assert "played 40 messages" in capsys.readouterr().out
    (mcap,) = recorded.glob("*.mcap")
    mcap.write_bytes(mcap.read_bytes()[:-200])
    assert main(["bag", "info", str(recorded)]) == 1
    assert "Damaged:" in capsys.readouterr().out


def test_crash_during_split_recording_recovers_every_flushed_message(tmp_path: Path) -> None:
    bag = tmp_path / "crash"
    w = BagWriter(bag, max_bag_duration=1.0)
    for k in range(25):
        w.write_message("/cmd_vel", Twist(), T0 + k * NS // 10)
    w.flush()  # what the recorder does every flush_interval; then the process dies
    assert sorted(p.name for p in bag.glob("*.mcap")) == ["crash_0.mcap", "crash_1.mcap",
                                                          "crash_2.mcap"]
    info = bag_info(bag)
    assert info.message_count == 25
    assert any("crash_2.mcap" in n for n in info.notes)
    (problem,) = info.problems
    assert problem.file.name == "crash_2.mcap"
    assert problem.message_index == 25


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
