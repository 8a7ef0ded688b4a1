"""The dashboard's navigation layers: global and local plans, the goal, AMCL's particle
cloud (at most ``MAX_PARTICLES`` at 5 Hz) and the controller's lookahead point.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from eddiebot.viz.dashboard.core import binary_frame, text_frame
from eddiebot.viz.dashboard.display import _NS, DisplayNode, _compose, _r, _yaw

__all__ = ["MAX_PARTICLES", "PlanLayers"]

#: particles sent per cloud (more are decimated evenly)
MAX_PARTICLES = 5000


class PlanLayers(DisplayNode):
    """Plans, goal, particles and lookahead in the display frame."""

    _goal: dict[str, Any] | None

    def _on_path(self, name: str, topic: str, msg: Any) -> None:
        key = f"path:{name}"
        self._replay[key] = (functools.partial(self._on_path, name, topic), msg)
        frame = msg.header.frame_id or (msg.poses[0].header.frame_id if msg.poses else "")
        where = self._to_display(frame)
        if where is None:
            self._problems[topic] = f"no TF from {frame!r} to {self.display_frame!r}"
            self._unplaced.add(key)
            return
        self._problems.pop(topic, None)
        self._unplaced.discard(key)
        poses = msg.poses
        step = max(1, len(poses) // 400)
        pts = []
        for p in poses[::step]:
            x, y, _ = _compose(where, p.pose.position.x, p.pose.position.y, 0.0)
            pts.append([round(x, 3), round(y, 3)])
        self.hub.post(f"path:{name}", text_frame("path", name=name, pts=pts))

    def _on_goal_pose(self, msg: Any) -> None:
        where = self._to_display(msg.header.frame_id)
        if where is None:
            return
        p = msg.pose
        self._set_goal(_compose(where, p.position.x, p.position.y, _yaw(p.orientation)), "published")

    def _set_goal(self, pose: tuple[float, float, float] | None, status: str) -> None:
        if pose is not None:
            self._goal = {"x": _r(pose[0]), "y": _r(pose[1]), "yaw": _r(pose[2])}
        self.hub.post("goal", text_frame("goal", pose=self._goal, status=status))

    def _on_particles(self, msg: Any) -> None:
        if self._throttled("particles", _NS // 5):
            return
        where = self._to_display(msg.header.frame_id)
        if where is None:
            self._problems[self.topics.particle_cloud] = (
                f"no TF from {msg.header.frame_id!r} to {self.display_frame!r}")
            return
        self._problems.pop(self.topics.particle_cloud, None)
        parts = msg.particles
        step = max(1, -(-len(parts) // MAX_PARTICLES))
        a = np.array([(p.pose.position.x, p.pose.position.y, p.pose.orientation.z,
                       p.pose.orientation.w, p.weight) for p in parts[::step]],
                     dtype=np.float64).reshape(-1, 5)
        c, s = math.cos(where[2]), math.sin(where[2])
        out = np.empty((a.shape[0], 4), np.float32)
        out[:, 0] = where[0] + c * a[:, 0] - s * a[:, 1]
        out[:, 1] = where[1] + s * a[:, 0] + c * a[:, 1]
        out[:, 2] = 2.0 * np.arctan2(a[:, 2], a[:, 3]) + where[2]
        out[:, 3] = a[:, 4]
        self.hub.post("particles", binary_frame(
            {"t": "particles", "frame": self.display_frame, "n": int(a.shape[0]),
             "total": len(parts)}, out.tobytes()))

    def _on_lookahead(self, msg: Any) -> None:
        self._replay["lookahead"] = (self._on_lookahead, msg)
        if self._throttled("lookahead", _NS // 10):
            return
        where = self._to_display(msg.header.frame_id)
        if where is None:
            self._unplaced.add("lookahead")
            return
        self._unplaced.discard("lookahead")
        x, y, _ = _compose(where, msg.point.x, msg.point.y, 0.0)
        self.hub.post("lookahead", text_frame("lookahead", x=_r(x), y=_r(y)))
