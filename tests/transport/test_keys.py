"""The key space matches rmw_zenoh's documented examples."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.typesys.store import Typestore

from eddiebot.core.qos import QoSProfile, qos_profile_latched, qos_profile_sensor_data
from eddiebot.transport.config import ZenohConfig, normalize_endpoint
from eddiebot.transport.keys import (
    dds_type_name,
    decode_attachment,
    encode_attachment,
    entity_gid,
    liveliness_key,
    node_liveliness_key,
    parse_liveliness_key,
    qos_from_keyexpr,
    qos_to_keyexpr,
    ros_type_name,
    topic_key,
)

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


def test_data_keys_as_rmw_zenoh() -> None:
    assert topic_key(0, "/chatter", "std_msgs/msg/String") == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
    assert topic_key(0, "/robot1/chatter", "std_msgs/String") == (
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
    key = topic_key(2, "/add", "std_srvs/srv/Trigger", service=True)
    assert key.startswith("2/add/std_srvs::srv::dds_::Trigger_/RIHS01_")


def test_type_names_round_trip() -> None:
    for name in ("std_msgs/msg/String", "nav2_msgs/action/Wait_FeedbackMessage",
                 "std_srvs/srv/Trigger"):
        assert ros_type_name(dds_type_name(name)) == name
    assert dds_type_name("geometry_msgs/msg/Twist") == "geometry_msgs::msg::dds_::Twist_"


def test_qos_chunk() -> None:
    assert qos_to_keyexpr(QoSProfile(depth=10)) == "::,10:,:,:,,"  # rmw_zenoh's example
    assert qos_to_keyexpr(qos_profile_sensor_data) == "2::,5:,:,:,,"
    assert qos_to_keyexpr(qos_profile_latched) == ":1:,1:,:,:,,"
    for q in (QoSProfile(depth=7), qos_profile_sensor_data, qos_profile_latched):
        assert qos_from_keyexpr(qos_to_keyexpr(q)) == q


def test_liveliness_tokens_as_rmw_zenoh() -> None:
    zid = "aac3178e146ba6f1fc6e6a4085e77f21"
    assert node_liveliness_key(2, zid, 0, "/", "listener") == (
        f"@ros2_lv/2/{zid}/0/0/NN/%/%/listener")
    key = liveliness_key(2, zid, 0, 10, "MS", "/", "listener", "/chatter",
                         "std_msgs/msg/String", QoSProfile(depth=10))
    assert key == (f"@ros2_lv/2/{zid}/0/10/MS/%/%/listener/%chatter/"
                   f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,")
    e = parse_liveliness_key(key)
    assert e is not None
    assert (e.kind, e.name, e.type_name, e.node, e.domain) == (
        "MS", "/chatter", "std_msgs/msg/String", "/listener", 2)
    ns = parse_liveliness_key(node_liveliness_key(0, zid, 3, "/robot1", "talker"))
    assert ns is not None and ns.node == "/robot1/talker"
    assert parse_liveliness_key("@ros2_lv/0/x") is None


def test_attachment_and_gid() -> None:
    gid = entity_gid("@ros2_lv/0/z/0/1/MP/%/%/n/%t/T/H/::,10:,:,:,,")
    assert len(gid) == 16
    data = encode_attachment(42, 1_700_000_000_123_456_789, gid)
    assert len(data) == 33
    assert decode_attachment(data) == (42, 1_700_000_000_123_456_789, gid)
    assert decode_attachment(b"short") is None


def test_config_from_env() -> None:
    cfg = ZenohConfig.from_env({"EDDIE_ZENOH_ROUTER": "17447"})
    assert cfg.router == "tcp/127.0.0.1:17447"
    assert cfg.router_host_port() == ("127.0.0.1", 17447)
    s = cfg.session_settings()
    assert s["scouting/multicast/enabled"] is False
    assert s["listen/endpoints"] == ["tcp/127.0.0.1:0"]
    lan = ZenohConfig.from_env({"EDDIE_NETWORK": "lan",
                                "EDDIE_ZENOH_CONNECT": "192.168.1.20:7447"})
    assert lan.session_settings()["scouting/multicast/enabled"] is True
    assert lan.router_settings()["listen/endpoints"] == ["tcp/[::]:7447"]
    assert lan.connect == ["tcp/192.168.1.20:7447"]
    assert normalize_endpoint("tcp/10.0.0.1:7447") == "tcp/10.0.0.1:7447"


def test_service_hash_as_rosidl() -> None:
    from rosbags.interfaces import Nodetype

    from eddiebot.msgs import TYPESTORE
    from eddiebot.transport.keys import service_hash_from

    name = "example_interfaces/srv/AddTwoInts"
    int64 = (Nodetype.BASE, ("int64", 0))
    defs = {**TYPESTORE.fielddefs,
            f"{name}_Request": ([], [("a", int64), ("b", int64)]),
            f"{name}_Response": ([], [("sum", int64)])}
    # rmw_zenoh's design.md example for add_two_ints
    assert service_hash_from(defs, name) == (
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a")


def test_service_hash_from_an_interface_file(tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """A service we do not ship hashes from its .srv, as rosidl and rmw_zenoh do."""
    from eddiebot.transport.keys import service_type_hash

    folder = tmp_path / "share" / "example_interfaces" / "srv"
    folder.mkdir(parents=True)
    (folder / "AddTwoInts.srv").write_text("int64 a\nint64 b\n---\nint64 sum\n")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))
    assert service_type_hash("example_interfaces/srv/AddTwoInts") == (
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a")


def test_shipped_service_hash_is_rosbags_hash_of_its_description() -> None:
    from rosbags.interfaces import Nodetype

    from eddiebot.msgs import TYPESTORE
    from eddiebot.transport.keys import service_type_hash

    name = "std_srvs/srv/SetBool"
    store = Typestore()
    store.fielddefs.update(TYPESTORE.fielddefs)
    info = "service_msgs/msg/ServiceEventInfo"
    consts, info_fields = store.fielddefs[info]
    store.fielddefs[info] = (consts, [
        (n, (Nodetype.ARRAY, ((Nodetype.BASE, ("uint8", 0)), 16))) if n == "client_gid"
        else (n, d) for n, d in info_fields])
    store.fielddefs[f"{name}_Event"] = ([], [
        ("info", (Nodetype.NAME, info)),
        ("request", (Nodetype.SEQUENCE, ((Nodetype.NAME, f"{name}_Request"), 1))),
        ("response", (Nodetype.SEQUENCE, ((Nodetype.NAME, f"{name}_Response"), 1)))])
    store.fielddefs[name] = ([], [
        ("request_message", (Nodetype.NAME, f"{name}_Request")),
        ("response_message", (Nodetype.NAME, f"{name}_Response")),
        ("event_message", (Nodetype.NAME, f"{name}_Event"))])
    assert service_type_hash(name) == store.hash_rihs01(name)


def test_undescribed_service_has_no_hash(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from eddiebot.msgs import UnknownTypeError
    from eddiebot.transport.keys import UNKNOWN_TYPE_HASH, message_type_hash, service_type_hash

    monkeypatch.setenv("EDDIE_INTERFACE_PATH", str(tmp_path))
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    with pytest.raises(UnknownTypeError, match=r"nowhere_srvs/srv/Nothing\.srv"):
        service_type_hash("nowhere_srvs/srv/Nothing")
    assert message_type_hash("nowhere_msgs/msg/Nothing") == UNKNOWN_TYPE_HASH
