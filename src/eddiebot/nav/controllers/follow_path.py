"""The controller server's FollowPath loop (``nav2_controller::ControllerServer``) as a pure
state machine: one :meth:`FollowPathRun.step` per ``controller_frequency`` tick."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np
import numpy.typing as npt

from eddiebot.nav.controllers import Controller, ControllerServerConfig
from eddiebot.nav.controllers.checkers import SimpleGoalChecker, SimpleProgressChecker
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import ControllerError, FailedToMakeProgress
from eddiebot.nav.types import Twist2D, as_path


class RunStatus(Enum):
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


@dataclass(frozen=True)
class FollowPathStep:
    cmd: Twist2D
    status: RunStatus
    error: ControllerError | None = None
    distance_to_goal: float = 0.0


def thresholded(cmd: Twist2D, cfg: ControllerServerConfig) -> Twist2D:
    """``getThresholdedTwist``: components below the ``min_*_velocity_threshold`` become 0."""
    return Twist2D(
        0.0 if abs(cmd.vx) < cfg.min_x_velocity_threshold else cmd.vx,
        0.0 if abs(cmd.vy) < cfg.min_y_velocity_threshold else cmd.vy,
        0.0 if abs(cmd.wz) < cfg.min_theta_velocity_threshold else cmd.wz,
    )


class FollowPathRun:
    """One FollowPath goal: progress check, goal check, control, ``failure_tolerance``.

    ``failure_tolerance`` (s): a controller exception fails the run once failures have
    lasted longer than this (0: at once; -1: never).
    """

    def __init__(self, config: ControllerServerConfig, controller: Controller,
                 goal_checker: SimpleGoalChecker, progress_checker: SimpleProgressChecker,
                 path: npt.ArrayLike, now_ns: int) -> None:
        self.config = config
        self.controller = controller
        self.goal_checker = goal_checker
        self.progress_checker = progress_checker
        self.path = as_path(path)
        self.goal = self.path[-1].copy()
        controller.set_plan(self.path)
        controller.set_goal_tolerance(goal_checker.tolerances()[0])
        goal_checker.reset()
        progress_checker.reset()
        self._last_valid_ns = now_ns
        self.dt = 1.0 / config.controller_frequency

    def update_path(self, path: npt.ArrayLike) -> None:
        """A new path (preemption with a replanned path, or one to a new goal). As Nav2's
        ``setPlannerPath``, the goal checker starts over: a stateful checker's latched xy
        test belongs to the old path's end."""
        self.path = as_path(path)
        self.goal = self.path[-1].copy()
        self.controller.set_plan(self.path)
        self.goal_checker.reset()

    def step(self, pose: npt.ArrayLike, velocity: Twist2D, costmap: LayeredCostmap,
             now_ns: int) -> FollowPathStep:
        p = np.asarray(pose, dtype=np.float64)
        dist = float(np.hypot(self.goal[0] - p[0], self.goal[1] - p[1]))
        if not self.progress_checker.check(p, now_ns):
            return FollowPathStep(Twist2D(), RunStatus.FAILED,
                                  FailedToMakeProgress("failed to make progress"), dist)
        if self.goal_checker.is_goal_reached(p, self.goal, velocity):
            return FollowPathStep(Twist2D(), RunStatus.SUCCEEDED, None, dist)
        try:
            cmd = self.controller.compute_velocity_commands(p, velocity, None, costmap, self.dt)
        except ControllerError as err:
            tol = self.config.failure_tolerance
            if tol == -1.0 or (now_ns - self._last_valid_ns) * 1e-9 <= tol:
                return FollowPathStep(Twist2D(), RunStatus.RUNNING, err, dist)
            return FollowPathStep(Twist2D(), RunStatus.FAILED, err, dist)
        self._last_valid_ns = now_ns
        return FollowPathStep(thresholded(cmd, self.config), RunStatus.RUNNING, None, dist)


__all__ = ["FollowPathRun", "FollowPathStep", "RunStatus", "thresholded"]
