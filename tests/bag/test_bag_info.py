"""``bag info``: counts, time span and the layout of ``ros2 bag info``."""

from __future__ import annotations

from pathlib import Path

import pytest

from _support.bags import NS, T0
from eddiebot.bag import BagWriter, bag_info, format_bag_info
from eddiebot.msgs import serialize
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.std_msgs import String


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


def test_bag_info_shows_the_distro(recorded: Path, tmp_path: Path) -> None:
    assert bag_info(recorded).ros_distro == "jazzy"
    assert "ROS Distro:        jazzy\n" in format_bag_info(bag_info(recorded))
    (mcap,) = recorded.glob("*.mcap")
    assert bag_info(mcap).ros_distro == "jazzy"  # a bare file: from its rosbag2 record
    (recorded / "metadata.yaml").unlink()
    assert bag_info(recorded).ros_distro == "jazzy"  # streamed: the same record


def test_bag_info_without_a_distro_says_unknown(tmp_path: Path) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    from eddiebot.msgs import TYPESTORE

    bag = tmp_path / "old"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conn = w.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=TYPESTORE)
        w.write(conn, T0, serialize(Twist()))
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("ros_distro: rosbags", "ros_distro: ''"))
    info = bag_info(bag)
    assert info.ros_distro == ""
    assert "ROS Distro:        unknown\n" in format_bag_info(info)


#: std_srvs/srv/SetBool_Event as rosbag2 stores a service event type (ros2msg, dependencies
#: after the separators).
_SET_BOOL_EVENT = """service_msgs/ServiceEventInfo info
std_srvs/SetBool_Request[<=1] request
std_srvs/SetBool_Response[<=1] response
================================================================================
MSG: service_msgs/ServiceEventInfo
uint8 REQUEST_SENT = 0
uint8 REQUEST_RECEIVED = 1
uint8 RESPONSE_SENT = 2
uint8 RESPONSE_RECEIVED = 3
uint8 event_type
builtin_interfaces/Time stamp
char[16] client_gid
int64 sequence_number
================================================================================
MSG: std_srvs/SetBool_Request
bool data
================================================================================
MSG: std_srvs/SetBool_Response
bool success
string message
"""


def test_bag_info_lists_services_apart_from_topics(tmp_path: Path) -> None:
    from eddiebot.bag import ServiceSummary

    bag = tmp_path / "services"
    with BagWriter(bag) as w:
        w.add_topic("/set_led/_service_event", "std_srvs/srv/SetBool_Event",
                    msgdef=_SET_BOOL_EVENT, rihs01="RIHS01_" + "ab" * 32)
        # a topic with the suffix but not a service event type stays a topic, as in rosbag2
        w.add_topic("/odd/_service_event", "std_msgs/msg/String")
        for k in range(4):  # request sent/received, response sent/received
            w.write("/set_led/_service_event", b"\x00\x01\x00\x00", T0 + k)
        for k in range(3):
            w.write_message("/cmd_vel", Twist(), T0 + k)
        w.write("/odd/_service_event", serialize(String(data="x")), T0)
    info = bag_info(bag)
    assert [t.name for t in info.topics] == ["/cmd_vel", "/odd/_service_event"]
    assert info.services == [ServiceSummary("/set_led", "std_srvs/srv/SetBool", 4, "cdr")]
    assert info.message_count == 8
    assert info.topic_message_count == 4
    text = format_bag_info(info)
    assert "Messages:          4\n" in text
    assert "Service:           1\n" in text
    assert ("Service information: Service: /set_led | Type: std_srvs/srv/SetBool | "
            "Event Count: 4 | Serialization Format: cdr") in text
    assert "Topic: /set_led" not in text
