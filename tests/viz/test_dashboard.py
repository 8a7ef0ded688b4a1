"""Dashboard: tiling, command validation, rate limits, and the server's security and
robustness over a real WebSocket (no browser needed)."""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import ClientConnection, connect

from eddiebot.core import Context, Node, SingleThreadedExecutor, qos_profile_latched
from eddiebot.core.tf import make_transform_2d
from eddiebot.maps import OccupancyMap, map_to_msg
from eddiebot.msgs.geometry_msgs import PoseStamped, Twist
from eddiebot.msgs.nav_msgs import OccupancyGrid
from eddiebot.msgs.std_msgs import Bool
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.viz.dashboard import (
    CommandError,
    GridMeta,
    TileCache,
    TokenBucket,
    parse_command,
    start_dashboard,
)
from eddiebot.viz.dashboard.core import split_binary_frame


# -- pure parts ------------------------------------------------------------------------
def test_tile_cache_resends_only_changed_tiles() -> None:
    cells = np.full((300, 400), -1, np.int8)  # 20 x 15 m at 0.05 m
    meta = GridMeta(400, 300, 0.05, (-10.0, -7.5, 0.0), "map")
    cache = TileCache(tile=64)
    new, tiles = cache.update(meta, cells)
    assert new and len(tiles) == 7 * 5
    assert tiles[0][4][0] == 255  # unknown on the wire
    cells[10, 10] = 100
    cells[299, 399] = 0
    new, tiles = cache.update(meta, cells)
    assert not new
    assert sorted((t[0], t[1]) for t in tiles) == [(0, 0), (6, 4)]
    assert (tiles[-1][2], tiles[-1][3]) == (400 - 6 * 64, 300 - 4 * 64)
    assert cache.update(meta, cells)[1] == []
    moved = GridMeta(400, 300, 0.05, (-10.0, -7.0, 0.0), "map")
    new, tiles = cache.update(moved, cells)
    assert new and len(tiles) == 35 and cache.generation == 2


def test_parse_command_refuses_bad_input() -> None:
    bounds = (-10.0, -7.5, 10.0, 7.5)
    goal = parse_command(json.dumps({"op": "goal", "x": 1, "y": 2, "yaw": 7.0}), bounds)
    assert goal.op == "goal" and goal.x == 1.0 and goal.yaw == pytest.approx(7.0 - 2 * math.pi)
    bad = [
        "{not json", "[1, 2]", json.dumps({"op": "reboot"}),
        '{"op": "goal", "x": NaN, "y": 0, "yaw": 0}',
        json.dumps({"op": "goal", "x": 11.0, "y": 0, "yaw": 0}),
        json.dumps({"op": "initialpose", "x": "1", "y": 0, "yaw": 0}),
        json.dumps({"op": "teleop", "linear": 5.0, "angular": 0}),
        json.dumps({"op": "teleop", "linear": True, "angular": 0}),
        json.dumps({"op": "estop", "engage": "yes"}),
        json.dumps({"op": "goal", "x": 0, "y": 0, "yaw": 0, "pad": "x" * 5000}),
    ]
    for raw in bad:
        with pytest.raises(CommandError):
            parse_command(raw, bounds)
    assert parse_command(json.dumps({"op": "goal", "x": 50, "y": 0, "yaw": 0}), None).x == 50


def test_token_bucket() -> None:
    bucket = TokenBucket(rate=10.0, burst=5.0)
    for _ in range(5):
        bucket.take(0.0)
    with pytest.raises(CommandError):
        bucket.take(0.0)
    bucket.take(0.1)  # one token back after 0.1 s
    with pytest.raises(CommandError):
        bucket.take(0.1)


# -- a live dashboard -------------------------------------------------------------------
class Graph:
    """A wall-clock context with a publisher node spinning in a thread."""

    def __init__(self) -> None:
        self.context = Context()
        self.node = Node("test_pub", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.received: dict[str, list[Any]] = {}
        self.lock = threading.Lock()

    def record(self, cls: Any, topic: str) -> list[Any]:
        out: list[Any] = []

        def cb(msg: Any) -> None:
            with self.lock:
                out.append((time.monotonic(), msg))

        self.node.create_subscription(cls, topic, cb, 100)
        return out

    def publish_world(self) -> None:
        cells = np.zeros((300, 400), np.int8)
        cells[:, :40] = -1
        cells[100:140, 100:160] = 100
        grid = OccupancyMap(data=cells, resolution=0.05, origin=(-10.0, -7.5, 0.0))
        self.map_pub = self.node.create_publisher(OccupancyGrid, "/map", qos_profile_latched)
        self.map_pub.publish(map_to_msg(grid, frame_id="map"))
        self.tf_pub = self.node.create_publisher(TFMessage, "/tf", 100)

        def tick() -> None:
            now = self.node.get_clock().now().nanoseconds
            self.tf_pub.publish(TFMessage(transforms=[
                make_transform_2d("map", "odom", now, 0.0, 0.0, 0.0),
                make_transform_2d("odom", "base_footprint", now, 1.0, 2.0, 0.5)]))

        tick()
        self.node.create_timer(0.05, tick)

    def close(self) -> None:
        self.executor.shutdown()
        self.context.shutdown()
        self.thread.join(5)


def wait_for(pred: Any, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.01)
    return bool(pred())


@pytest.fixture
def graph() -> Iterator[Graph]:
    g = Graph()
    yield g
    g.close()


def ws_url(url: str, token: str | None = None) -> str:
    base = url.split("?")[0].replace("http://", "ws://") + "ws"
    return f"{base}?token={token}" if token else base


def origin_of(url: str) -> str:
    return url.split("?")[0].rstrip("/")


def recv_until(ws: ClientConnection, kind: str, timeout: float = 3.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        frame = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
        head = split_binary_frame(frame)[0] if isinstance(frame, bytes) else json.loads(frame)
        if head["t"] == kind:
            return head


def test_page_and_initial_state(graph: Graph) -> None:
    graph.publish_world()
    with start_dashboard(graph.context, "127.0.0.1", 0, print_url=False) as dash:
        import urllib.request

        with urllib.request.urlopen(dash.url) as resp:
            page = resp.read().decode()
            assert "<canvas" in page and "http" not in page.split("<body>")[1]
            assert "default-src 'self'" in resp.headers["Content-Security-Policy"]
        with connect(ws_url(dash.url), origin=origin_of(dash.url)) as ws:  # type: ignore[arg-type]
            hello = recv_until(ws, "hello")
            assert hello["read_only"] is False
            grid = recv_until(ws, "grid")
            while grid["origin"] is None:
                grid = recv_until(ws, "grid")
            assert (grid["w"], grid["h"], grid["origin"]) == (400, 300, [-10.0, -7.5, 0.0])
            pose = recv_until(ws, "pose")
            assert (pose["frame"], pose["x"], pose["y"], pose["yaw"]) == ("map", 1.0, 2.0, 0.5)
            # one map cell changes: one tile comes again, not 35
            cells = np.zeros((300, 400), np.int8)
            cells[:, :40] = -1
            cells[100:140, 100:160] = 100
            cells[5, 300] = 100
            tiles = []
            graph.map_pub.publish(map_to_msg(OccupancyMap(cells, 0.05, (-10.0, -7.5, 0.0)), frame_id="map"))
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline:
                try:
                    frame = ws.recv(timeout=0.2)
                except TimeoutError:
                    break
                if isinstance(frame, bytes) and split_binary_frame(frame)[0]["t"] == "tile":
                    tiles.append(split_binary_frame(frame)[0])
            assert [(t["tx"], t["ty"]) for t in tiles] == [(4, 0)]


def test_security_token_origin_and_read_only(graph: Graph) -> None:
    with start_dashboard(graph.context, "127.0.0.1", 0, token="s3cret", print_url=False,
                         read_only=True) as dash:
        import urllib.error
        import urllib.request

        assert dash.url.endswith("?token=s3cret")
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(dash.url.replace("s3cret", "wrong"))
        assert err.value.code == 401
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(dash.url.split("?")[0])
        assert err.value.code == 401
        origin = origin_of(dash.url)
        with pytest.raises(InvalidStatus):
            connect(ws_url(dash.url, "wrong"), origin=origin)  # type: ignore[arg-type]
        with pytest.raises(InvalidStatus):
            connect(ws_url(dash.url), origin=origin)  # type: ignore[arg-type]
        with pytest.raises(InvalidStatus):
            connect(ws_url(dash.url, "s3cret"), origin="http://evil.example")  # type: ignore[arg-type]
        cmd_vel = graph.record(Twist, "/cmd_vel_teleop")
        with connect(ws_url(dash.url, "s3cret"), origin=origin) as ws:  # type: ignore[arg-type]
            assert recv_until(ws, "hello")["read_only"] is True
            ws.send(json.dumps({"op": "teleop", "linear": 0.2, "angular": 0.0}))
            err_msg = recv_until(ws, "error")
            assert "read-only" in err_msg["msg"]
        assert cmd_vel == []


def test_foreign_origin_refused_on_loopback(graph: Graph) -> None:
    with start_dashboard(graph.context, "127.0.0.1", 0, print_url=False) as dash:
        with pytest.raises(InvalidStatus) as err:
            connect(ws_url(dash.url), origin="http://evil.example")  # type: ignore[arg-type]
        assert err.value.response.status_code == 403
        with pytest.raises(InvalidStatus):  # DNS rebinding: a foreign Host name
            connect(ws_url(dash.url), additional_headers={"Host": "evil.example"})


def test_non_loopback_bind_gets_a_token(graph: Graph) -> None:
    with start_dashboard(graph.context, "0.0.0.0", 0, print_url=False) as dash:
        assert dash.token and len(dash.token) >= 20 and f"?token={dash.token}" in dash.url


def test_bad_messages_floods_and_estop(graph: Graph) -> None:
    graph.publish_world()
    cmd_vel = graph.record(Twist, "/cmd_vel_teleop")
    e_stop = graph.record(Bool, "/e_stop")
    goals = graph.record(PoseStamped, "/goal_pose")
    with (
        start_dashboard(graph.context, "127.0.0.1", 0, print_url=False) as dash,
        connect(ws_url(dash.url), origin=origin_of(dash.url)) as ws,  # type: ignore[arg-type]
    ):
        recv_until(ws, "pose")
        for raw in ("{oops", "x" * 20000, json.dumps({"op": "goal", "x": 50.0, "y": 0, "yaw": 0}),
                    '{"op": "goal", "x": NaN, "y": 0, "yaw": 0}'):
            ws.send(raw)
            assert recv_until(ws, "error")["msg"]
        ws.send(b"\x00\xff" * 10)
        assert recv_until(ws, "error")
        ws.send(json.dumps({"op": "goal", "x": 2.0, "y": -1.0, "yaw": 1.0}))
        assert "goal_pose" in recv_until(ws, "ack")["msg"]
        ws.send(json.dumps({"op": "estop"}))
        assert recv_until(ws, "ack")["msg"] == "e-stop engaged"
        assert wait_for(lambda: e_stop and e_stop[-1][1].data is True)
        assert wait_for(lambda: cmd_vel and cmd_vel[-1][1].linear.x == 0.0)
        ws.send(json.dumps({"op": "teleop", "linear": 0.1, "angular": 0.0}))
        assert "emergency stop" in recv_until(ws, "error")["msg"]
        ws.send(json.dumps({"op": "estop"}))
        assert recv_until(ws, "ack")["msg"] == "e-stop released"
        assert wait_for(lambda: e_stop[-1][1].data is False)
        for _ in range(80):  # a teleop flood
            ws.send(json.dumps({"op": "teleop", "linear": 0.1, "angular": 0.0}))
        assert "teleop refused" in recv_until(ws, "error")["msg"]
        ws.send(json.dumps({"op": "teleop", "linear": 0.0, "angular": 0.0}))
        ws.send(json.dumps({"op": "ping"}))
        recv_until(ws, "pong")
        assert wait_for(lambda: len(goals) == 1)
        g = goals[0][1]
        assert (g.header.frame_id, g.pose.position.x, g.pose.position.y) == ("map", 2.0, -1.0)
        assert dash.is_alive()


def test_teleop_held_then_dropped_connection_stops(graph: Graph) -> None:
    cmd_vel = graph.record(Twist, "/cmd_vel_teleop")
    with (
        start_dashboard(graph.context, "127.0.0.1", 0, print_url=False) as dash,
        connect(ws_url(dash.url), origin=origin_of(dash.url)) as ws,  # type: ignore[arg-type]
    ):
        recv_until(ws, "hello")
        ws.send(json.dumps({"op": "teleop", "linear": 0.2, "angular": 0.5}))
        assert wait_for(lambda: len(cmd_vel) >= 4, 2.0)  # the server repeats at 10 Hz
        assert wait_for(lambda: cmd_vel[-1][1].linear.x == 0.0, 2.0)
        n = len(cmd_vel)
        time.sleep(0.3)
        assert len(cmd_vel) == n  # nothing after the stop


def test_goal_via_action_estop_cancels_and_save_map(graph: Graph) -> None:
    from eddiebot.core import ActionServer, CancelResponse
    from eddiebot.core.action import sleep
    from eddiebot.msgs import get_action, get_service
    from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped

    nav = get_action("nav2_msgs/action/NavigateToPose")
    goals: list[Any] = []
    outcome: list[str] = []

    async def execute(handle: Any) -> Any:
        goals.append(handle.request.pose)
        while not handle.is_cancel_requested:
            await sleep(graph.node, 0.02)
        handle.canceled()
        outcome.append("canceled")
        return nav.Result()

    ActionServer(graph.node, nav, "navigate_to_pose", execute,
                 cancel_callback=lambda h: CancelResponse.ACCEPT)
    save = get_service("nav2_msgs/srv/SaveMap")
    saved: list[str] = []

    def on_save(req: Any, res: Any) -> Any:
        saved.append(req.map_url)
        res.result = True
        return res

    graph.node.create_service(save, "/map_saver/save_map", on_save)
    initial = graph.record(PoseWithCovarianceStamped, "/initialpose")
    graph.publish_world()
    with (
        start_dashboard(graph.context, "127.0.0.1", 0, print_url=False) as dash,
        connect(ws_url(dash.url), origin=origin_of(dash.url)) as ws,  # type: ignore[arg-type]
    ):
        recv_until(ws, "pose")
        ws.send(json.dumps({"op": "goal", "x": 3.0, "y": 1.0, "yaw": -0.5}))
        assert "navigate_to_pose" in recv_until(ws, "ack")["msg"]
        assert wait_for(lambda: len(goals) == 1)
        assert (goals[0].pose.position.x, goals[0].header.frame_id) == (3.0, "map")
        ws.send(json.dumps({"op": "estop", "engage": True}))
        assert recv_until(ws, "ack")["msg"] == "e-stop engaged"
        assert wait_for(lambda: outcome == ["canceled"])
        ws.send(json.dumps({"op": "estop", "engage": False}))
        assert recv_until(ws, "ack")["msg"] == "e-stop released"
        ws.send(json.dumps({"op": "initialpose", "x": 0.5, "y": -0.5, "yaw": 3.0}))
        assert recv_until(ws, "ack")["op"] == "initialpose"
        ws.send(json.dumps({"op": "save_map", "name": "office"}))
        ack = recv_until(ws, "ack")
        assert ack["op"] == "save_map" and "saved" in ack["msg"]
    assert saved == ["office"]
    assert wait_for(lambda: len(initial) == 1)
    p = initial[0][1].pose
    assert (p.pose.position.x, p.pose.position.y) == (0.5, -0.5)
    assert p.covariance[0] == 0.25 and 2 * math.atan2(p.pose.orientation.z, p.pose.orientation.w) == pytest.approx(3.0)


def test_images_and_missing_topics(graph: Graph) -> None:
    from eddiebot.msgs.sensor_msgs import Image

    pub = graph.node.create_publisher(Image, "/image_raw", 5)
    with (
        start_dashboard(graph.context, "127.0.0.1", 0, print_url=False) as dash,
        connect(ws_url(dash.url), origin=origin_of(dash.url)) as ws,  # type: ignore[arg-type]
    ):
        status = recv_until(ws, "status")
        assert status["age"]["/image_raw"] is None and status["age"]["/map"] is None
        img = np.zeros((480, 640, 3), np.uint8)
        pub.publish(Image(height=480, width=640, encoding="rgb8", step=1920, data=img.reshape(-1)))
        deadline = time.monotonic() + 3
        while True:
            frame = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
            if isinstance(frame, bytes):
                head, payload = split_binary_frame(frame)
                if head["t"] == "image":
                    break
        assert head["name"] == "camera" and payload[:2] == b"\xff\xd8"  # a JPEG
        pub.publish(Image(height=2, width=2, encoding="yuv422", step=4, data=np.zeros(8, np.uint8)))
        time.sleep(0.25)  # images are taken at most every 0.2 s
        pub.publish(Image(height=2, width=2, encoding="yuv422", step=4, data=np.zeros(8, np.uint8)))
        status = recv_until(ws, "status")
        while "/image_raw" not in status["problems"]:
            status = recv_until(ws, "status")
        assert "yuv422" in status["problems"]["/image_raw"]


def test_sim_time_context_is_not_driven_by_the_dashboard() -> None:
    context = Context(use_sim_time=True)
    with (
        start_dashboard(context, "127.0.0.1", 0, print_url=False) as dash,
        connect(ws_url(dash.url), origin=origin_of(dash.url)) as ws,  # type: ignore[arg-type]
    ):
        recv_until(ws, "status")
        recv_until(ws, "status")  # wall-clock timers tick on a sim-time context
        assert context.sim_clock.now_ns() == 0
    context.shutdown()


# -- layers and views ----------------------------------------------------------------------
def test_view_commands_parse_and_urdf_footprint() -> None:
    from eddiebot.robot.urdf import BASE_RADIUS_M, eddie_urdf
    from eddiebot.viz.dashboard.node import footprint_from_urdf

    cmd = parse_command(json.dumps({"op": "view", "name": "cloud", "engage": True}))
    assert (cmd.op, cmd.name, cmd.engage) == ("view", "cloud", True)
    for bad in ({"op": "view", "name": "camera", "engage": True},
                {"op": "view", "name": "tf", "engage": 1}, {"op": "view", "name": "tf"}):
        with pytest.raises(CommandError, match="view"):
            parse_command(json.dumps(bad))
    assert footprint_from_urdf(eddie_urdf()) == BASE_RADIUS_M == 0.2245
    assert footprint_from_urdf("<robot name='r'><link name='base_link'/></robot>") is None
    with pytest.raises(ValueError, match="not valid XML"):
        footprint_from_urdf("<robot")


def test_hub_sends_view_frames_only_to_pages_that_opened_the_view() -> None:
    import asyncio

    from eddiebot.viz.dashboard import Hub

    async def run() -> tuple[list[Any], list[Any], int, list[Any]]:
        hub = Hub()
        loop = asyncio.get_running_loop()
        a, b = hub.attach(loop), hub.attach(loop)
        hub.post("pose", "p0")
        assert not hub.view_open("cloud")
        hub.post("cloud:points", b"c0", view="cloud")  # nobody has it open: retained only
        opened = hub.set_view(a, "cloud", True)
        hub.post("cloud:points", b"c1", view="cloud")
        got_a, got_b = await a.next_batch(), await b.next_batch()
        hub.set_view(a, "cloud", False)
        hub.post("cloud:points", b"c2", view="cloud")
        hub.post("pose", "p1")
        return got_a, got_b, opened, await a.next_batch()

    got_a, got_b, opened, later = asyncio.run(run())
    assert opened == 1
    assert got_a == ["p0", b"c1"] and got_b == ["p0"]
    assert later == ["p1"]


def test_read_only_page_opens_views_particles_decimated_and_mux_source(graph: Graph) -> None:
    from eddiebot.msgs.geometry_msgs import Point, Pose, Quaternion
    from eddiebot.msgs.nav2_msgs import Particle, ParticleCloud
    from eddiebot.msgs.sensor_msgs import PointCloud2, PointField
    from eddiebot.msgs.std_msgs import Header
    from eddiebot.viz.dashboard.node import MAX_LIVE_POINTS, MAX_PARTICLES

    graph.publish_world()
    n_part = 3 * MAX_PARTICLES + 7
    cloud_pub = graph.node.create_publisher(ParticleCloud, "/particle_cloud", 10)
    points_pub = graph.node.create_publisher(PointCloud2, "/points", 10)
    n_pts = 2 * MAX_LIVE_POINTS + 1
    xyz = np.zeros((n_pts, 3), np.float32)
    xyz[:, 0] = np.arange(n_pts) * 1e-4  # x = k * 0.1 mm for point k
    xyz[6] = np.nan  # an invalid point is left out
    fields = [PointField(name=k, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, k in enumerate("xyz")]
    with start_dashboard(graph.context, "127.0.0.1", 0, read_only=True, print_url=False) as dash, \
            connect(ws_url(dash.url), origin=origin_of(dash.url)) as ws:  # type: ignore[arg-type]
        recv_until(ws, "pose")
        cloud_pub.publish(ParticleCloud(header=Header(frame_id="odom"), particles=[
            Particle(pose=Pose(position=Point(x=0.5, y=0.0, z=0.0),
                               orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)), weight=1.0)
            for _ in range(n_part)]))
        head = recv_until(ws, "particles")
        assert (head["total"], head["n"]) == (n_part, math.ceil(n_part / 4))  # every 4th
        status = recv_until(ws, "status")
        assert status["mux"] == {"active": None, "topic": None, "locks": [],
                                 "table": "twist_mux defaults"}
        points_pub.publish(PointCloud2(
            header=Header(frame_id="base_footprint"), height=1, width=n_pts, fields=fields,
            is_bigendian=False, point_step=12, row_step=12 * n_pts,
            data=xyz.view(np.uint8).reshape(-1), is_dense=False))
        ws.send(json.dumps({"op": "view", "name": "cloud", "engage": True}))
        assert recv_until(ws, "ack")["msg"] == "cloud view opened"  # read-only may look
        deadline = time.monotonic() + 3.0
        cloud = None
        while cloud is None and time.monotonic() < deadline:
            frame = ws.recv(timeout=3.0)
            if isinstance(frame, bytes) and split_binary_frame(frame)[0]["t"] == "cloud":
                cloud = split_binary_frame(frame)
        assert cloud is not None
        head, payload = cloud
        # every 3rd point, less the invalid one
        assert (head["name"], head["total"], head["n"]) == ("points", n_pts, math.ceil(n_pts / 3) - 1)
        assert head["n"] <= MAX_LIVE_POINTS
        pts = np.frombuffer(payload, np.float32).reshape(-1, 3)
        assert len(pts) == head["n"]
        # pts[2] is point 9, in the robot's frame at (1, 2) heading 0.5 rad in the map
        x9 = 9e-4
        assert pts[2] == pytest.approx([1.0 + x9 * math.cos(0.5), 2.0 + x9 * math.sin(0.5), 0.0],
                                       abs=1e-5)
        ws.send(json.dumps({"op": "goal", "x": 1.0, "y": 1.0, "yaw": 0.0}))
        assert "read-only" in recv_until(ws, "error")["msg"]
