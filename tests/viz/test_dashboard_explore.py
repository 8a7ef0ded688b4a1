"""Dashboard exploration panel over a real WebSocket: "map this floor" resumes a paused explore
node through its explore/resume service, pause stops it again, the status's known area and
history reach the page, the topic fallback, a finished run and no explore node at all."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from websockets.sync.client import ClientConnection, connect

from eddiebot.core import Context, Node, SingleThreadedExecutor, qos_profile_latched
from eddiebot.core.qos import QoSProfile
from eddiebot.explore.node import ExploreNode
from eddiebot.maps import OccupancyMap, map_to_msg
from eddiebot.msgs.diagnostic_msgs import DiagnosticStatus, KeyValue
from eddiebot.msgs.nav_msgs import OccupancyGrid
from eddiebot.msgs.std_msgs import Bool
from eddiebot.viz.dashboard import CommandError, parse_command, start_dashboard
from eddiebot.viz.dashboard.core import split_binary_frame


class Bus:
    """A wall-clock context with a publisher node (and optionally an explore node) spinning."""

    def __init__(self, explore: bool) -> None:
        self.context = Context()
        self.node = Node("explore_test_pub", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.explore: ExploreNode | None = None
        if explore:
            self.explore = ExploreNode(context=self.context, parameter_overrides={"start_paused": True})
            self.executor.add_node(self.explore)
        # a 10 x 5 m map: 6 x 5 m free, 4 x 5 m occupied, nothing unknown
        cells = np.zeros((100, 200), np.int8)
        cells[:, 120:] = 100
        self.map_pub = self.node.create_publisher(OccupancyGrid, "/map", qos_profile_latched)
        self.map_pub.publish(map_to_msg(OccupancyMap(cells, 0.05, (0.0, 0.0, 0.0)), frame_id="map"))
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.executor.shutdown()
        self.context.shutdown()
        self.thread.join(5)


@pytest.fixture
def bus() -> Iterator[Bus]:
    b = Bus(explore=True)
    yield b
    b.close()


@pytest.fixture
def bare() -> Iterator[Bus]:
    b = Bus(explore=False)
    yield b
    b.close()


def ws_url(url: str) -> str:
    return url.split("?")[0].replace("http://", "ws://") + "ws"


def recv_until(ws: ClientConnection, kind: str, pred: Any = None, timeout: float = 20.0) -> dict[str, Any]:
    """The next text frame of ``kind`` for which ``pred`` holds (generous: a loaded runner)."""
    deadline = time.monotonic() + timeout
    while True:
        frame = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
        head = split_binary_frame(frame)[0] if isinstance(frame, bytes) else json.loads(frame)
        if head["t"] == kind and (pred is None or pred(head)):
            return head


def status(state: str, elapsed: float | None, known: float, frontiers: int | None, **extra: str) -> Any:
    values = {"state": state, "paused": "false", "reason": "", "abandoned": "1", "goals_reached": "4",
              "frontiers": "" if frontiers is None else str(frontiers), "known_m2": f"{known:.2f}",
              "free_m2": f"{known / 2:.2f}", "elapsed_s": "" if elapsed is None else f"{elapsed:.1f}",
              "returned_home": "", "home_failure": "", **extra}
    return DiagnosticStatus(level=0, name="/explore_node", message=f"{state}", hardware_id="",
                            values=[KeyValue(key=k, value=v) for k, v in values.items()])


def test_explore_command_parses() -> None:
    assert parse_command(json.dumps({"op": "explore", "action": "start"})).action == "start"
    for bad in ({"op": "explore"}, {"op": "explore", "action": "go"}, {"op": "explore", "action": 1}):
        with pytest.raises(CommandError, match="explore: 'action' must be one of start, pause, resume"):
            parse_command(json.dumps(bad))


def test_map_this_floor_resumes_the_paused_explore_node_and_pause_stops_it(bus: Bus) -> None:
    assert bus.explore is not None and bus.explore.paused
    with start_dashboard(bus.context, "127.0.0.1", 0, print_url=False) as dash, \
            connect(ws_url(dash.url), origin=dash.url.rstrip("/")) as ws:  # type: ignore[arg-type]
        # the node's status: waiting (no navigation server here), paused, the map's areas
        first = recv_until(ws, "explore", lambda f: f["known_m2"] > 0)
        assert (first["state"], first["paused"]) == ("waiting", True)
        assert first["known_m2"] == pytest.approx(50.0)
        assert first["free_m2"] == pytest.approx(30.0)
        assert first["frontiers"] is None and first["elapsed_s"] is None
        assert first["message"] == "paused (waiting)"
        ws.send(json.dumps({"op": "explore", "action": "start"}))
        ack = recv_until(ws, "ack", lambda f: f["op"] == "explore")
        assert ack["msg"] == "/explore/resume: exploring" and ack["action"] == "start"
        assert not bus.explore.paused
        resumed = recv_until(ws, "explore", lambda f: not f["paused"])
        assert resumed["message"] == "waiting"
        ws.send(json.dumps({"op": "explore", "action": "pause"}))
        ack = recv_until(ws, "ack", lambda f: f["op"] == "explore")
        assert ack["msg"] == "/explore/resume: paused"
        assert bus.explore.paused
        assert recv_until(ws, "explore", lambda f: f["paused"])["state"] == "waiting"


def test_progress_history_topic_fallback_and_a_finished_run(bare: Bus) -> None:
    pub = bare.node.create_publisher(DiagnosticStatus, "/explore/status", QoSProfile(
        depth=20, durability=qos_profile_latched.durability))
    resumes: list[bool] = []
    bare.node.create_subscription(Bool, "/explore/resume", lambda m: resumes.append(bool(m.data)), 10)
    with start_dashboard(bare.context, "127.0.0.1", 0, print_url=False) as dash, \
            connect(ws_url(dash.url), origin=dash.url.rstrip("/")) as ws:  # type: ignore[arg-type]
        # nothing publishes the status and no service answers: one clear refusal
        ws.send(json.dumps({"op": "explore", "action": "start"}))
        err = recv_until(ws, "error", lambda f: f["op"] == "explore")
        assert err["msg"].startswith("no explore node")
        # a minute of exploring, one status every 10 s (and a repeat 0.4 s later: kept once)
        for k in range(7):
            pub.publish(status("exploring", 10.0 * k, 20.0 + 5.0 * k, 9 - k))
            if k == 3:
                pub.publish(status("exploring", 30.4, 36.0, 6))
        last = recv_until(ws, "explore", lambda f: f["elapsed_s"] == 60.0)
        assert [p[0] for p in last["history"]] == [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0]
        assert [p[1] for p in last["history"]] == [20.0, 25.0, 30.0, 35.0, 40.0, 45.0, 50.0]
        assert [p[3] for p in last["history"]] == [9, 8, 7, 6, 5, 4, 3]
        assert (last["frontiers"], last["goals_reached"], last["abandoned"]) == (3, 4, 1)
        # no service, but a status came: pause goes out on the explore/resume topic
        ws.send(json.dumps({"op": "explore", "action": "pause"}))
        ack = recv_until(ws, "ack", lambda f: f["op"] == "explore")
        assert ack["msg"] == "pause sent on /explore/resume"
        deadline = time.monotonic() + 10
        while not resumes and time.monotonic() < deadline:
            time.sleep(0.05)
        assert resumes == [False]
        # done: a start is refused with the reason
        pub.publish(status("done", 75.0, 52.0, 0, reason="no reachable frontier left",
                           returned_home="false"))
        done = recv_until(ws, "explore", lambda f: f["state"] == "done")
        assert done["returned_home"] is False and len(done["history"]) == 8
        ws.send(json.dumps({"op": "explore", "action": "start"}))
        err = recv_until(ws, "error", lambda f: f["op"] == "explore")
        assert err["msg"].startswith("exploration finished (no reachable frontier left)")
        assert resumes == [False]


def test_frontiers_reach_the_page_in_the_display_frame(bare: Bus) -> None:
    from eddiebot.core.tf import make_transform_2d
    from eddiebot.msgs.geometry_msgs import Point
    from eddiebot.msgs.tf2_msgs import TFMessage
    from eddiebot.msgs.visualization_msgs import Marker, MarkerArray

    tf_pub = bare.node.create_publisher(TFMessage, "/tf", 100)

    def tick() -> None:
        now = bare.node.get_clock().now().nanoseconds
        tf_pub.publish(TFMessage(transforms=[
            make_transform_2d("map", "odom", now, 0.0, 0.0, 0.0),
            make_transform_2d("odom", "base_footprint", now, 1.0, 2.0, 0.5)]))

    bare.node.create_timer(0.05, tick)

    def cells(k: int, pts: list[tuple[float, float]], rgb: tuple[float, float, float]) -> Any:
        m = Marker(ns="frontiers", id=k, type=Marker.POINTS, action=Marker.ADD)
        m.header.frame_id = "map"
        m.pose.orientation.w = 1.0
        m.color.r, m.color.g, m.color.b, m.color.a = (*rgb, 1.0)
        m.points = [Point(x=x, y=y, z=0.0) for x, y in pts]
        return m

    dot = Marker(ns="frontiers", id=1, type=Marker.SPHERE, action=Marker.ADD)
    dot.header.frame_id = "map"
    dot.pose.position.x, dot.pose.position.y = 2.5, 4.25
    dot.pose.orientation.w = 1.0
    gone = Marker(ns="frontiers", id=9, action=Marker.DELETE)
    markers = MarkerArray(markers=[cells(0, [(2.0, 4.0), (2.05, 4.0), (2.1, 4.05)], (0.0, 0.0, 1.0)), dot,
                                   cells(2, [(-1.5, 0.5)], (1.0, 0.0, 0.0)), gone])
    pub = bare.node.create_publisher(MarkerArray, "/explore/frontiers", 10)
    with start_dashboard(bare.context, "127.0.0.1", 0, print_url=False) as dash, \
            connect(ws_url(dash.url), origin=dash.url.rstrip("/")) as ws:  # type: ignore[arg-type]
        recv_until(ws, "pose", lambda f: f["frame"] == "map")
        pub.publish(markers)
        frame = recv_until(ws, "frontiers")
        assert frame["frame"] == "map"
        assert frame["open"] == [2.0, 4.0, 2.05, 4.0, 2.1, 4.05]
        assert frame["abandoned"] == [-1.5, 0.5]
        assert frame["centroids"] == [2.5, 4.25]
        # the next plan: no frontier left
        pub.publish(MarkerArray(markers=[Marker(ns="frontiers", id=k, action=Marker.DELETE)
                                         for k in range(3)]))
        empty = recv_until(ws, "frontiers")
        assert empty["open"] == [] and empty["abandoned"] == [] and empty["centroids"] == []
