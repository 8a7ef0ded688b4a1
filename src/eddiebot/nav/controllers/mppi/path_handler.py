"""``mppi::PathHandler`` (Jazzy): the global plan pruned to the stretch the optimiser sees.

Poses are in the costmap's global frame (m, rad). Each cycle the closest plan pose is
searched within ``max_robot_pose_search_dist`` of integrated length, the plan is cut to
``prune_distance`` of length beyond it (and at the first pose off the costmap), and the
poses behind the robot are dropped. With ``enforce_path_inversion`` the plan ends at its
first direction reversal until the robot reaches that pose within the inversion tolerances.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import InvalidPath

F64 = npt.NDArray[np.float64]


def first_after_integrated_distance(poses: F64, dist: float) -> int:
    """``geometry_utils::first_after_integrated_distance``: the first index at which the
    integrated length from ``poses[0]`` exceeds ``dist`` (``len(poses)`` when none does)."""
    if poses.shape[0] < 2:
        return poses.shape[0]
    cum = np.cumsum(np.hypot(np.diff(poses[:, 0]), np.diff(poses[:, 1])))
    over = np.nonzero(cum > dist)[0]
    return int(over[0]) + 1 if over.size else poses.shape[0]


def first_path_inversion(poses: F64) -> int:
    """``utils::findFirstPathInversion``: index of the first pose after a reversal of
    direction (``len(poses)`` when there is none)."""
    if poses.shape[0] < 3:
        return poses.shape[0]
    d = np.diff(poses[:, :2], axis=0)
    dots = np.sum(d[:-1] * d[1:], axis=1)
    idx = np.nonzero(dots < 0.0)[0]
    return int(idx[0]) + 2 if idx.size else poses.shape[0]


class MPPIPathHandler:
    """Holds the global plan; :meth:`transform_path` gives the pruned plan each cycle."""

    def __init__(self, max_robot_pose_search_dist: float = -1.0, prune_distance: float = 1.5,
                 enforce_path_inversion: bool = False, inversion_xy_tolerance: float = 0.2,
                 inversion_yaw_tolerance: float = 0.4) -> None:
        self.max_robot_pose_search_dist = max_robot_pose_search_dist
        self.prune_distance = prune_distance
        self.enforce_path_inversion = enforce_path_inversion
        self.inversion_xy_tolerance = inversion_xy_tolerance
        self.inversion_yaw_tolerance = inversion_yaw_tolerance
        self.global_plan = np.zeros((0, 3))
        self.plan_up_to_inversion = np.zeros((0, 3))
        self.inversion_locale = 0

    def set_path(self, plan: npt.ArrayLike) -> None:
        p = np.asarray(plan, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] == 0 or p.shape[1] < 3:
            raise InvalidPath("received an empty or malformed plan")
        self.global_plan = np.ascontiguousarray(p[:, :3])
        self.plan_up_to_inversion = self.global_plan
        self.inversion_locale = 0
        if self.enforce_path_inversion:
            self._crop_at_inversion()

    def _crop_at_inversion(self) -> None:
        """``removePosesAfterFirstInversion``: returns the cut index (0 when none)."""
        cut = first_path_inversion(self.plan_up_to_inversion)
        if cut == self.plan_up_to_inversion.shape[0]:
            self.inversion_locale = 0
            return
        self.plan_up_to_inversion = self.plan_up_to_inversion[:cut]
        self.inversion_locale = cut

    def goal(self) -> F64:
        """``getTransformedGoal``: the last pose of the whole plan."""
        if self.global_plan.shape[0] == 0:
            raise InvalidPath("received plan with zero length")
        return self.global_plan[-1].copy()

    def transform_path(self, pose: F64, costmap: LayeredCostmap) -> F64:
        """``transformPath``: the pruned plan (global frame), from the closest pose on."""
        plan = self.plan_up_to_inversion
        if plan.shape[0] == 0:
            raise InvalidPath("received plan with zero length")
        m = costmap.master
        search = self.max_robot_pose_search_dist
        if search < 0.0:
            search = max(m.size_x, m.size_y) * m.resolution * 0.5
        upper = max(first_after_integrated_distance(plan, search), 1)
        d = np.hypot(plan[:upper, 0] - pose[0], plan[:upper, 1] - pose[1])
        closest = int(np.argmin(d))
        rest = plan[closest:]
        end = first_after_integrated_distance(rest, self.prune_distance)
        seg = rest[:end]
        fx = np.floor((seg[:, 0] - m.origin_x) / m.resolution)
        fy = np.floor((seg[:, 1] - m.origin_y) / m.resolution)
        off = np.nonzero((seg[:, 0] < m.origin_x) | (seg[:, 1] < m.origin_y)
                         | (fx >= m.size_x) | (fy >= m.size_y))[0]
        if off.size:
            seg = seg[:int(off[0])]
        self.plan_up_to_inversion = plan[closest:]
        if self.enforce_path_inversion and self.inversion_locale != 0 \
                and self._within_inversion_tolerances(pose):
            self.global_plan = self.global_plan[self.inversion_locale:]
            self.plan_up_to_inversion = self.global_plan
            self._crop_at_inversion()
        if seg.shape[0] == 0:
            raise InvalidPath("Resulting plan has 0 poses in it.")
        return seg.copy()

    def _within_inversion_tolerances(self, pose: F64) -> bool:
        last = self.plan_up_to_inversion[-1]
        dist = math.hypot(pose[0] - last[0], pose[1] - last[1])
        dyaw = math.atan2(math.sin(last[2] - pose[2]), math.cos(last[2] - pose[2]))
        return dist <= self.inversion_xy_tolerance and abs(dyaw) <= self.inversion_yaw_tolerance


__all__ = ["MPPIPathHandler", "first_after_integrated_distance", "first_path_inversion"]
