"""Plan handling shared by the controllers: pruning and transforming into the robot frame."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from eddiebot.nav.errors import InvalidPath


def to_robot_frame(pose: npt.NDArray[np.float64], pts: npt.NDArray[np.float64]
                   ) -> npt.NDArray[np.float64]:
    """Poses (N, 3) from the global frame into the frame of ``pose``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx = pts[:, 0] - pose[0]
    dy = pts[:, 1] - pose[1]
    out = np.empty((pts.shape[0], 3))
    out[:, 0] = c * dx + s * dy
    out[:, 1] = -s * dx + c * dy
    out[:, 2] = np.arctan2(np.sin(pts[:, 2] - pose[2]), np.cos(pts[:, 2] - pose[2]))
    return out


class PlanHandler:
    """The global plan and the index of its closest pose, pruned as the robot advances
    (Nav2's ``transformGlobalPlan``: the closest pose is searched within
    ``max_robot_pose_search_dist`` of path length from the last closest pose; poses farther
    than ``max_extent`` from the robot are cut off)."""

    def __init__(self) -> None:
        self.plan = np.zeros((0, 3))
        self.start = 0

    def set_plan(self, path: npt.ArrayLike) -> None:
        p = np.asarray(path, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] == 0 or p.shape[1] < 3:
            raise InvalidPath("received an empty or malformed plan")
        self.plan = np.ascontiguousarray(p[:, :3])
        self.start = 0

    def transform(self, pose: npt.NDArray[np.float64], max_search_dist: float,
                  max_extent: float) -> npt.NDArray[np.float64]:
        if self.plan.shape[0] == 0:
            raise InvalidPath("received plan with zero length")
        rest = self.plan[self.start:]
        seg = np.hypot(np.diff(rest[:, 0]), np.diff(rest[:, 1]))
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        upto = int(np.searchsorted(cum, max_search_dist, side="right"))
        upto = max(1, min(upto + 1, rest.shape[0]))
        d = np.hypot(rest[:upto, 0] - pose[0], rest[:upto, 1] - pose[1])
        closest = int(np.argmin(d))
        self.start += closest
        rest = self.plan[self.start:]
        dist = np.hypot(rest[:, 0] - pose[0], rest[:, 1] - pose[1])
        far = np.nonzero(dist > max_extent)[0]
        end = int(far[0]) if far.size else rest.shape[0]
        end = max(end, 1)
        return to_robot_frame(pose, rest[:end])


def path_length(p: npt.NDArray[np.float64]) -> float:
    if p.shape[0] < 2:
        return 0.0
    return float(np.sum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))))


__all__ = ["PlanHandler", "path_length", "to_robot_frame"]
