"""Foxglove bridge over the Foxglove WebSocket protocol (``foxglove.websocket.v1``)."""

from __future__ import annotations

import json
import struct
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from websockets.sync.client import ClientConnection, connect

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.tf import StaticTransformBroadcaster, make_transform
from eddiebot.msgs import deserialize, serialize
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.msgs.std_srvs import Trigger
from eddiebot.viz.foxglove_bridge import BridgeConfig, FoxgloveBridge

pytest.importorskip("foxglove")
#: The protocol is foxglove.websocket.v1; foxglove-sdk 0.30 negotiates it under its new name
#: foxglove.sdk.v1 only, so a client offers both (as the Foxglove app does).
SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]


@pytest.fixture
def bridge() -> Iterator[tuple[FoxgloveBridge, Node]]:
    context = Context()
    node = Node("fox_test", context=context)
    scan_pub = node.create_publisher(LaserScan, "/scan", 10)

    def tick() -> None:
        scan = LaserScan(angle_min=-0.5, angle_increment=0.01, range_min=0.1, range_max=8.0,
                         ranges=np.linspace(1.0, 2.0, 101, dtype=np.float32))
        scan.header.frame_id = "base_scan"
        scan_pub.publish(scan)

    node.create_timer(0.05, tick)
    StaticTransformBroadcaster(node).sendTransform(
        make_transform("base_footprint", "base_scan", 0, 0.1, 0.0, 0.3))
    node.create_service(Trigger, "/fox_test/trigger",
                        lambda req, res: Trigger.Response(success=True, message="done"))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    b = FoxgloveBridge(context, BridgeConfig(port=0, discovery_period_s=0.2))
    yield b, node
    b.stop()
    executor.shutdown()
    context.shutdown()
    thread.join(5)


def channels(ws: ClientConnection, want: set[str], timeout: float = 5.0) -> dict[str, dict[str, Any]]:
    found: dict[str, dict[str, Any]] = {}
    deadline = time.monotonic() + timeout
    while not want <= found.keys():
        frame = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg.get("op") == "advertise":
                found.update({c["topic"]: c for c in msg["channels"]})
    return found


def message_data(ws: ClientConnection, sub_id: int, timeout: float = 5.0) -> bytes:
    deadline = time.monotonic() + timeout
    while True:
        frame = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
        if isinstance(frame, bytes) and frame[0] == 0x01:
            (sid,) = struct.unpack_from("<I", frame, 1)
            if sid == sub_id:
                return frame[1 + 4 + 8:]


def test_scan_with_ros2msg_schema_and_cdr(bridge: tuple[FoxgloveBridge, Node]) -> None:
    b, _ = bridge
    with connect(f"ws://127.0.0.1:{b.port}", subprotocols=SUBPROTOCOLS) as ws:  # type: ignore[arg-type]
        info = json.loads(ws.recv(timeout=5))
        assert info["op"] == "serverInfo"
        assert {"clientPublish", "services", "parameters"} <= set(info["capabilities"])
        chans = channels(ws, {"/scan", "/tf_static"})
        scan = chans["/scan"]
        assert scan["encoding"] == "cdr" and scan["schemaEncoding"] == "ros2msg"
        assert scan["schemaName"] == "sensor_msgs/msg/LaserScan"
        assert "float32[] ranges" in scan["schema"] and "MSG: std_msgs/Header" in scan["schema"]
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": scan["id"]}]}))
        msg = deserialize(message_data(ws, 7), scan["schemaName"])
        assert msg.header.frame_id == "base_scan" and len(msg.ranges) == 101
        assert msg.ranges[-1] == pytest.approx(2.0)


def test_late_subscriber_gets_tf_static(bridge: tuple[FoxgloveBridge, Node]) -> None:
    b, _ = bridge
    time.sleep(0.3)  # the static transform is long published when the client comes
    with connect(f"ws://127.0.0.1:{b.port}", subprotocols=SUBPROTOCOLS) as ws:  # type: ignore[arg-type]
        tf = channels(ws, {"/tf_static"})["/tf_static"]
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 3, "channelId": tf["id"]}]}))
        msg = deserialize(message_data(ws, 3), "tf2_msgs/msg/TFMessage")
        assert [t.child_frame_id for t in msg.transforms] == ["base_scan"]
        assert msg.transforms[0].transform.translation.x == pytest.approx(0.1)


def test_client_publish_teleop_goes_to_cmd_vel_teleop(bridge: tuple[FoxgloveBridge, Node]) -> None:
    b, node = bridge
    got: list[Any] = []
    node.create_subscription(Twist, "/cmd_vel_teleop", got.append, 10)
    with connect(f"ws://127.0.0.1:{b.port}", subprotocols=SUBPROTOCOLS) as ws:  # type: ignore[arg-type]
        json.loads(ws.recv(timeout=5))
        ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": 1, "topic": "/cmd_vel", "encoding": "cdr", "schemaName": "geometry_msgs/msg/Twist"},
            {"id": 2, "topic": "/cmd_vel", "encoding": "json", "schemaName": "geometry_msgs/msg/Twist"}]}))
        time.sleep(0.2)
        twist = Twist()
        twist.linear.x = 0.25
        ws.send(b"\x01" + struct.pack("<I", 1) + serialize(twist))
        ws.send(b"\x01" + struct.pack("<I", 2) + json.dumps({"angular": {"z": -0.5}}).encode())
        deadline = time.monotonic() + 5
        while len(got) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
    assert [(m.linear.x, m.angular.z) for m in got] == [(0.25, 0.0), (0.0, -0.5)]


def test_service_call(bridge: tuple[FoxgloveBridge, Node]) -> None:
    b, _ = bridge
    with connect(f"ws://127.0.0.1:{b.port}", subprotocols=SUBPROTOCOLS) as ws:  # type: ignore[arg-type]
        services: dict[str, Any] = {}
        deadline = time.monotonic() + 5
        while "/fox_test/trigger" not in services:
            frame = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
            if isinstance(frame, str) and json.loads(frame).get("op") == "advertiseServices":
                services.update({s["name"]: s for s in json.loads(frame)["services"]})
        svc = services["/fox_test/trigger"]
        assert svc["type"] == "std_srvs/srv/Trigger"
        payload = serialize(Trigger.Request())
        enc = b"cdr"
        ws.send(b"\x02" + struct.pack("<III", svc["id"], 42, len(enc)) + enc + payload)
        while True:
            frame = ws.recv(timeout=5)
            if isinstance(frame, bytes) and frame[0] == 0x03:
                _sid, call_id, n = struct.unpack_from("<III", frame, 1)
                assert call_id == 42
                res = deserialize(frame[13 + n:], "std_srvs/srv/Trigger_Response")
                assert res.success and res.message == "done"
                break


def test_parameters_of_local_nodes(bridge: tuple[FoxgloveBridge, Node]) -> None:
    b, node = bridge
    node.declare_parameter("max_speed", 0.3)
    with connect(f"ws://127.0.0.1:{b.port}", subprotocols=SUBPROTOCOLS) as ws:  # type: ignore[arg-type]
        json.loads(ws.recv(timeout=5))

        def reply(request_id: str) -> dict[str, Any]:
            while True:
                frame = ws.recv(timeout=5)
                if isinstance(frame, str):
                    msg = json.loads(frame)
                    if msg.get("op") == "parameterValues" and msg.get("id") == request_id:
                        return {p["name"]: p.get("value") for p in msg["parameters"]}

        ws.send(json.dumps({"op": "getParameters", "parameterNames": ["/fox_test.max_speed"], "id": "a"}))
        assert reply("a") == {"/fox_test.max_speed": 0.3}
        ws.send(json.dumps({"op": "setParameters", "id": "b",
                            "parameters": [{"name": "/fox_test.max_speed", "value": 0.5}]}))
        assert reply("b") == {"/fox_test.max_speed": 0.5}
    assert node.get_parameter("max_speed").value == 0.5


def test_vanished_topic_is_withdrawn(bridge: tuple[FoxgloveBridge, Node]) -> None:
    b, node = bridge
    pub = node.create_publisher(Twist, "/short_lived", 1)
    deadline = time.monotonic() + 3
    while "/short_lived" not in b._topics and time.monotonic() < deadline:
        time.sleep(0.05)
    assert "/short_lived" in b._topics
    node.destroy_publisher(pub)
    while "/short_lived" in b._topics and time.monotonic() < deadline + 3:
        time.sleep(0.05)
    assert "/short_lived" not in b._topics


def _parameter_reply(ws: ClientConnection, request_id: str) -> dict[str, Any]:
    deadline = time.monotonic() + 15
    while True:
        frame = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg.get("op") == "parameterValues" and msg.get("id") == request_id:
                return {p["name"]: p.get("value") for p in msg["parameters"]}


def test_parameter_names_split_at_the_node() -> None:
    from eddiebot.viz.foxglove_bridge import split_parameter_name

    assert split_parameter_name("/controller_server.FollowPath.max_vel_x") == (
        "/controller_server", "FollowPath.max_vel_x")
    assert split_parameter_name("/eddie/ns/slam.resolution") == ("/eddie/ns/slam", "resolution")
    assert split_parameter_name("no_node") == ("", "no_node")


def test_distro_goes_in_the_server_metadata_when_the_sdk_takes_it() -> None:
    from eddiebot.viz.foxglove_bridge import _server_metadata

    def newer(*, name: str | None = None, server_info: dict[str, str] | None = None) -> None:
        return None

    def older(*, name: str | None = None) -> None:
        return None

    assert _server_metadata(newer) == {"server_info": {"ROS_DISTRO": "jazzy"}}
    assert _server_metadata(older) == {}


@pytest.fixture
def remote_graph(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[FoxgloveBridge, Node]]:
    """A bridge in one context and, in another (another Zenoh session: another process as far
    as the graph goes), a node with parameters, both on a private router."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "transport"))
    from _procs import private_router

    from eddiebot.transport import ZenohConfig, connect

    monkeypatch.delenv("EDDIE_TRANSPORT", raising=False)
    with private_router() as env:
        config = ZenohConfig.from_env(env)
        remote_ctx, bridge_ctx = Context(), Context()
        remote = Node("remote_params", context=remote_ctx)
        remote.declare_parameter("max_speed", 0.3)
        remote.declare_parameter("FollowPath.max_vel_x", 0.26)
        remote.declare_parameter("frames", ["map", "odom"])
        connect(remote_ctx, config, required=True)
        connect(bridge_ctx, config, required=True)
        b = FoxgloveBridge(bridge_ctx, BridgeConfig(port=0, discovery_period_s=0.2))
        try:
            yield b, remote
        finally:
            b.stop()
            bridge_ctx.shutdown()
            remote_ctx.shutdown()


def test_parameters_of_nodes_in_other_processes(
        remote_graph: tuple[FoxgloveBridge, Node]) -> None:
    b, remote = remote_graph
    deadline = time.monotonic() + 15
    while "/remote_params" not in b._remote_nodes() and time.monotonic() < deadline:
        time.sleep(0.05)
    with connect(f"ws://127.0.0.1:{b.port}", subprotocols=SUBPROTOCOLS) as ws:  # type: ignore[arg-type]
        json.loads(ws.recv(timeout=5))
        ws.send(json.dumps({"op": "getParameters", "parameterNames": [], "id": "all"}))
        values = _parameter_reply(ws, "all")
        assert values["/remote_params.max_speed"] == 0.3
        assert values["/remote_params.FollowPath.max_vel_x"] == 0.26
        assert values["/remote_params.frames"] == ["map", "odom"]
        assert values["/remote_params.use_sim_time"] is False
        ws.send(json.dumps({"op": "setParameters", "id": "set", "parameters": [
            {"name": "/remote_params.FollowPath.max_vel_x", "value": 0.4}]}))
        assert _parameter_reply(ws, "set") == {"/remote_params.FollowPath.max_vel_x": 0.4}
    assert remote.get_parameter("FollowPath.max_vel_x").value == 0.4
