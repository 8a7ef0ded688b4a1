"""Nav2's path and goal tools: leaves that rewrite goals and paths on the blackboard
(``RemovePassedGoals``, ``TruncatePath``, ``GetPoseFromPath``), and the path length the
navigator's feedback reports.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from eddiebot.nav.bt.core import LeafNode, Port, Status, input_port, output_port

__all__ = ["GetPoseFromPath", "RemovePassedGoals", "TruncatePath", "path_length_from"]

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class RemovePassedGoals(LeafNode):
    """Drops leading goals within ``radius`` of the robot, keeping the last one."""

    PORTS: ClassVar[dict[str, Port]] = {
        "input_goals": input_port(object, description="Original goals to remove viapoints from"),
        "output_goals": output_port(object, "Goals with passed viapoints removed"),
        "radius": input_port(float, 0.5, "radius to goal for it to be considered for removal"),
        "global_frame": input_port(str, description="Global frame"),
        "robot_base_frame": input_port(str, description="Robot base frame"),
    }

    def tick(self) -> Status:
        goals = list(self.get_input("input_goals") or [])
        if not goals:
            self.set_output("output_goals", goals)
            return S
        frame = goals[0].header.frame_id or self.get_input("global_frame")
        pose = self.context.robot_pose(frame, self.get_input("robot_base_frame"))
        if pose is None:
            return F
        radius = float(self.get_input("radius"))
        while len(goals) > 1:
            g = goals[0].pose.position
            if math.hypot(g.x - pose[0], g.y - pose[1]) > radius:
                break
            goals.pop(0)
        self.set_output("output_goals", goals)
        return S


class TruncatePath(LeafNode):
    """Cuts ``distance`` metres (straight-line, from the end) off the path and turns its
    new last pose towards the old end."""

    PORTS: ClassVar[dict[str, Port]] = {
        "input_path": input_port(object, description="Original Path"),
        "output_path": output_port(object, "Path truncated to a certain distance"),
        "distance": input_port(float, 1.0, "distance"),
    }

    def tick(self) -> Status:
        import copy

        path = self.get_input("input_path")
        if path is None or not path.poses:
            self.set_output("output_path", path)
            return S
        out = copy.deepcopy(path)
        final = out.poses[-1].pose.position
        distance = float(self.get_input("distance"))

        def dist() -> float:
            p = out.poses[-1].pose.position
            return math.hypot(p.x - final.x, p.y - final.y)

        while dist() < distance and len(out.poses) > 2:
            out.poses.pop()
        last = out.poses[-1].pose
        angle = math.atan2(final.y - last.position.y, final.x - last.position.x)
        if not math.isfinite(angle):
            angle = 0.0
        last.orientation.x = last.orientation.y = 0.0
        last.orientation.z, last.orientation.w = math.sin(angle / 2), math.cos(angle / 2)
        self.set_output("output_path", out)
        return S


class GetPoseFromPath(LeafNode):
    PORTS: ClassVar[dict[str, Port]] = {
        "path": input_port(object, description="Path to extract pose from"),
        "pose": output_port(object, "Stamped Extracted Pose"),
        "index": input_port(int, 0, "Index of pose to extract from. -1 is the end"),
    }

    def tick(self) -> Status:
        import copy

        path = self.get_input("path")
        if path is None or not path.poses:
            return F
        i = int(self.get_input("index"))
        if not -len(path.poses) <= i < len(path.poses):
            return F
        pose = copy.deepcopy(path.poses[i])
        if not pose.header.frame_id:
            pose.header = copy.deepcopy(path.header)
        self.set_output("pose", pose)
        return S


def path_length_from(path_xy: Any, x: float, y: float) -> float:
    """Length of ``path_xy`` ((N, 2), m) from its pose closest to (x, y) to its end."""
    import numpy as np

    p = np.asarray(path_xy, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] == 0:
        return 0.0
    i = int(np.argmin(np.hypot(p[:, 0] - x, p[:, 1] - y)))
    seg = np.hypot(np.diff(p[i:, 0]), np.diff(p[i:, 1]))
    return float(math.hypot(p[i, 0] - x, p[i, 1] - y) + seg.sum())
