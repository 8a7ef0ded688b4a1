"""The files we write are rosbag2 (Jazzy) MCAP: definitions, hashes, QoS, splits; sqlite3
bags are read too."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from rosbags.highlevel import AnyReader

from _support.bags import NS, T0, read_bag
from eddiebot.bag import (
    BagReader,
    BagWriter,
    Player,
    bag_info,
)
from eddiebot.core import (
    Context,
    Node,
    QoSProfile,
    SingleThreadedExecutor,
    qos_profile_latched,
)
from eddiebot.msgs import message_definition, serialize, type_hash
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav_msgs import OccupancyGrid


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
    assert [t for _, t, _ in read_bag(bag)] == [T0 + k * NS // 10 for k in range(25)]


def test_sqlite3_bag_isread_bag(tmp_path: Path) -> None:
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


def _channel_metadata(mcap: Path) -> dict[str, dict[str, str]]:
    """Topic → the channel's metadata map, read with rosbags' own MCAP reader."""
    from io import BytesIO

    from rosbags.rosbag2.storage_mcap import McapReader, read_string

    reader = McapReader(mcap)
    reader.open()
    try:
        out: dict[str, dict[str, str]] = {}
        for channel in reader.channels.values():
            bio, meta = BytesIO(channel.metadata), {}
            while bio.tell() < len(channel.metadata):
                key = read_string(bio)
                meta[key] = read_string(bio)
            out[channel.topic] = meta
        return out
    finally:
        reader.close()


def test_mcap_channels_carry_topic_type_hash_and_infinite_qos(recorded: Path) -> None:
    import yaml

    (mcap,) = recorded.glob("*.mcap")
    channels = _channel_metadata(mcap)
    types = {"/odom": "nav_msgs/msg/Odometry", "/scan": "sensor_msgs/msg/LaserScan",
             "/map": "nav_msgs/msg/OccupancyGrid", "/cmd_vel": "geometry_msgs/msg/Twist"}
    assert set(channels) == set(types)
    for topic, meta in channels.items():
        # rosbag2's MCAP plugin reads the hash from this key into type_description_hash
        assert meta["topic_type_hash"] == type_hash(types[topic])
        (offered,) = yaml.safe_load(meta["offered_qos_profiles"])
        assert offered["deadline"] == {"sec": 9223372036, "nsec": 854775807}
        assert offered["liveliness_lease_duration"] == {"sec": 9223372036, "nsec": 854775807}


def test_each_file_names_the_distro_in_its_rosbag2_record(recorded: Path) -> None:
    import yaml

    from eddiebot.bag.recovery import read_rosbag2_metadata

    (mcap,) = recorded.glob("*.mcap")
    embedded = yaml.safe_load(read_rosbag2_metadata(mcap)["serialized_metadata"])
    assert embedded["ros_distro"] == "jazzy"
    assert embedded["message_count"] == 40
    meta = yaml.safe_load((recorded / "metadata.yaml").read_text())
    assert meta["rosbag2_bagfile_information"]["ros_distro"] == "jazzy"
