"""The dashboard's 2D SLAM graph and its editing: the slam_toolbox graph
(``/slam_toolbox/graph_visualization``, at most once a second) with node ids, and the page's
``slam`` commands — interactive mode, a dragged node (an InteractiveMarkerFeedback
``MOUSE_UP`` on ``/slam_toolbox/feedback``, as RViz's marker client sends), close loop
(``manual_loop_closure``), clear changes, and merging a saved session (``add_submap`` then
``merge_submaps``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from eddiebot.core.task import Future
from eddiebot.msgs import get_message, get_service
from eddiebot.viz.dashboard.core import text_frame
from eddiebot.viz.dashboard.display import _NS, DisplayNode, _compose, _r, _yaw

__all__ = ["SLAM_ACTIONS", "SlamEditLayers"]

#: the ``slam`` command's actions → the slam_toolbox service each calls (``move`` publishes
#: feedback instead; ``merge`` calls ``add_submap`` then ``merge_submaps``)
SLAM_ACTIONS = {
    "interactive": "toggle_interactive_mode",
    "close_loop": "manual_loop_closure",
    "clear": "clear_changes",
    "merge": "add_submap",
    "move": "",
}
_MAX_GRAPH_NODES = 20000


class SlamEditLayers(DisplayNode):
    """The SLAM graph layer and the ``slam`` commands."""

    _slam_graph: tuple[int, Any] | None
    _slam_graph_sent: int
    _slam_clients: dict[str, Any]
    _feedback_pub: Any
    _feedback_cls: Any

    def _setup_slam_edit(self) -> None:
        ns = self.topics.slam_namespace.rstrip("/")
        self._slam_graph = None
        self._slam_graph_sent = 0
        self._feedback_cls = get_message("visualization_msgs/msg/InteractiveMarkerFeedback")
        self._feedback_pub = self.create_publisher(self._feedback_cls, f"{ns}/feedback", 10)
        names = {
            "toggle_interactive_mode": "ToggleInteractive",
            "manual_loop_closure": "LoopClosure",
            "clear_changes": "Clear",
            "add_submap": "AddSubmap",
            "merge_submaps": "MergeMaps",
        }
        self._slam_clients = {
            name: self.create_client(get_service(f"slam_toolbox/srv/{kind}"), f"{ns}/{name}")
            for name, kind in names.items()
        }
        self._sub(get_message("visualization_msgs/msg/MarkerArray"), f"{ns}/graph_visualization",
                  self._on_slam_graph, 1)

    def _on_slam_graph(self, msg: Any) -> None:
        seq = self._slam_graph[0] + 1 if self._slam_graph is not None else 1
        self._slam_graph = (seq, msg)

    def _send_slam_graph(self) -> None:
        """Post the newest graph (from the status tick; at most once a second)."""
        kept = self._slam_graph
        if kept is None or kept[0] == self._slam_graph_sent or self._throttled("slam_graph", _NS):
            return
        frame = self._slam_graph_frame(kept[1])
        if frame is not None:
            self._slam_graph_sent = kept[0]
            self.hub.post("slam_graph", frame)

    def _slam_graph_frame(self, msg: Any) -> str | None:
        """Node positions (index = node id) and edge segments in the display frame."""
        topic = f"{self.topics.slam_namespace.rstrip('/')}/graph_visualization"
        nodes: list[float] = []
        edges: list[float] = []
        for m in msg.markers:
            if m.action != 0 or m.type not in (5, 7, 8):  # LINE_LIST, SPHERE_LIST, POINTS
                continue
            where = self._to_display(m.header.frame_id)
            if where is None:
                self._problems[topic] = (
                    f"no TF from {m.header.frame_id!r} to {self.display_frame!r}")
                return None
            base = _compose(where, m.pose.position.x, m.pose.position.y, _yaw(m.pose.orientation))
            xy = np.array([(p.x, p.y) for p in m.points], np.float64).reshape(-1, 2)
            c, s = math.cos(base[2]), math.sin(base[2])
            flat = np.round(np.stack([base[0] + c * xy[:, 0] - s * xy[:, 1],
                                      base[1] + s * xy[:, 0] + c * xy[:, 1]], 1).reshape(-1), 3)
            if m.type == 5:
                edges += flat[: len(flat) // 4 * 4].tolist()
            else:
                nodes += flat.tolist()
        self._problems.pop(topic, None)
        n = len(nodes) // 2
        truncated = n > _MAX_GRAPH_NODES
        return text_frame("slam_graph", frame=self.display_frame,
                          nodes=nodes[: 2 * _MAX_GRAPH_NODES], edges=edges[: 8 * _MAX_GRAPH_NODES],
                          count=n, truncated=truncated)

    # -- commands (called from the web server's thread) ---------------------------------------
    def slam_command(self, action: str, done: Callable[[bool, str], None], *, node: int = -1,
                     x: float = 0.0, y: float = 0.0, yaw: float = 0.0, path: str = "") -> None:
        """Run one ``slam`` command; ``done(ok, text)`` runs when it is sent or answered."""
        if action == "move":
            done(*self._send_move(node, x, y, yaw))
            return
        if action == "merge":
            self._call("add_submap", done, filename=path,
                       then=lambda: self._call("merge_submaps", done))
            return
        self._call(SLAM_ACTIONS[action], done)

    def _send_move(self, node: int, x: float, y: float, yaw: float) -> tuple[bool, str]:
        """The drag of ``node`` to (x, y) in the display frame, turned by ``yaw``, as
        slam_toolbox's interactive marker feedback in the map frame."""
        graph = self._slam_graph
        frame = graph[1].markers[0].header.frame_id if graph and graph[1].markers else "map"
        where = self._to_display(frame)
        if where is None:
            return False, f"move: no TF from {frame!r} to {self.display_frame!r} yet"
        # display → graph frame: the inverse of the graph frame's pose in the display frame
        c, s = math.cos(where[2]), math.sin(where[2])
        dx, dy = x - where[0], y - where[1]
        mx, my = c * dx + s * dy, -s * dx + c * dy
        msg = self._feedback_cls()
        msg.header.frame_id = frame
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.client_id = self.get_name()
        msg.marker_name = str(int(node))
        msg.event_type = self._feedback_cls.MOUSE_UP
        msg.pose.position.x, msg.pose.position.y = mx, my
        msg.pose.orientation.z, msg.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        msg.mouse_point.x, msg.mouse_point.y = mx, my
        msg.mouse_point_valid = True
        self._feedback_pub.publish(msg)
        return True, f"node {int(node)} moved to ({_r(mx, 2)}, {_r(my, 2)}) in {frame}: staged"

    def _call(self, name: str, done: Callable[[bool, str], None], *,
              then: Callable[[], None] | None = None, **fields: Any) -> None:
        client = self._slam_clients[name]
        if not client.service_is_ready():
            done(False, f"no SLAM editing: {client.srv_name} does not answer "
                        "(slam_toolbox with enable_interactive_mode: true)")
            return
        req = client.srv_type.Request()
        for key, value in fields.items():
            setattr(req, key, value)

        def answered(f: Future) -> None:
            if f.exception() is not None:
                done(False, f"{name}: {f.exception()}")
            elif then is not None:
                then()
            else:
                done(True, f"{name}: done (the SLAM node's log says what changed)")

        client.call_async(req).add_done_callback(answered)
