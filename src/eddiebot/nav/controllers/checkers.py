"""Progress and goal checker plugins (``nav2_controller/plugins``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.nav.params import require
from eddiebot.nav.types import Twist2D, wrap_angle


@dataclass(frozen=True)
class SimpleProgressCheckerConfig:
    """``nav2_controller::SimpleProgressChecker`` (Jazzy code defaults)."""

    required_movement_radius: float = 0.5
    movement_time_allowance: float = 10.0

    def validate(self, server: str = "controller_server") -> None:
        require(self.required_movement_radius >= 0.0, server, "required_movement_radius",
                self.required_movement_radius, "must be >= 0")
        require(self.movement_time_allowance >= 0.0, server, "movement_time_allowance",
                self.movement_time_allowance, "must be >= 0")


class SimpleProgressChecker:
    """Fails when the robot has not left a circle of ``required_movement_radius`` around the
    last baseline pose within ``movement_time_allowance`` seconds."""

    def __init__(self, config: SimpleProgressCheckerConfig | None = None) -> None:
        self.config = config or SimpleProgressCheckerConfig()
        self._baseline: npt.NDArray[np.float64] | None = None
        self._baseline_ns = 0

    def check(self, pose: npt.ArrayLike, now_ns: int) -> bool:
        """True while progress is being made (``check``)."""
        p = np.asarray(pose, dtype=np.float64)
        if self._baseline is None or math.hypot(
            p[0] - self._baseline[0], p[1] - self._baseline[1]
        ) > self.config.required_movement_radius:
            self._baseline = p.copy()
            self._baseline_ns = now_ns
            return True
        return not ((now_ns - self._baseline_ns) * 1e-9 > self.config.movement_time_allowance)

    def reset(self) -> None:
        self._baseline = None


@dataclass(frozen=True)
class PoseProgressCheckerConfig:
    """``nav2_controller::PoseProgressChecker`` (Jazzy code defaults)."""

    required_movement_radius: float = 0.5
    required_movement_angle: float = 0.5
    movement_time_allowance: float = 10.0

    def validate(self, server: str = "controller_server") -> None:
        require(self.required_movement_radius >= 0.0, server, "required_movement_radius",
                self.required_movement_radius, "must be >= 0")
        require(self.required_movement_angle >= 0.0, server, "required_movement_angle",
                self.required_movement_angle, "must be >= 0")
        require(self.movement_time_allowance >= 0.0, server, "movement_time_allowance",
                self.movement_time_allowance, "must be >= 0")


class PoseProgressChecker(SimpleProgressChecker):
    """As :class:`SimpleProgressChecker`, but turning by ``required_movement_angle`` (rad)
    also counts as progress: a robot turning in place to the goal heading, or to face its
    path, is not failed for standing on the spot."""

    def __init__(self, config: PoseProgressCheckerConfig | None = None) -> None:
        self.pose_config = config or PoseProgressCheckerConfig()
        self.pose_config.validate()
        super().__init__(SimpleProgressCheckerConfig(
            self.pose_config.required_movement_radius, self.pose_config.movement_time_allowance))

    def check(self, pose: npt.ArrayLike, now_ns: int) -> bool:
        p = np.asarray(pose, dtype=np.float64)
        b = self._baseline
        if b is None or math.hypot(p[0] - b[0], p[1] - b[1]) > self.config.required_movement_radius \
                or abs(wrap_angle(float(p[2] - b[2]))) > self.pose_config.required_movement_angle:
            self._baseline = p.copy()
            self._baseline_ns = now_ns
            return True
        return not ((now_ns - self._baseline_ns) * 1e-9 > self.config.movement_time_allowance)


@dataclass(frozen=True)
class SimpleGoalCheckerConfig:
    """``nav2_controller::SimpleGoalChecker`` (Jazzy code defaults)."""

    xy_goal_tolerance: float = 0.25
    yaw_goal_tolerance: float = 0.25
    stateful: bool = True

    def validate(self, server: str = "controller_server") -> None:
        require(self.xy_goal_tolerance >= 0.0, server, "xy_goal_tolerance",
                self.xy_goal_tolerance, "must be >= 0")
        require(self.yaw_goal_tolerance >= 0.0, server, "yaw_goal_tolerance",
                self.yaw_goal_tolerance, "must be >= 0")


class SimpleGoalChecker:
    """Goal reached when within ``xy_goal_tolerance`` and ``yaw_goal_tolerance``; with
    ``stateful`` the xy test is latched once passed (the robot may drift while turning)."""

    def __init__(self, config: SimpleGoalCheckerConfig | None = None) -> None:
        self.config = config or SimpleGoalCheckerConfig()
        self._check_xy = True

    def reset(self) -> None:
        self._check_xy = True

    def is_goal_reached(self, pose: npt.ArrayLike, goal: npt.ArrayLike,
                        velocity: Twist2D | None = None) -> bool:
        p = np.asarray(pose, dtype=np.float64)
        g = np.asarray(goal, dtype=np.float64)
        if self._check_xy:
            dx, dy = g[0] - p[0], g[1] - p[1]
            if dx * dx + dy * dy > self.config.xy_goal_tolerance ** 2:
                return False
            if self.config.stateful:
                self._check_xy = False
        return abs(wrap_angle(float(g[2] - p[2]))) < self.config.yaw_goal_tolerance

    def tolerances(self) -> tuple[float, float]:
        """(xy, yaw) tolerances (``getTolerances``)."""
        return self.config.xy_goal_tolerance, self.config.yaw_goal_tolerance


__all__ = [
    "PoseProgressChecker",
    "PoseProgressCheckerConfig",
    "SimpleGoalChecker",
    "SimpleGoalCheckerConfig",
    "SimpleProgressChecker",
    "SimpleProgressCheckerConfig",
]
