"""The dashboard's SLAM graph editing: the ``slam`` command as validated, and in headless
Chromium against a stand-in slam_toolbox — the graph drawn with node ids, "Edit graph"
toggles interactive mode, a dragged node reaches ``/slam_toolbox/feedback`` as RViz's marker
feedback in the map frame, "Close loop", "Clear changes" and "Merge session" call the
services, and without a SLAM node the page says so."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from test_dashboard_browser import CHROMIUM, World, browser, client_xy, open_page, wait_js

from eddiebot.msgs.geometry_msgs import Point
from eddiebot.msgs.slam_toolbox import AddSubmap, Clear, LoopClosure, MergeMaps, ToggleInteractive
from eddiebot.msgs.visualization_msgs import InteractiveMarkerFeedback, Marker, MarkerArray
from eddiebot.viz.dashboard import start_dashboard
from eddiebot.viz.dashboard.core import parse_command
from eddiebot.viz.dashboard.errors import CommandError

__all__ = ["browser"]  # the module-scoped Chromium fixture, shared

NODES = [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (2.0, 1.0)]
needs_chromium = pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                    reason=f"{CHROMIUM} is absent (Debian package 'chromium')")


def _cmd(**obj: object) -> str:
    return json.dumps({"op": "slam", **obj})


def test_slam_commands_parse() -> None:
    c = parse_command(_cmd(action="move", node=3, x=1.5, y=-2.0))
    assert (c.op, c.action, c.node, c.x, c.y, c.yaw) == ("slam", "move", 3, 1.5, -2.0, 0.0)
    c = parse_command(_cmd(action="merge", path=" /tmp/other.eslam "))
    assert (c.action, c.path) == ("merge", "/tmp/other.eslam")
    for action in ("interactive", "close_loop", "clear"):
        assert parse_command(_cmd(action=action)).action == action


@pytest.mark.parametrize(("obj", "words"), [
    ({"action": "undo"}, "'action' must be one of interactive, move, close_loop, clear, merge"),
    ({"action": "move", "node": -1, "x": 0, "y": 0}, "'node' must be a node id"),
    ({"action": "move", "node": "4", "x": 0, "y": 0}, "'node' must be a node id"),
    ({"action": "move", "node": True, "x": 0, "y": 0}, "'node' must be a node id"),
    ({"action": "move", "node": 2, "x": 0}, "'y' must be a number"),
    ({"action": "merge", "path": "  "}, "'path' must be the session file's path"),
    ({"action": "merge"}, "'path' must be the session file's path"),
])
def test_bad_slam_commands_are_refused(obj: dict, words: str) -> None:
    with pytest.raises(CommandError) as exc:
        parse_command(_cmd(**obj))
    assert words in str(exc.value) and exc.value.op == "slam"


class SlamStandIn:
    """slam_toolbox's editing services (recording their calls) and its graph markers."""

    def __init__(self, world: World) -> None:
        self.calls: list[tuple[str, str]] = []
        node = world.node
        for kind, name in ((ToggleInteractive, "toggle_interactive_mode"),
                           (LoopClosure, "manual_loop_closure"), (Clear, "clear_changes"),
                           (AddSubmap, "add_submap"), (MergeMaps, "merge_submaps")):
            node.create_service(kind, f"/slam_toolbox/{name}", self._recorder(name))
        self.feedback = world.record(InteractiveMarkerFeedback, "/slam_toolbox/feedback")
        pub = node.create_publisher(MarkerArray, "/slam_toolbox/graph_visualization", 1)
        nodes = Marker(ns="slam_toolbox", id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
        nodes.header.frame_id = "map"
        nodes.pose.orientation.w = 1.0
        nodes.points = [Point(x=x, y=y, z=0.0) for x, y in NODES]
        edges = Marker(ns="slam_toolbox_edges", id=1, type=Marker.LINE_LIST, action=Marker.ADD)
        edges.header.frame_id = "map"
        edges.pose.orientation.w = 1.0
        edges.points = [Point(x=x, y=y, z=0.0) for a, b in zip(NODES, NODES[1:]) for x, y in (a, b)]
        self.timer = node.create_timer(0.2, lambda: pub.publish(MarkerArray(markers=[nodes, edges])))

    def _recorder(self, name: str) -> Any:
        def handle(req: Any, res: Any) -> Any:
            self.calls.append((name, str(getattr(req, "filename", ""))))
            return res
        return handle


@pytest.fixture
def world() -> Iterator[World]:
    w = World()
    yield w
    w.close()


def _wait(pred: Any, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while not pred() and time.monotonic() < deadline:
        time.sleep(0.02)
    return bool(pred())


@needs_chromium
def test_edit_the_slam_graph_from_the_page(browser: Any, world: World, tmp_path: Path) -> None:
    slam = SlamStandIn(world)
    with start_dashboard(world.context, "127.0.0.1", 0, print_url=False) as dash:
        page = open_page(browser, dash.url)
        page.uncheck("#follow")
        wait_js(page, "window.eddie.state.slamGraph && window.eddie.state.slamGraph.count === 4")
        assert page.evaluate("window.eddie.state.slamGraph.nodes") == [v for p in NODES for v in p]
        assert len(page.evaluate("window.eddie.state.slamGraph.edges")) == 12
        # outside interactive mode a drag on a node pans the view and moves nothing
        x0, y0 = client_xy(page, 1.0, 0.0)
        page.mouse.move(x0, y0)
        page.mouse.down()
        page.mouse.move(x0 + 30, y0 - 30)
        page.mouse.up()
        page.click("#slam-interactive")
        wait_js(page, "window.eddie.state.slamEdit === true")
        assert slam.calls == [("toggle_interactive_mode", "")]
        assert slam.feedback == []
        # drag node 1 from (1, 0) to (1, 1)
        x0, y0 = client_xy(page, 1.0, 0.0)
        x1, y1 = client_xy(page, 1.0, 1.0)
        page.mouse.move(x0, y0)
        page.mouse.down()
        page.mouse.move(x0, (y0 + y1) / 2)
        page.mouse.move(x1, y1)
        page.mouse.up()
        assert _wait(lambda: len(slam.feedback) == 1)
        msg = slam.feedback[0][1]
        assert msg.marker_name == "1" and msg.event_type == InteractiveMarkerFeedback.MOUSE_UP
        assert msg.header.frame_id == "map" and msg.mouse_point_valid
        assert abs(msg.mouse_point.x - 1.0) < 0.05 and abs(msg.mouse_point.y - 1.0) < 0.05
        assert page.evaluate("Object.keys(window.eddie.state.staged)") == ["1"]
        page.click("#slam-close")
        assert _wait(lambda: ("manual_loop_closure", "") in slam.calls)
        wait_js(page, "Object.keys(window.eddie.state.staged).length === 0")
        page.click("#slam-clear")
        assert _wait(lambda: ("clear_changes", "") in slam.calls)
        session = str(tmp_path / "other.eslam")
        page.fill("#slam-session", session)
        page.click("#slam-merge")
        assert _wait(lambda: ("merge_submaps", "") in slam.calls)
        assert slam.calls[-2:] == [("add_submap", session), ("merge_submaps", "")]
        page.context.close()


@needs_chromium
def test_without_a_slam_node_the_page_says_so(browser: Any, world: World) -> None:
    with start_dashboard(world.context, "127.0.0.1", 0, print_url=False) as dash:
        page = open_page(browser, dash.url)
        page.click("#slam-interactive")
        wait_js(page, "window.eddie.state.lastError && window.eddie.state.lastError.op === 'slam'")
        text = page.evaluate("window.eddie.state.lastError.msg")
        assert "/slam_toolbox/toggle_interactive_mode does not answer" in text
        assert page.evaluate("window.eddie.state.slamEdit") is False
        page.context.close()

