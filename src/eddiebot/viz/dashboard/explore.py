"""The dashboard's exploration panel: "Map this floor", pause and resume, and progress.

Talks to the explore node (`eddiebot.explore`, explore_lite's node) only over the bus: the
``explore/resume`` service (std_srvs/SetBool; true starts or resumes, false pauses), or,
when an explore node publishes its status but offers no service, the ``explore/resume``
topic (std_msgs/Bool, as explore_lite's ROS 2 port). Progress comes from
``explore/status`` (diagnostic_msgs/DiagnosticStatus: state, paused, finish reason,
frontiers left, known and free map area, time since exploring began), kept as a history
(one point per second of exploring) for the page's chart; the frontiers themselves from
``explore/frontiers`` (visualization_msgs/MarkerArray: POINTS markers of frontier cells,
blue open and red abandoned, SPHERE markers at their centroids), drawn on the map.

The dashboard does not start an explore node (it joins a context and talks to what runs
there, as for navigation and SLAM): ``eddie explore`` with the explore node's
``start_paused`` waits for the button; without an explore node the button says so.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any

from eddiebot.core.qos import QoSProfile, qos_profile_latched
from eddiebot.core.task import Future
from eddiebot.msgs import get_message, get_service
from eddiebot.viz.dashboard.core import text_frame
from eddiebot.viz.dashboard.display import _NS, DisplayNode, _compose, _yaw

__all__ = ["EXPLORE_ACTIONS", "MAX_HISTORY", "ExploreLayers"]

#: the ``explore`` command's actions → the resume value each sends
EXPLORE_ACTIONS = {"start": True, "resume": True, "pause": False}
#: points of the progress history kept (one per second of exploring, the oldest dropped)
MAX_HISTORY = 7200
#: points of it sent to the page (evenly thinned)
SENT_HISTORY = 240
#: frontier cells sent to the page at most (evenly thinned)
MAX_FRONTIER_POINTS = 20000
_POINTS, _SPHERE, _ADD = 8, 2, 0


def _number(text: str) -> float | None:
    try:
        return float(text) if text != "" else None
    except ValueError:
        return None


class ExploreLayers(DisplayNode):
    """The explore node's status, its history, and the ``explore`` commands."""

    _explore: dict[str, Any] | None
    _explore_history: deque[tuple[float, float, float, int | None]]
    _explore_client: Any
    _explore_pub: Any
    _explore_seen_ns: int | None
    _frontiers: tuple[int, Any] | None
    _frontiers_sent: int

    def _setup_explore(self) -> None:
        self._explore = None
        self._frontiers = None
        self._frontiers_sent = 0
        self._explore_history = deque(maxlen=MAX_HISTORY)
        self._explore_seen_ns = None
        self._explore_client = self.create_client(get_service("std_srvs/srv/SetBool"),
                                                  self.topics.explore_resume)
        self._explore_pub = self.create_publisher(get_message("std_msgs/msg/Bool"),
                                                  self.topics.explore_resume, 10)
        self._sub(get_message("diagnostic_msgs/msg/DiagnosticStatus"), self.topics.explore_status,
                  self._on_explore_status,
                  QoSProfile(depth=20, durability=qos_profile_latched.durability))
        self._sub(get_message("visualization_msgs/msg/MarkerArray"), self.topics.explore_frontiers,
                  self._on_frontiers, 2)
        self.create_timer(0.5, self._send_frontiers, clock=self._wall)

    def _on_frontiers(self, msg: Any) -> None:
        seq = self._frontiers[0] + 1 if self._frontiers is not None else 1
        self._frontiers = (seq, msg)

    def _send_frontiers(self) -> None:
        """Post the newest frontiers in the display frame (twice a second at most)."""
        kept = self._frontiers
        if kept is None or kept[0] == self._frontiers_sent:
            return
        frame = self._frontiers_frame(kept[1])
        if frame is not None:
            self._frontiers_sent = kept[0]
            self.hub.post("frontiers", frame)

    def _frontiers_frame(self, msg: Any) -> str | None:
        """``open`` and ``abandoned`` frontier cells and ``centroids`` as flat x, y lists in
        the display frame; None while TF cannot place them."""
        groups: dict[str, list[float]] = {"open": [], "abandoned": [], "centroids": []}
        markers = [m for m in msg.markers if int(m.action) == _ADD and int(m.type) in (_POINTS, _SPHERE)]
        total = sum(len(m.points) for m in markers if int(m.type) == _POINTS)
        step = max(1, -(-total // MAX_FRONTIER_POINTS))
        for m in markers:
            where = self._to_display(m.header.frame_id or "map")
            if where is None:
                self._problems[self.topics.explore_frontiers] = (
                    f"no TF from {m.header.frame_id!r} to {self.display_frame!r}")
                return None
            base = _compose(where, m.pose.position.x, m.pose.position.y, _yaw(m.pose.orientation))
            if int(m.type) == _SPHERE:
                groups["centroids"] += [round(base[0], 3), round(base[1], 3)]
                continue
            key = "abandoned" if m.color.r > m.color.b else "open"
            c, s = math.cos(base[2]), math.sin(base[2])
            for p in m.points[::step]:
                groups[key] += [round(base[0] + c * p.x - s * p.y, 3),
                                round(base[1] + s * p.x + c * p.y, 3)]
        self._problems.pop(self.topics.explore_frontiers, None)
        return text_frame("frontiers", frame=self.display_frame, **groups)

    def _on_explore_status(self, msg: Any) -> None:
        values = {str(kv.key): str(kv.value) for kv in msg.values}
        elapsed = _number(values.get("elapsed_s", ""))
        known = _number(values.get("known_m2", "")) or 0.0
        free = _number(values.get("free_m2", "")) or 0.0
        frontiers = _number(values.get("frontiers", ""))
        n_frontiers = None if frontiers is None else int(frontiers)
        history = self._explore_history
        if elapsed is not None:
            if history and elapsed < history[-1][0]:
                history.clear()  # a new run
            if not history or elapsed - history[-1][0] >= 1.0:
                history.append((round(elapsed, 1), round(known, 2), round(free, 2), n_frontiers))
        self._explore_seen_ns = self._wall.now_ns()
        self._explore = {
            "state": values.get("state", ""), "paused": values.get("paused") == "true",
            "reason": values.get("reason", ""), "message": str(msg.message),
            "level": int.from_bytes(msg.level, "little") if isinstance(msg.level, bytes) else int(msg.level),
            "frontiers": n_frontiers, "abandoned": int(_number(values.get("abandoned", "")) or 0),
            "goals_reached": int(_number(values.get("goals_reached", "")) or 0),
            "known_m2": known, "free_m2": free, "elapsed_s": elapsed,
            "returned_home": {"true": True, "false": False}.get(values.get("returned_home", "")),
            "home_failure": values.get("home_failure", ""),
        }
        self._post_explore()

    def _post_explore(self) -> None:
        history = list(self._explore_history)
        if len(history) > SENT_HISTORY:
            step = len(history) / SENT_HISTORY
            history = [history[int(k * step)] for k in range(SENT_HISTORY - 1)] + [history[-1]]
        self.hub.post("explore", text_frame("explore", **(self._explore or {}),
                                            history=[list(p) for p in history]))

    def explore_state(self) -> dict[str, Any] | None:
        """The explore node's last status (None before one arrived)."""
        return None if self._explore is None else dict(self._explore)

    def explore_command(self, action: str, done: Callable[[bool, str], None]) -> None:
        """Start, pause or resume exploring; ``done(ok, text)`` once sent or answered."""
        resume = EXPLORE_ACTIONS[action]
        status = self._explore
        if status is not None and status["state"] == "done" and resume:
            done(False, f"exploration finished ({status['reason'] or 'stopped'}); "
                        "start a new run with eddie explore")
            return
        client = self._explore_client
        if client.service_is_ready():
            def answered(f: Future) -> None:
                if f.exception() is not None:
                    done(False, f"{client.srv_name}: {f.exception()}")
                    return
                res = f.result()
                done(bool(res.success), f"{client.srv_name}: {res.message}")

            client.call_async(client.srv_type.Request(data=resume)).add_done_callback(answered)
            return
        seen = self._explore_seen_ns
        if seen is not None and self._wall.now_ns() - seen < 5 * _NS:
            self._explore_pub.publish(self._bool_cls(data=resume))
            done(True, f"{'resume' if resume else 'pause'} sent on {self.topics.explore_resume}")
            return
        done(False, f"no explore node: neither {self.topics.explore_resume} (service) answers "
                    f"nor {self.topics.explore_status} is published; start one with "
                    "eddie explore (start_paused:=true waits for this button)")
