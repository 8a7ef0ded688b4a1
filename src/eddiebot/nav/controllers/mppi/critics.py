"""MPPI critics (``mppi::critics::*``, Jazzy): each adds a weighted cost per sampled trajectory.

A critic's parameters are those of its upstream class with the same defaults; every critic
also takes ``enabled``. A term is ``(weight · x)^cost_power`` (upstream raises the weighted
term, not the raw one, when ``cost_power`` > 1). Poses are in the costmap's global frame
(m, rad); the velocities and trajectories are (batch, time_steps) arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from eddiebot.nav.controllers.mppi import _kernels
from eddiebot.nav.controllers.mppi.config import MPPIConfig
from eddiebot.nav.controllers.mppi.critic_configs import (
    ConstraintCriticConfig,
    CostCriticConfig,
    GoalAngleCriticConfig,
    GoalCriticConfig,
    ObstaclesCriticConfig,
    PathAlignCriticConfig,
    PathAngleCriticConfig,
    PathAngleMode,
    PathFollowCriticConfig,
    PreferForwardCriticConfig,
    TwirlingCriticConfig,
    VelocityDeadbandCriticConfig,
)
from eddiebot.nav.cost_values import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import ControllerError

F64 = npt.NDArray[np.float64]


@dataclass
class CriticData:
    """What the critics score (``mppi::CriticData``); ``costs`` accumulates in place and
    ``fail_flag`` is set by the collision critics when every trajectory collides."""

    pose: F64
    goal: F64
    path: F64
    vx: F64
    wz: F64
    traj_x: F64
    traj_y: F64
    traj_yaw: F64
    costs: F64
    model_dt: float
    costmap: LayeredCostmap | None = None
    #: the goal checker's xy tolerance (m); None without a goal checker
    goal_tolerance: float | None = None
    fail_flag: bool = False
    furthest_reached_path_point: int | None = None
    path_pts_valid: npt.NDArray[np.bool_] | None = None
    extras: dict[str, Any] = field(default_factory=dict)


def normalize_angles(a: npt.ArrayLike) -> F64:
    """``utils::normalize_angles`` into [-π, π)."""
    theta = np.fmod(np.asarray(a, dtype=np.float64) + math.pi, 2.0 * math.pi)
    return np.where(theta < 0.0, theta + math.pi, theta - math.pi)


def shortest_angular_distance(frm: npt.ArrayLike, to: npt.ArrayLike) -> F64:
    return normalize_angles(np.asarray(to, dtype=np.float64) - np.asarray(frm, dtype=np.float64))


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def within_position_goal_tolerance(tolerance: float, pose: F64, goal: F64) -> bool:
    """``utils::withinPositionGoalTolerance`` (strictly inside)."""
    dx, dy = goal[0] - pose[0], goal[1] - pose[1]
    return bool(dx * dx + dy * dy < tolerance * tolerance)


def pose_point_angle(pose: F64, px: float, py: float, forward_preference: bool) -> float:
    """``utils::posePointAngle``: angle between the robot's heading (or its reverse when
    direction does not matter) and the direction to the point."""
    yaw = math.atan2(py - pose[1], px - pose[0])
    if not forward_preference:
        return min(abs(_wrap(pose[2] - yaw)), abs(_wrap(_wrap(pose[2] + math.pi) - yaw)))
    return abs(_wrap(pose[2] - yaw))


def pose_point_angle_oriented(pose: F64, px: float, py: float, point_yaw: float) -> float:
    """``utils::posePointAngle`` with the point's own yaw: the direction to the point is
    flipped when it opposes the yaw the path asks for there."""
    yaw = math.atan2(py - pose[1], px - pose[0])
    if abs(_wrap(point_yaw - yaw)) > math.pi / 2:
        yaw = _wrap(yaw + math.pi)
    return abs(_wrap(pose[2] - yaw))


def set_path_furthest_point(data: CriticData) -> int:
    if data.furthest_reached_path_point is None:
        data.furthest_reached_path_point = int(_kernels.furthest_reached_path_point(
            np.ascontiguousarray(data.traj_x[:, -1]), np.ascontiguousarray(data.traj_y[:, -1]),
            np.ascontiguousarray(data.path[:, 0]), np.ascontiguousarray(data.path[:, 1])))
    return data.furthest_reached_path_point


def set_path_costs(data: CriticData) -> npt.NDArray[np.bool_]:
    """``utils::findPathCosts``: per path segment start, whether its cell is usable (not
    lethal or inscribed, not off the map, unknown only when unknown space is tracked)."""
    if data.path_pts_valid is None:
        n = max(data.path.shape[0] - 1, 0)
        valid = np.zeros(n, dtype=bool)
        cm = data.costmap
        if cm is not None and n:
            m = cm.master
            fx = np.floor((data.path[:n, 0] - m.origin_x) / m.resolution)
            fy = np.floor((data.path[:n, 1] - m.origin_y) / m.resolution)
            on = (fx >= 0) & (fy >= 0) & (fx < m.size_x) & (fy < m.size_y)
            c = np.full(n, -1, dtype=np.int64)
            c[on] = m.data[fy[on].astype(np.int64), fx[on].astype(np.int64)]
            valid = on & (c != LETHAL_OBSTACLE) & (c != INSCRIBED_INFLATED_OBSTACLE)
            valid &= (c != NO_INFORMATION) | cm.track_unknown_space
        data.path_pts_valid = valid
    return data.path_pts_valid


def _add(data: CriticData, weighted: npt.ArrayLike, power: int) -> None:
    term = np.asarray(weighted, dtype=np.float64)
    data.costs += term ** power if power > 1 else term


# --- critics ----------------------------------------------------------------------------


class Critic:
    """Base of the critics: ``config`` (the critic's dataclass), ``mppi`` (the controller's)."""

    Config: ClassVar[type[Any]]

    def __init__(self, config: Any = None, mppi: MPPIConfig | None = None,
                 name: str = "") -> None:
        self.config = config if config is not None else self.Config()
        self.mppi = mppi or MPPIConfig()
        self.name = name or type(self).__name__

    def score(self, data: CriticData) -> None:
        raise NotImplementedError


class ConstraintCritic(Critic):
    """Penalises state velocities beyond the speed limits (``vx`` vs the magnitude
    ``hypot(vx_max, vy_max)`` and ``-hypot(vx_min, vy_max)``, as upstream computes them)."""

    Config = ConstraintCriticConfig

    def __init__(self, config: Any = None, mppi: MPPIConfig | None = None,
                 name: str = "") -> None:
        super().__init__(config, mppi, name)
        m = self.mppi
        self.max_vel = math.hypot(m.vx_max, m.vy_max)
        self.min_vel = (1.0 if m.vx_min > 0.0 else -1.0) * math.hypot(m.vx_min, m.vy_max)

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled:
            return
        # max(vx - max_vel, 0) + max(min_vel - vx, 0) == |vx - clip(vx, min_vel, max_vel)|
        out = np.clip(data.vx, self.min_vel, self.max_vel)
        np.subtract(data.vx, out, out=out)
        np.abs(out, out=out)
        _add(data, out.sum(axis=1) * (data.model_dt * c.cost_weight), c.cost_power)


class _CollisionCritic(Critic):
    """Shared costmap facts of CostCritic and ObstaclesCritic."""

    def _inflation(self, costmap: LayeredCostmap) -> Any:
        from eddiebot.nav.costmap.layers.inflation import InflationLayer

        wanted = self.config.inflation_layer_name
        found = None
        for layer in costmap.layers:
            if isinstance(layer, InflationLayer) and (not wanted or layer.name == wanted):
                found = layer  # upstream takes the last one when no name is given
        return found

    def _check_footprint(self, costmap: LayeredCostmap) -> None:
        if self.config.consider_footprint and costmap.use_radius:
            raise ControllerError(
                f"{self.name}: consider_footprint is true but the costmap has no footprint "
                "polygon (robot_radius is set): considering footprint in collision checking "
                "but no robot footprint provided in the costmap")

    def _circumscribed_cost(self, costmap: LayeredCostmap, layer: Any) -> float:
        """``findCircumscribedCost``: the inflation cost at the circumscribed radius (-1
        without an inflation layer, 0 when inflation does not reach that far)."""
        from eddiebot.nav.costmap.layers.inflation import inflation_cost

        if layer is None:
            return -1.0
        r = costmap.circumscribed_radius
        if layer.config.inflation_radius < r and isinstance(self, CostCritic):
            return 0.0
        res = costmap.master.resolution
        return float(inflation_cost(r / res, res, costmap.inscribed_radius,
                                    layer.config.cost_scaling_factor))


class CostCritic(_CollisionCritic):
    """Scores trajectories by the inflated costmap's cost along them; a collision costs
    ``collision_cost``. Weight is ``cost_weight / 254`` per sampled point."""

    Config = CostCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled:
            return
        cm = data.costmap
        if cm is None:
            raise ControllerError(f"{self.name} needs a costmap")
        self._check_footprint(cm)
        possible = self._circumscribed_cost(cm, self._inflation(cm)) if c.consider_footprint \
            else 0.0
        near_goal = within_position_goal_tolerance(c.near_goal_distance, data.pose, data.goal)
        m = cm.master
        step = c.trajectory_point_step
        traj_len = data.traj_x.shape[1] // step
        if traj_len == 0:
            return
        repulsive, all_collide = _kernels.cost_critic(
            data.traj_x, data.traj_y, data.traj_yaw, step, m.data, m.origin_x, m.origin_y,
            m.resolution, np.ascontiguousarray(cm.footprint, dtype=np.float64),
            c.consider_footprint, possible, cm.track_unknown_space, float(c.near_collision_cost),
            c.critical_cost, c.collision_cost, near_goal)
        _add(data, repulsive * (c.cost_weight / 254.0 / traj_len), c.cost_power)
        data.fail_flag = bool(all_collide)


class ObstaclesCritic(_CollisionCritic):
    """Scores trajectories by the distance to obstacles the inflation decay implies: a
    critical term inside ``collision_margin_distance`` and a repulsive term within the
    inflation radius (normalised by the best trajectory's)."""

    Config = ObstaclesCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled:
            return
        cm = data.costmap
        if cm is None:
            raise ControllerError(f"{self.name} needs a costmap")
        self._check_footprint(cm)
        layer = self._inflation(cm)
        possible = self._circumscribed_cost(cm, layer)
        radius = float(layer.config.inflation_radius) if layer is not None else 0.0
        scale = float(layer.config.cost_scaling_factor) if layer is not None else 0.0
        near_goal = within_position_goal_tolerance(c.near_goal_distance, data.pose, data.goal)
        m = cm.master
        raw, repulsive, all_collide = _kernels.obstacles_critic(
            data.traj_x, data.traj_y, data.traj_yaw, m.data, m.origin_x, m.origin_y,
            m.resolution, np.ascontiguousarray(cm.footprint, dtype=np.float64),
            c.consider_footprint, possible, cm.track_unknown_space, radius, scale,
            cm.inscribed_radius, c.collision_margin_distance, c.collision_cost, near_goal)
        normalized = (repulsive - repulsive.min()) / data.traj_x.shape[1]
        _add(data, c.critical_weight * raw + c.repulsion_weight * normalized, c.cost_power)
        data.fail_flag = bool(all_collide)


class GoalCritic(Critic):
    """Within ``threshold_to_consider`` of the goal: mean distance of the trajectory to it."""

    Config = GoalCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled or not within_position_goal_tolerance(
                c.threshold_to_consider, data.pose, data.goal):
            return
        d = np.hypot(data.traj_x - data.goal[0], data.traj_y - data.goal[1])
        _add(data, d.mean(axis=1) * c.cost_weight, c.cost_power)


class GoalAngleCritic(Critic):
    """Within ``threshold_to_consider`` of the goal: mean angular distance of the
    trajectory's yaws to the yaw of the path's last pose (or its reverse, when symmetric)."""

    Config = GoalAngleCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled or not within_position_goal_tolerance(
                c.threshold_to_consider, data.pose, data.goal):
            return
        goal_yaw = float(data.path[-1, 2])
        d = np.abs(shortest_angular_distance(data.traj_yaw, goal_yaw))
        if c.symmetric_yaw_tolerance:
            sym = float(normalize_angles(goal_yaw + math.pi))
            d = np.minimum(d, np.abs(shortest_angular_distance(data.traj_yaw, sym)))
        _add(data, d.mean(axis=1) * c.cost_weight, c.cost_power)


class PathAlignCritic(Critic):
    """Away from the goal, once trajectories progress at least ``offset_from_furthest``
    points along the path and the path is not too occupied: mean distance of every
    ``trajectory_point_step``-th point to the path point at the same distance along it."""

    Config = PathAlignCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled or within_position_goal_tolerance(
                c.threshold_to_consider, data.pose, data.goal):
            return
        count = set_path_furthest_point(data)
        if count < c.offset_from_furthest or count == 0:
            return
        valid = set_path_costs(data)
        invalid = np.cumsum(~valid[:count])
        ratio = invalid / float(count)
        if np.any((ratio > c.max_path_occupancy_ratio) & (invalid > 2.0)):
            return
        p = data.path[:count]
        seg = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        cost = _kernels.path_align(
            data.traj_x, data.traj_y, data.traj_yaw, c.trajectory_point_step,
            np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
            np.ascontiguousarray(p[:, 2]), cum, np.ascontiguousarray(valid[:count]),
            c.use_path_orientations)
        _add(data, cost * c.cost_weight, c.cost_power)


class PathFollowCritic(Critic):
    """Away from the goal: distance of each trajectory's end to the first usable path point
    ``offset_from_furthest`` beyond the furthest any trajectory reaches."""

    Config = PathFollowCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled or data.path.shape[0] < 2 or within_position_goal_tolerance(
                c.threshold_to_consider, data.pose, data.goal):
            return
        furthest = set_path_furthest_point(data)
        valid = set_path_costs(data)
        path_size = data.path.shape[0] - 1
        idx = min(furthest + c.offset_from_furthest, path_size)
        ok = False
        while not ok and idx < path_size - 1:
            ok = bool(valid[idx])
            if not ok:
                idx += 1
        px, py = data.path[idx, 0], data.path[idx, 1]
        d = np.hypot(data.traj_x[:, -1] - px, data.traj_y[:, -1] - py)
        _add(data, c.cost_weight * d, c.cost_power)


class PathAngleCritic(Critic):
    """Away from the goal, when the path point ``offset_from_furthest`` beyond the furthest
    reached lies more than ``max_angle_to_furthest`` off the robot's heading: the angle
    between each trajectory's final yaw and the direction from its end to that point."""

    Config = PathAngleCriticConfig

    def __init__(self, config: Any = None, mppi: MPPIConfig | None = None,
                 name: str = "") -> None:
        super().__init__(config, mppi, name)
        vx_min = self.mppi.vx_min
        reversing = not abs(vx_min) < 1e-6
        self.mode = PathAngleMode(self.config.mode)
        if not reversing and self.mode == PathAngleMode.NO_DIRECTIONAL_PREFERENCE:
            # upstream: no directional preference needs reversing; forward preference instead
            self.mode = PathAngleMode.FORWARD_PREFERENCE

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled or within_position_goal_tolerance(
                c.threshold_to_consider, data.pose, data.goal):
            return
        furthest = set_path_furthest_point(data)
        idx = min(furthest + c.offset_from_furthest, data.path.shape[0] - 1)
        gx, gy, gyaw = (float(v) for v in data.path[idx, :3])
        mode = self.mode
        if mode == PathAngleMode.FORWARD_PREFERENCE:
            angle = pose_point_angle(data.pose, gx, gy, True)
        elif mode == PathAngleMode.NO_DIRECTIONAL_PREFERENCE:
            angle = pose_point_angle(data.pose, gx, gy, False)
        else:
            angle = pose_point_angle_oriented(data.pose, gx, gy, gyaw)
        if angle < c.max_angle_to_furthest:
            return
        yaws_between = np.arctan2(gy - data.traj_y[:, -1], gx - data.traj_x[:, -1])
        last_yaw = data.traj_yaw[:, -1]
        if mode == PathAngleMode.FORWARD_PREFERENCE:
            d = np.abs(shortest_angular_distance(last_yaw, yaws_between))
        elif mode == PathAngleMode.NO_DIRECTIONAL_PREFERENCE:
            raw = np.abs(shortest_angular_distance(last_yaw, yaws_between))
            corrected = np.where(raw < math.pi / 2, yaws_between,
                                 normalize_angles(yaws_between + math.pi))
            d = np.abs(shortest_angular_distance(last_yaw, corrected))
        else:
            toward = np.abs(shortest_angular_distance(yaws_between, gyaw)) < math.pi / 2
            corrected = np.where(toward, yaws_between, normalize_angles(yaws_between + math.pi))
            d = np.abs(shortest_angular_distance(last_yaw, corrected))
        _add(data, d * c.cost_weight, c.cost_power)


class PreferForwardCritic(Critic):
    """Away from the goal: the integrated reverse speed."""

    Config = PreferForwardCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled or within_position_goal_tolerance(
                c.threshold_to_consider, data.pose, data.goal):
            return
        back = -np.minimum(data.vx, 0.0).sum(axis=1)
        _add(data, back * (data.model_dt * c.cost_weight), c.cost_power)


class TwirlingCritic(Critic):
    """Outside the goal checker's tolerance: the mean absolute rotation rate."""

    Config = TwirlingCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled or (data.goal_tolerance is not None and within_position_goal_tolerance(
                data.goal_tolerance, data.pose, data.goal)):
            return
        _add(data, np.abs(data.wz).mean(axis=1) * c.cost_weight, c.cost_power)


class VelocityDeadbandCritic(Critic):
    """The integrated shortfall of |vx| and |wz| below ``deadband_velocities`` [vx, vy, wz]."""

    Config = VelocityDeadbandCriticConfig

    def score(self, data: CriticData) -> None:
        c = self.config
        if not c.enabled:
            return
        db = c.deadband_velocities
        short = np.maximum(abs(db[0]) - np.abs(data.vx), 0.0) + \
            np.maximum(abs(db[2]) - np.abs(data.wz), 0.0)
        _add(data, np.sum(short * data.model_dt, axis=1) * c.cost_weight, c.cost_power)


#: critic names as ``critics:`` lists them (upstream prefixes ``mppi::critics::``)
CRITICS: dict[str, type[Critic]] = {
    "ConstraintCritic": ConstraintCritic,
    "CostCritic": CostCritic,
    "GoalCritic": GoalCritic,
    "GoalAngleCritic": GoalAngleCritic,
    "ObstaclesCritic": ObstaclesCritic,
    "PathAlignCritic": PathAlignCritic,
    "PathAngleCritic": PathAngleCritic,
    "PathFollowCritic": PathFollowCritic,
    "PreferForwardCritic": PreferForwardCritic,
    "TwirlingCritic": TwirlingCritic,
    "VelocityDeadbandCritic": VelocityDeadbandCritic,
}

__all__ = [
    "CRITICS",
    "ConstraintCritic",
    "ConstraintCriticConfig",
    "CostCritic",
    "CostCriticConfig",
    "Critic",
    "CriticData",
    "GoalAngleCritic",
    "GoalAngleCriticConfig",
    "GoalCritic",
    "GoalCriticConfig",
    "ObstaclesCritic",
    "ObstaclesCriticConfig",
    "PathAlignCritic",
    "PathAlignCriticConfig",
    "PathAngleCritic",
    "PathAngleCriticConfig",
    "PathAngleMode",
    "PathFollowCritic",
    "PathFollowCriticConfig",
    "PreferForwardCritic",
    "PreferForwardCriticConfig",
    "TwirlingCritic",
    "TwirlingCriticConfig",
    "VelocityDeadbandCritic",
    "VelocityDeadbandCriticConfig",
    "normalize_angles",
    "shortest_angular_distance",
]
