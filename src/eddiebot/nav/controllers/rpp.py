"""Regulated Pure Pursuit (``nav2_regulated_pure_pursuit_controller``), Jazzy semantics.

Poses and paths are in the costmap's global frame (m, rad); the output is a robot-frame
:class:`~eddiebot.nav.types.Twist2D`. Raises :class:`~eddiebot.nav.errors.NoValidControl`
when a collision is imminent along the commanded arc.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.nav.controllers._plan import PlanHandler, path_length
from eddiebot.nav.cost_values import LETHAL_OBSTACLE, NO_INFORMATION
from eddiebot.nav.costmap.footprint import transform_footprint
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import NoValidControl
from eddiebot.nav.params import require
from eddiebot.nav.types import Twist2D, as_path, as_pose


@dataclass(frozen=True)
class RegulatedPurePursuitConfig:
    """RPP parameters with Jazzy code defaults (``max_robot_pose_search_dist`` < 0 means
    half the costmap's larger side, upstream's computed default)."""

    desired_linear_vel: float = 0.5
    lookahead_dist: float = 0.6
    min_lookahead_dist: float = 0.3
    max_lookahead_dist: float = 0.9
    lookahead_time: float = 1.5
    rotate_to_heading_angular_vel: float = 1.8
    transform_tolerance: float = 0.1
    use_velocity_scaled_lookahead_dist: bool = False
    min_approach_linear_velocity: float = 0.05
    approach_velocity_scaling_dist: float = 0.6
    max_allowed_time_to_collision_up_to_carrot: float = 1.0
    use_regulated_linear_velocity_scaling: bool = True
    use_cost_regulated_linear_velocity_scaling: bool = True
    cost_scaling_dist: float = 0.6
    cost_scaling_gain: float = 1.0
    inflation_cost_scaling_factor: float = 3.0
    regulated_linear_scaling_min_radius: float = 0.90
    regulated_linear_scaling_min_speed: float = 0.25
    use_fixed_curvature_lookahead: bool = False
    curvature_lookahead_dist: float = 0.6
    use_rotate_to_heading: bool = True
    rotate_to_heading_min_angle: float = 0.785
    max_angular_accel: float = 3.2
    use_cancel_deceleration: bool = False
    cancel_deceleration: float = 3.2
    allow_reversing: bool = False
    max_robot_pose_search_dist: float = -1.0
    interpolate_curvature_after_goal: bool = False
    use_collision_detection: bool = True
    stateful: bool = True

    def validate(self, server: str = "controller_server") -> None:
        require(self.desired_linear_vel > 0.0, server, "desired_linear_vel",
                self.desired_linear_vel, "must be > 0")
        require(0.0 <= self.min_lookahead_dist <= self.max_lookahead_dist, server,
                "min_lookahead_dist", self.min_lookahead_dist,
                "needs 0 <= min_lookahead_dist <= max_lookahead_dist")
        require(not (self.use_rotate_to_heading and self.allow_reversing), server,
                "allow_reversing", self.allow_reversing,
                "use_rotate_to_heading and allow_reversing cannot both be true")
        require(self.max_angular_accel > 0.0, server, "max_angular_accel",
                self.max_angular_accel, "must be > 0")
        require(self.regulated_linear_scaling_min_radius > 0.0, server,
                "regulated_linear_scaling_min_radius", self.regulated_linear_scaling_min_radius,
                "must be > 0")
        require(self.approach_velocity_scaling_dist >= 0.0, server,
                "approach_velocity_scaling_dist", self.approach_velocity_scaling_dist, "must be >= 0")


def circle_segment_intersection(p1: npt.NDArray[np.float64], p2: npt.NDArray[np.float64],
                                r: float) -> npt.NDArray[np.float64]:
    """Intersection of the circle of radius ``r`` at the origin with segment p1 -> p2
    (p1 inside, p2 outside), as upstream's ``circleSegmentIntersection``."""
    x1, y1 = float(p1[0]), float(p1[1])
    x2, y2 = float(p2[0]), float(p2[1])
    dx, dy = x2 - x1, y2 - y1
    dr2 = dx * dx + dy * dy
    d = x1 * y2 - x2 * y1
    disc = max(0.0, r * r * dr2 - d * d)
    sq = math.sqrt(disc)
    sign_dy = 1.0 if dy >= 0 else -1.0
    out = np.empty(2)
    out[0] = (d * dy + sign_dy * dx * sq) / dr2
    out[1] = (-d * dx + abs(dy) * sq) / dr2
    # Of the two roots, upstream's formula picks the one along increasing distance; make
    # sure it lies on the segment (handles the mirrored case).
    alt = np.array([(d * dy - sign_dy * dx * sq) / dr2, (-d * dx - abs(dy) * sq) / dr2])
    def on_seg(q: npt.NDArray[np.float64]) -> float:
        t = ((q[0] - x1) * dx + (q[1] - y1) * dy) / dr2 if dr2 > 0 else 0.0
        return abs(t - min(max(t, 0.0), 1.0))
    return out if on_seg(out) <= on_seg(alt) else alt


def find_cusp_distance(path: npt.NDArray[np.float64]) -> float:
    """Distance from the robot to the first direction reversal of a robot-frame path."""
    if path.shape[0] < 3:
        return math.inf
    d = np.diff(path[:, :2], axis=0)
    dots = np.sum(d[:-1] * d[1:], axis=1)
    idx = np.nonzero(dots < 0.0)[0]
    if idx.size == 0:
        return math.inf
    p = path[idx[0] + 1]
    return math.hypot(p[0], p[1])


class RegulatedPurePursuitController:
    """Stateful RPP controller (keeps the pruned plan and the goal-heading latch)."""

    def __init__(self, config: RegulatedPurePursuitConfig | None = None, name: str = "FollowPath",
                 controller_frequency: float = 20.0) -> None:
        self.config = config or RegulatedPurePursuitConfig()
        self.config.validate()
        self.name = name
        self.control_duration = 1.0 / controller_frequency
        self.goal_dist_tol = 0.25
        self._plan = PlanHandler()
        self._plan_src: object = None
        self._desired_linear_vel = self.config.desired_linear_vel
        self._rotating_to_goal = False
        self.last_carrot = np.zeros(2)

    # --- plugin API --------------------------------------------------------------------
    def set_plan(self, path: npt.ArrayLike) -> None:
        self._plan.set_plan(as_path(path))
        self._rotating_to_goal = False

    def reset(self) -> None:
        self._rotating_to_goal = False

    def set_speed_limit(self, speed_limit: float, percentage: bool) -> None:
        """Nav2 ``setSpeedLimit``: 0 restores the base speed; else % of it or absolute m/s."""
        base = self.config.desired_linear_vel
        if speed_limit == 0.0:
            self._desired_linear_vel = base
        elif percentage:
            self._desired_linear_vel = base * speed_limit / 100.0
        else:
            self._desired_linear_vel = speed_limit

    def set_goal_tolerance(self, xy_tolerance: float) -> None:
        self.goal_dist_tol = xy_tolerance

    def compute_velocity_commands(
        self,
        pose: npt.ArrayLike,
        velocity: Twist2D,
        path: npt.ArrayLike | None,
        costmap: LayeredCostmap,
        dt: float | None = None,
    ) -> Twist2D:
        """One control cycle; ``path`` (when given and new) replaces the plan."""
        cfg = self.config
        # A new path object replaces the plan (held, so identity cannot be recycled);
        # nodes may instead call set_plan() once per received path and pass None here.
        if path is not None and path is not self._plan_src:
            self.set_plan(path)
            self._plan_src = path
        dt = self.control_duration if dt is None else dt
        p = as_pose(pose)
        cm = costmap.master
        max_extent = max(cm.size_x, cm.size_y) * cm.resolution / 2.0
        search = cfg.max_robot_pose_search_dist if cfg.max_robot_pose_search_dist > 0 else max_extent
        tpath = self._plan.transform(p, search, max_extent)
        speed = velocity

        lookahead = cfg.lookahead_dist
        if cfg.use_velocity_scaled_lookahead_dist:
            lookahead = min(max(abs(speed.vx) * cfg.lookahead_time, cfg.min_lookahead_dist),
                            cfg.max_lookahead_dist)
        curv_lookahead = cfg.curvature_lookahead_dist
        if cfg.allow_reversing:
            cusp = find_cusp_distance(tpath)
            lookahead = min(lookahead, cusp)
            curv_lookahead = min(curv_lookahead, cusp)

        carrot = self._lookahead_point(lookahead, tpath, cfg.interpolate_curvature_after_goal)
        self.last_carrot = carrot
        carrot_dist2 = carrot[0] ** 2 + carrot[1] ** 2
        if cfg.use_fixed_curvature_lookahead:
            cc = self._lookahead_point(curv_lookahead, tpath, cfg.interpolate_curvature_after_goal)
            cd2 = cc[0] ** 2 + cc[1] ** 2
            curvature = 2.0 * cc[1] / cd2 if cd2 > 0.001 else 0.0
        else:
            curvature = 2.0 * carrot[1] / carrot_dist2 if carrot_dist2 > 0.001 else 0.0

        sign = 1.0
        if cfg.allow_reversing:
            sign = -1.0 if carrot[0] < 0.0 else 1.0

        linear = self._desired_linear_vel
        angular: float
        goal_yaw = float(tpath[-1, 2])
        if self._should_rotate_to_goal_heading(carrot):
            self._rotating_to_goal = cfg.stateful
            linear, angular = self._rotate_to_heading(goal_yaw, speed)
        elif self._should_rotate_to_path(carrot):
            angle = math.atan2(carrot[1], carrot[0])
            linear, angular = self._rotate_to_heading(angle, speed)
        else:
            linear = self._apply_constraints(curvature, p, tpath, linear, sign, costmap)
            angular = linear * curvature

        if cfg.use_collision_detection and self._collision_imminent(
            p, linear, angular, math.sqrt(carrot_dist2), costmap
        ):
            raise NoValidControl("RegulatedPurePursuitController detected collision ahead!")
        return Twist2D(linear, 0.0, angular)

    # --- pieces ------------------------------------------------------------------------
    @staticmethod
    def _lookahead_point(lookahead: float, tpath: npt.NDArray[np.float64],
                         interpolate_after_goal: bool) -> npt.NDArray[np.float64]:
        d = np.hypot(tpath[:, 0], tpath[:, 1])
        idx = np.nonzero(d >= lookahead)[0]
        if idx.size == 0:
            last = tpath[-1, :2]
            if interpolate_after_goal and tpath.shape[0] >= 2:
                prev = tpath[-2, :2]
                direction = last - prev
                n = float(np.hypot(*direction))
                if n > 0:
                    far = last + direction / n * lookahead
                    return circle_segment_intersection(prev, far, lookahead)
            return last.copy()
        i = int(idx[0])
        if i > 0:
            return circle_segment_intersection(tpath[i - 1, :2], tpath[i, :2], lookahead)
        return tpath[i, :2].copy()

    def _should_rotate_to_goal_heading(self, carrot: npt.NDArray[np.float64]) -> bool:
        if not self.config.use_rotate_to_heading:
            return False
        if self._rotating_to_goal and self.config.stateful:
            return True
        return math.hypot(carrot[0], carrot[1]) < self.goal_dist_tol

    def _should_rotate_to_path(self, carrot: npt.NDArray[np.float64]) -> bool:
        angle = math.atan2(carrot[1], carrot[0])
        return self.config.use_rotate_to_heading and abs(angle) > self.config.rotate_to_heading_min_angle

    def _rotate_to_heading(self, angle: float, speed: Twist2D) -> tuple[float, float]:
        cfg = self.config
        sign = 1.0 if angle > 0.0 else -1.0
        w = sign * cfg.rotate_to_heading_angular_vel
        dt = self.control_duration
        w = min(max(w, speed.wz - cfg.max_angular_accel * dt), speed.wz + cfg.max_angular_accel * dt)
        max_to_stop = math.sqrt(2.0 * cfg.max_angular_accel * abs(angle))
        if abs(w) > max_to_stop:
            w = sign * max_to_stop
        return 0.0, w

    def _cost_at_pose(self, pose: npt.NDArray[np.float64], costmap: LayeredCostmap) -> int:
        return costmap.master.cost_at_world(pose[0], pose[1], outside=NO_INFORMATION)

    def _apply_constraints(self, curvature: float, pose: npt.NDArray[np.float64],
                           tpath: npt.NDArray[np.float64], linear: float, sign: float,
                           costmap: LayeredCostmap) -> float:
        cfg = self.config
        curv_vel = linear
        cost_vel = linear
        if cfg.use_regulated_linear_velocity_scaling and curvature != 0.0:
            radius = abs(1.0 / curvature)
            r_min = cfg.regulated_linear_scaling_min_radius
            if radius < r_min:
                curv_vel = linear * (1.0 - abs(radius - r_min) / r_min)
        if cfg.use_cost_regulated_linear_velocity_scaling and cfg.inflation_cost_scaling_factor > 0:
            c = self._cost_at_pose(pose, costmap)
            if c != NO_INFORMATION and c != 0:
                k = cfg.inflation_cost_scaling_factor
                obstacle_dist = (k * costmap.inscribed_radius - math.log(c) + math.log(253.0)) / k
                if obstacle_dist < cfg.cost_scaling_dist:
                    cost_vel = linear * cfg.cost_scaling_gain * obstacle_dist / cfg.cost_scaling_dist
        linear = min(curv_vel, cost_vel)
        linear = max(linear, cfg.regulated_linear_scaling_min_speed)
        # Approach to the goal.
        remaining = path_length(tpath)
        if remaining < cfg.approach_velocity_scaling_dist:
            last = tpath[-1]
            scaling = math.hypot(last[0], last[1]) / cfg.approach_velocity_scaling_dist
            approach = self._desired_linear_vel
            if approach * scaling < cfg.min_approach_linear_velocity:
                approach = cfg.min_approach_linear_velocity
            else:
                approach *= scaling
            linear = min(linear, approach)
        linear = min(max(abs(linear), 0.0), self._desired_linear_vel)
        return sign * linear

    def _in_collision(self, x: float, y: float, th: float, costmap: LayeredCostmap) -> bool:
        cm = costmap.master
        if cm.world_to_map(x, y) is None:
            return False
        fp = transform_footprint((x, y, th), costmap.footprint)
        c = cm.footprint_cost(fp)
        if c < 0:
            return False
        if c == NO_INFORMATION and costmap.track_unknown_space:
            return False
        return c >= LETHAL_OBSTACLE

    def _collision_imminent(self, pose: npt.NDArray[np.float64], linear: float, angular: float,
                            carrot_dist: float, costmap: LayeredCostmap) -> bool:
        if self._in_collision(pose[0], pose[1], pose[2], costmap):
            return True
        res = costmap.master.resolution
        if abs(linear) < 0.01 and abs(angular) > 0.01:
            step = 2.0 * math.sin((res / 2.0) / max(costmap.circumscribed_radius, 1e-6)) / abs(angular)
        elif abs(linear) > 1e-9:
            step = res / abs(linear)
        else:
            return False
        x, y, th = 0.0, 0.0, 0.0
        c0, s0 = math.cos(pose[2]), math.sin(pose[2])
        i = 1
        while True:
            if i * step >= self.config.max_allowed_time_to_collision_up_to_carrot:
                break
            if math.hypot(x, y) >= carrot_dist:
                break
            i += 1
            th += step * angular
            x += step * linear * math.cos(th)
            y += step * linear * math.sin(th)
            gx = pose[0] + c0 * x - s0 * y
            gy = pose[1] + s0 * x + c0 * y
            if self._in_collision(gx, gy, pose[2] + th, costmap):
                return True
        return False


__all__ = [
    "RegulatedPurePursuitConfig",
    "RegulatedPurePursuitController",
    "circle_segment_intersection",
    "find_cusp_distance",
]
