"""Type descriptions and every node's ~/get_type_description (type_description_interfaces)."""

from __future__ import annotations

from typing import Any

import pytest

from eddiebot.core import Context, Node
from eddiebot.core.type_description import describe, rihs01, service_fielddefs
from eddiebot.msgs import TYPESTORE, get_service, load_type, type_hash
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.msgs.std_msgs import String
from eddiebot.transport.keys import service_type_hash

GET_TYPE_DESCRIPTION = "type_description_interfaces/srv/GetTypeDescription"


@pytest.mark.parametrize("name", [
    "std_msgs/msg/String", "sensor_msgs/msg/LaserScan", "nav_msgs/msg/OccupancyGrid",
    "tf2_msgs/msg/TFMessage", "sensor_msgs/msg/Image", "rcl_interfaces/msg/Log",
])
def test_description_hashes_to_the_types_rihs01(name: str) -> None:
    assert rihs01(describe(TYPESTORE.fielddefs, name)) == type_hash(name)


@pytest.mark.parametrize("name", ["std_srvs/srv/Trigger", "rcl_interfaces/srv/GetParameters",
                                  GET_TYPE_DESCRIPTION])
def test_service_description_hashes_to_the_service_hash(name: str) -> None:
    load_type(name, "service")
    assert rihs01(describe(service_fielddefs(TYPESTORE.fielddefs, name), name)) == \
        service_type_hash(name)


def test_get_type_description_is_jazzys_type() -> None:
    # the hash a ROS 2 Jazzy client puts in the service's key
    assert service_type_hash(GET_TYPE_DESCRIPTION) == \
        "RIHS01_69b9c19c1021405984cc60dbbb1edceb147a6538b411d812ba6afabeed962cd5"


@pytest.fixture
def node() -> Any:
    ctx = Context()
    n = Node("scanner", namespace="/robot", context=ctx)
    n.create_publisher(LaserScan, "scan", 5)
    n.create_subscription(String, "cmd", lambda m: None, 5)
    yield n
    ctx.shutdown()


def _ask(node: Node, type_hash_text: str, sources: bool = True) -> Any:
    srv = get_service(GET_TYPE_DESCRIPTION)
    caller = Node("asker", context=node.context, start_parameter_services=False)
    client = caller.create_client(srv, "/robot/scanner/get_type_description")
    return client.call(srv.Request(type_name="", type_hash=type_hash_text,
                                   include_type_sources=sources), timeout_sec=5)


def test_every_node_serves_get_type_description(node: Node) -> None:
    assert "/robot/scanner/get_type_description" in node.context.services
    hidden = Node("_cli", context=node.context, start_parameter_services=False)
    assert "/_cli/get_type_description" not in hidden.context.services


def test_a_publishers_type_is_described_with_its_references_and_sources(node: Node) -> None:
    res = _ask(node, type_hash("sensor_msgs/msg/LaserScan"))
    assert res.successful and res.failure_reason == ""
    top = res.type_description.type_description
    assert top.type_name == "sensor_msgs/msg/LaserScan"
    assert [f.name for f in top.fields] == [
        "header", "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
        "range_min", "range_max", "ranges", "intensities"]
    ranges = top.fields[8].type
    assert (ranges.type_id, ranges.capacity) == (154, 0)  # float32 unbounded sequence
    assert [r.type_name for r in res.type_description.referenced_type_descriptions] == [
        "builtin_interfaces/msg/Time", "std_msgs/msg/Header"]
    assert [s.type_name for s in res.type_sources] == [
        "sensor_msgs/msg/LaserScan", "std_msgs/msg/Header", "builtin_interfaces/msg/Time"]
    assert all(s.encoding == "msg" for s in res.type_sources)
    assert "float32[] ranges" in res.type_sources[0].raw_file_contents
    assert _ask(node, type_hash("sensor_msgs/msg/LaserScan"), sources=False).type_sources == []


def test_subscription_and_service_types_are_described(node: Node) -> None:
    assert _ask(node, type_hash("std_msgs/msg/String")).type_description \
        .type_description.fields[0].name == "data"
    res = _ask(node, service_type_hash(GET_TYPE_DESCRIPTION))  # the node serves it itself
    assert res.successful
    assert [f.name for f in res.type_description.type_description.fields] == [
        "request_message", "response_message", "event_message"]


def test_types_the_node_does_not_use_and_bad_hashes_fail_as_rcl_says(node: Node) -> None:
    res = _ask(node, type_hash("nav_msgs/msg/Odometry"))
    assert not res.successful
    assert res.failure_reason == "Type not currently in use by this node"
    res = _ask(node, "RIHS01_nothex")
    assert not res.successful and res.failure_reason == "Failed to parse type hash"
