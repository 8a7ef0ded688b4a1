"""``nav2_rotation_shim_controller::RotationShimController`` (Nav2 Jazzy): rotate in place
toward a new path's rough heading, then hand the path to a primary controller.

The shim and its primary share one plugin block, as in Nav2::

    FollowPath:
      plugin: "nav2_rotation_shim_controller::RotationShimController"
      primary_controller: "nav2_mppi_controller::MPPIController"
      angular_dist_threshold: 0.785
      ...                      # the shim's keys (RotationShimConfig)
      time_steps: 56           # the primary's keys, beside them
      critics: [...]

Behaviour, as upstream's ``computeVelocityCommands``:

- after each ``set_plan`` (with ``rotate_to_heading_once``: only when the goal changed or a
  rotation was under way) the heading error to the path is measured — the bearing, from the
  robot, of the first path pose at least ``forward_sampling_distance`` from the path's first
  pose, or that pose's yaw minus the robot's with ``use_path_orientations``; while it exceeds
  ``angular_dist_threshold`` (``angular_disengage_threshold`` once rotating) the robot turns
  in place at ``rotate_to_heading_angular_vel``, changing the rate by at most
  ``max_angular_accel`` per control period from the measured rate (``closed_loop``) or the
  last command, and slowing so that it can stop at the heading (``sqrt(2 a |error|)``);
- each rotation command is checked by turning the footprint on the local costmap over
  ``simulate_ahead_time`` in control periods: a footprint cost of ``max_cost_threshold`` or
  more (off the map counts as lethal; unknown, when the costmap tracks unknown space) makes
  the shim stop shimming this path and hand over to the primary at once, as upstream;
- with ``rotate_to_goal_heading`` the robot turns to the goal's yaw once it is within the goal
  checker's ``xy_goal_tolerance`` of the goal (a stateful position check, reset with each
  plan);
- otherwise the primary computes the command. ``set_plan``, ``set_speed_limit``,
  ``set_goal_tolerance`` and ``reset`` go through to the primary.

Path and pose are in the costmap's global frame (the controller server brings the plan
there), so the sampled point's bearing is taken in the robot's frame directly.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import LETHAL_OBSTACLE, NO_INFORMATION
from eddiebot.nav.costmap.footprint import transform_footprint
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import ControllerError, NoValidControl, UnsupportedPlugin
from eddiebot.nav.params import from_params, require
from eddiebot.nav.plugins import PluginContext, PluginRegistry, plugin_key, registry
from eddiebot.nav.types import Twist2D, as_path, as_pose

F64 = npt.NDArray[np.float64]

#: the shim's own plugin type
SHIM_TYPE = "nav2_rotation_shim_controller::RotationShimController"


@dataclass(frozen=True)
class RotationShimConfig:
    """The shim's parameters with Nav2 Jazzy's code defaults (``configure``)."""

    primary_controller: str = ""
    angular_dist_threshold: float = 0.785
    angular_disengage_threshold: float = 0.785 / 2.0
    forward_sampling_distance: float = 0.5
    rotate_to_heading_angular_vel: float = 1.8
    max_angular_accel: float = 3.2
    max_cost_threshold: float = float(LETHAL_OBSTACLE)
    simulate_ahead_time: float = 1.0
    rotate_to_goal_heading: bool = False
    rotate_to_heading_once: bool = False
    closed_loop: bool = True
    use_path_orientations: bool = False

    def validate(self, where: str = "controller_server.FollowPath") -> None:
        require(bool(self.primary_controller), where, "primary_controller",
                self.primary_controller or None,
                "required: the controller the shim hands the path to")
        for key in ("angular_dist_threshold", "angular_disengage_threshold",
                    "forward_sampling_distance", "simulate_ahead_time"):
            value = getattr(self, key)
            require(math.isfinite(value) and value >= 0.0, where, key, value,
                    "must be finite and >= 0")
        for key in ("rotate_to_heading_angular_vel", "max_angular_accel"):
            value = getattr(self, key)
            require(math.isfinite(value) and value > 0.0, where, key, value,
                    "must be finite and > 0")


#: the keys the shim reads from its block; every other key is the primary's
SHIM_KEYS = frozenset(f.name for f in dataclasses.fields(RotationShimConfig))


def split_params(params: Mapping[str, Any], server: str, name: str,
                 controllers: PluginRegistry | None = None) -> tuple[dict[str, Any], str,
                                                                    dict[str, Any]]:
    """A shim block split into the shim's keys, the primary's type and the primary's keys
    (``plugin`` left out of both). A missing, unknown or recursive ``primary_controller`` is
    :class:`~eddiebot.nav.errors.UnsupportedPlugin` on ``<name>.primary_controller``."""
    controllers = controllers if controllers is not None else registry("controllers")
    own = {k: v for k, v in params.items() if k in SHIM_KEYS}
    rest = {k: v for k, v in params.items() if k not in SHIM_KEYS and k != "plugin"}
    key = f"{name}.primary_controller"
    primary = params.get("primary_controller")
    if not isinstance(primary, str) or not primary.strip():
        raise UnsupportedPlugin(server, key, primary,
                                "the rotation shim needs the type of its primary controller, "
                                f"one of {sorted(k for k in controllers if k != SHIM_TYPE)}")
    primary = plugin_key(primary.strip())
    if primary == SHIM_TYPE:
        raise UnsupportedPlugin(server, key, primary,
                                "the rotation shim cannot be its own primary controller")
    controllers.resolve(primary, server, key)
    return own, primary, rest


class RotationShimController:
    """The shim around ``primary`` (any controller of the registry's interface)."""

    def __init__(self, config: RotationShimConfig, primary: Any, name: str = "FollowPath",
                 controller_frequency: float = 20.0,
                 server: str = "controller_server") -> None:
        config.validate(f"{server}.{name}")
        require(controller_frequency > 0.0, server, "controller_frequency",
                controller_frequency, "must be > 0")
        self.config = config
        self.primary = primary
        self.name = name
        self.control_duration = 1.0 / controller_frequency
        self.path = np.zeros((0, 3))
        self.path_updated = False
        self.in_rotation = False
        #: the last command's angular rate (None: none yet; upstream's ``DBL_MAX``)
        self.last_angular_vel: float | None = None
        self.xy_goal_tolerance = 0.25  # PositionGoalChecker's default until told
        self._position_reached = False
        self._plan_src: object = None

    @classmethod
    def from_params(cls, params: Mapping[str, Any], name: str,
                    context: PluginContext) -> RotationShimController:
        """The registry's factory: the shim's keys configure the shim, the rest of the block
        configures the primary (built by its own factory under the same instance name)."""
        controllers = registry("controllers")
        own, primary_type, rest = split_params(params, context.server, name, controllers)
        cfg = from_params(RotationShimConfig, own, server=context.where)
        primary = controllers.create(primary_type, rest, name, context)
        freq = getattr(context.server_config, "controller_frequency", 20.0)
        return cls(cfg, primary, name, freq, context.server)

    # --- plugin API --------------------------------------------------------------------
    def set_plan(self, path: npt.ArrayLike) -> None:
        p = as_path(path)
        self.path_updated = self.is_goal_changed(p) if self.config.rotate_to_heading_once else True
        self.path = p
        self.primary.set_plan(p)
        self._position_reached = False

    def set_speed_limit(self, speed_limit: float, percentage: bool) -> None:
        self.primary.set_speed_limit(speed_limit, percentage)

    def set_goal_tolerance(self, xy_tolerance: float) -> None:
        self.xy_goal_tolerance = float(xy_tolerance)
        self.primary.set_goal_tolerance(xy_tolerance)

    def reset(self) -> None:
        self.last_angular_vel = None
        reset = getattr(self.primary, "reset", None)
        if callable(reset):
            reset()
        self._position_reached = False

    def compute_velocity_commands(self, pose: npt.ArrayLike, velocity: Twist2D,
                                  path: npt.ArrayLike | None, costmap: LayeredCostmap,
                                  dt: float | None = None) -> Twist2D:
        """One control cycle; ``path`` (when given and new) replaces the plan."""
        if path is not None and path is not self._plan_src:
            self.set_plan(path)
            self._plan_src = path
        p = as_pose(pose)
        cfg = self.config
        if cfg.rotate_to_goal_heading and self.path.shape[0] > 0:
            goal = self.path[-1]
            if self._goal_position_reached(p, goal):
                try:
                    cmd = self.rotate_command(_angle_diff(p[2], goal[2]), p, velocity, costmap)
                    self.last_angular_vel = cmd.wz
                    return cmd
                except ControllerError:
                    pass  # upstream logs and goes on to the path heading / the primary
        if self.path_updated:
            try:
                err = self.heading_error(p)
                thresh = (cfg.angular_disengage_threshold if self.in_rotation
                          else cfg.angular_dist_threshold)
                if abs(err) > thresh:
                    self.in_rotation = True
                    cmd = self.rotate_command(err, p, velocity, costmap)
                    self.last_angular_vel = cmd.wz
                    return cmd
                self.path_updated = False
            except ControllerError:
                self.path_updated = False
        self.in_rotation = False
        cmd = self.primary.compute_velocity_commands(p, velocity, None, costmap, dt)
        self.last_angular_vel = cmd.wz
        return cmd

    # --- upstream's helpers ------------------------------------------------------------
    def sampled_path_point(self) -> F64:
        """``getSampledPathPt``: the first pose at least ``forward_sampling_distance`` from
        the path's first pose, else the last; :class:`ControllerError` under 2 poses."""
        if self.path.shape[0] < 2:
            raise ControllerError(
                "Path is too short to find a valid sampled path point for rotation.")
        d = np.hypot(self.path[1:, 0] - self.path[0, 0], self.path[1:, 1] - self.path[0, 1])
        far = np.nonzero(d >= self.config.forward_sampling_distance)[0]
        return self.path[int(far[0]) + 1] if far.size else self.path[-1]

    def heading_error(self, pose: F64) -> float:
        """Signed angle (rad) the robot has to turn to face the sampled path point (its yaw,
        with ``use_path_orientations``)."""
        pt = self.sampled_path_point()
        if self.config.use_path_orientations:
            return _angle_diff(pose[2], pt[2])
        c, s = math.cos(pose[2]), math.sin(pose[2])
        dx, dy = pt[0] - pose[0], pt[1] - pose[1]
        return math.atan2(-s * dx + c * dy, c * dx + s * dy)

    def rotate_command(self, angular_distance: float, pose: F64, velocity: Twist2D,
                       costmap: LayeredCostmap | None) -> Twist2D:
        """``computeRotateToHeadingCommand``: the in-place turn toward ``angular_distance``
        (rad, signed), acceleration- and stop-limited, checked for collision (raises
        :class:`NoValidControl`; no check without a costmap)."""
        cfg = self.config
        current = velocity.wz if cfg.closed_loop else self.last_angular_vel
        if current is None:
            current = 0.0
        sign = 1.0 if angular_distance > 0.0 else -1.0
        dt = self.control_duration
        wz = min(max(sign * cfg.rotate_to_heading_angular_vel,
                     current - cfg.max_angular_accel * dt), current + cfg.max_angular_accel * dt)
        max_vel_to_stop = math.sqrt(2.0 * cfg.max_angular_accel * abs(angular_distance))
        if abs(wz) > max_vel_to_stop:
            wz = sign * max_vel_to_stop
        cmd = Twist2D(0.0, 0.0, wz)
        if costmap is not None:
            self.check_rotation(cmd, angular_distance, pose, costmap)
        return cmd

    def check_rotation(self, cmd: Twist2D, angular_distance: float, pose: F64,
                       costmap: LayeredCostmap) -> None:
        """``isCollisionFree``: the footprint turned at ``cmd.wz`` in control periods up to
        ``simulate_ahead_time``; raises :class:`NoValidControl` on a cost of at least
        ``max_cost_threshold`` (or unknown, when tracked)."""
        cfg = self.config
        remaining = abs(angular_distance) - cfg.angular_dist_threshold
        master = costmap.master
        t = 0.0
        while t < cfg.simulate_ahead_time:
            t += self.control_duration
            yaw = pose[2] + cmd.wz * t
            # upstream's stop test, ``shortest_angular_distance(yaw, initial_yaw) >=
            # remaining``, measures initial - yaw: a left turn is simulated for the whole
            # time, a right turn until it passes the threshold
            if _angle_diff(yaw, pose[2]) >= remaining:
                break
            cost = float(master.footprint_cost(
                transform_footprint((pose[0], pose[1], yaw), costmap.footprint)))
            if cost < 0.0:
                cost = float(LETHAL_OBSTACLE)  # off the map, as FootprintCollisionChecker
            if cost == float(NO_INFORMATION) and costmap.track_unknown_space:
                raise NoValidControl(
                    "RotationShimController detected a potential collision ahead!")
            if cost >= cfg.max_cost_threshold:
                raise NoValidControl("RotationShimController detected collision ahead!")

    def is_goal_changed(self, path: F64) -> bool:
        """``isGoalChanged``: rotating, no current path, or a different last pose."""
        if self.in_rotation or self.path.shape[0] == 0:
            return True
        if path.shape[0] == 0:
            return True
        return not np.array_equal(self.path[-1, :3], path[-1, :3])

    def _goal_position_reached(self, pose: F64, goal: F64) -> bool:
        """Nav2's stateful ``PositionGoalChecker`` at the goal checker's xy tolerance."""
        if self._position_reached:
            return True
        dx, dy = pose[0] - goal[0], pose[1] - goal[1]
        self._position_reached = dx * dx + dy * dy <= self.xy_goal_tolerance ** 2
        return self._position_reached


def _angle_diff(a: float, b: float) -> float:
    """``angles::shortest_angular_distance(a, b)``: b - a wrapped to [-pi, pi]."""
    d = b - a
    return math.atan2(math.sin(d), math.cos(d))



__all__ = ["SHIM_KEYS", "SHIM_TYPE", "RotationShimConfig", "RotationShimController",
           "split_params"]
