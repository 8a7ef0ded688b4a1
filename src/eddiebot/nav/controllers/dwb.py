"""DWB-style sampling controller (``dwb_core`` + ``dwb_plugins`` + ``dwb_critics``).

Velocity samples inside the dynamic window (current velocity ± acceleration · sim period,
within the kinematic limits) are rolled out at constant velocity for ``sim_time`` and scored
by weighted critics; the lowest total wins. Critics: BaseObstacle, GoalAlign, PathAlign,
PathDist, GoalDist, RotateToGoal, Oscillation, with Nav2's names, scales and the rule that a
critic may declare a trajectory illegal, plus ObstacleFootprint, PreferForward and Twirling.
Rollouts run in a numba kernel; the critics are in :mod:`.dwb_critics` (the map-grid critics
score by upstream's wavefront over the costmap).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.nav.controllers import dwb_critics as critics
from eddiebot.nav.controllers._plan import PlanHandler
from eddiebot.nav.controllers.dwb_critics import AGGREGATION_TYPES
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import NoValidControl, ParameterError
from eddiebot.nav.params import require
from eddiebot.nav.types import Twist2D, as_path, as_pose, wrap_angle

KNOWN_CRITICS = ("BaseObstacle", "ObstacleFootprint", "GoalAlign", "PathAlign", "PathDist",
                 "GoalDist", "RotateToGoal", "Oscillation", "PreferForward", "Twirling")
_MAP_GRID = ("PathDist", "GoalDist", "PathAlign", "GoalAlign")


@dataclass(frozen=True)
class DWBConfig:
    """``dwb_core::DWBLocalPlanner`` + KinematicParameters + StandardTrajectoryGenerator
    parameters (Jazzy code defaults; the kinematic limits default to 0 upstream, so set them)."""

    min_vel_x: float = 0.0
    min_vel_y: float = 0.0
    max_vel_x: float = 0.0
    max_vel_y: float = 0.0
    max_vel_theta: float = 0.0
    min_speed_xy: float = 0.0
    max_speed_xy: float = 0.0
    min_speed_theta: float = 0.0
    acc_lim_x: float = 0.0
    acc_lim_y: float = 0.0
    acc_lim_theta: float = 0.0
    decel_lim_x: float = 0.0
    decel_lim_y: float = 0.0
    decel_lim_theta: float = 0.0
    vx_samples: int = 20
    vy_samples: int = 5
    vtheta_samples: int = 20
    sim_time: float = 1.7
    discretize_by_time: bool = False
    time_granularity: float = 0.5
    linear_granularity: float = 0.5
    angular_granularity: float = 0.025
    include_last_point: bool = True
    trans_stopped_velocity: float = 0.25
    short_circuit_trajectory_evaluation: bool = True
    prune_plan: bool = True
    prune_distance: float = 2.0
    forward_prune_distance: float = 2.0
    shorten_transformed_plan: bool = True
    critics: tuple[str, ...] = ()
    # Critic parameters, flattened "<Critic>.<param>" upstream.
    BaseObstacle_scale: float = 1.0
    BaseObstacle_sum_scores: bool = False
    ObstacleFootprint_scale: float = 1.0
    ObstacleFootprint_sum_scores: bool = False
    GoalAlign_scale: float = 1.0
    GoalAlign_forward_point_distance: float = 0.325
    GoalAlign_aggregation_type: str = "last"
    PathAlign_scale: float = 1.0
    PathAlign_forward_point_distance: float = 0.325
    PathAlign_aggregation_type: str = "last"
    PathDist_scale: float = 1.0
    PathDist_aggregation_type: str = "last"
    GoalDist_scale: float = 1.0
    GoalDist_aggregation_type: str = "last"
    PreferForward_scale: float = 1.0
    PreferForward_penalty: float = 1.0
    PreferForward_strafe_x: float = 0.1
    PreferForward_strafe_theta: float = 0.2
    PreferForward_theta_scale: float = 10.0
    Twirling_scale: float = 1.0
    RotateToGoal_scale: float = 1.0
    RotateToGoal_slowing_factor: float = 5.0
    RotateToGoal_lookahead_time: float = -1.0
    Oscillation_scale: float = 1.0
    Oscillation_oscillation_reset_dist: float = 0.05
    Oscillation_oscillation_reset_angle: float = 0.2

    def validate(self, server: str = "controller_server") -> None:
        for c in self.critics:
            name = c.removesuffix("Critic").split("::")[-1]
            require(name in KNOWN_CRITICS, server, "critics", list(self.critics),
                    f"unknown critic {c!r}; known: {list(KNOWN_CRITICS)}")
        for g in _MAP_GRID:
            key = f"{g}_aggregation_type"
            value = str(getattr(self, key))
            require(value.lower() in AGGREGATION_TYPES, server, key.replace("_", ".", 1), value,
                    f"must be one of {list(AGGREGATION_TYPES)}")
        require(self.sim_time > 0.0, server, "sim_time", self.sim_time, "must be > 0")
        require(self.vx_samples > 0 and self.vtheta_samples > 0, server, "vx_samples",
                self.vx_samples, "sample counts must be > 0")
        require(self.max_vel_x >= self.min_vel_x, server, "max_vel_x", self.max_vel_x,
                "must be >= min_vel_x")


def dwb_config_from_params(params: dict[str, object], server: str = "controller_server") -> DWBConfig:
    """DWBConfig from a plugin's parameter dict (nested critic dicts flattened)."""
    from eddiebot.nav.params import from_params

    flat: dict[str, object] = {}
    for k, v in params.items():
        if isinstance(v, dict):
            for kk, vv in v.items():
                flat[f"{k}_{kk}"] = vv
        else:
            flat[k.replace(".", "_")] = v
    if "critics" in flat and isinstance(flat["critics"], str):
        flat["critics"] = str(flat["critics"]).split()
    try:
        return from_params(DWBConfig, flat, server=server)
    except ParameterError:
        raise


def _project_velocity(v0: float, accel: float, decel: float, dt: float, target: float) -> float:
    """``projectVelocity``: one sim period of acceleration (decel is signed, <= 0)."""
    if v0 < target:
        return min(target, v0 + accel * dt)
    return max(target, v0 + decel * dt)


def _axis_samples(v: float, lo: float, hi: float, acc: float, dec: float, dt: float, n: int
                  ) -> npt.NDArray[np.float64]:
    """``OneDVelocityIterator``: ``n`` evenly spaced samples over the window reachable in
    ``dt`` from the (clamped) current velocity, plus 0 when the window straddles it."""
    v = min(max(v, lo), hi)
    vmax = _project_velocity(v, acc, dec, dt, hi)
    vmin = _project_velocity(v, acc, dec, dt, lo)
    if n <= 1 or vmax == vmin:
        return np.array([vmin])
    s = np.linspace(vmin, vmax, n)
    if vmin < 0.0 < vmax:
        s = np.unique(np.append(s, 0.0))
    return s


@njit(cache=True)
def _rollout_kernel(x0: float, y0: float, th0: float, vx: np.ndarray, vy: np.ndarray,
                    wz: np.ndarray, sim_time: float, steps: int) -> np.ndarray:
    """Constant-twist rollouts (exact arcs), poses at sim_time·k/steps, k = 1..steps."""
    n = vx.shape[0]
    out = np.empty((n, steps, 3))
    c0 = math.cos(th0)
    s0 = math.sin(th0)
    for i in range(n):
        w = wz[i]
        for k in range(steps):
            t = sim_time * (k + 1) / steps
            th = w * t
            if abs(w) < 1e-6:
                x = vx[i] * t - vy[i] * 0.5 * w * t * t
                y = vy[i] * t + vx[i] * 0.5 * w * t * t
            else:
                st = math.sin(th)
                ct = math.cos(th)
                x = (vx[i] * st + vy[i] * (ct - 1.0)) / w
                y = (vx[i] * (1.0 - ct) + vy[i] * st) / w
            out[i, k, 0] = x0 + c0 * x - s0 * y
            out[i, k, 1] = y0 + s0 * x + c0 * y
            out[i, k, 2] = th0 + th
    return out


class DWBController:
    """Sampling controller with critics; the plugin shape of :class:`RegulatedPurePursuitController`."""

    def __init__(self, config: DWBConfig | None = None, name: str = "FollowPath",
                 controller_frequency: float = 20.0) -> None:
        self.config = config or DWBConfig()
        self.config.validate()
        self.name = name
        self.sim_period = 1.0 / controller_frequency
        self.xy_goal_tolerance = 0.25
        self._plan = PlanHandler()
        self._plan_src: object = None
        self._critics = [c.removesuffix("Critic").split("::")[-1] for c in self.config.critics]
        self._rotating = False
        self._in_window = False
        self._speed_scale = 1.0
        self._osc_sign_x = 0.0
        self._osc_sign_w = 0.0
        self._osc_flip_pose: npt.NDArray[np.float64] | None = None
        self._osc_flipped_x = False
        self._osc_flipped_w = False
        self.last_scores: dict[str, float] = {}
        # Map-grid critics' cell values of the last cycle ([y, x], cells), for inspection.
        self.grid_values: dict[str, npt.NDArray[np.float64]] = {}
        self._cycle_values: dict[str, npt.NDArray[np.float64] | None] = {}

    def set_plan(self, path: npt.ArrayLike) -> None:
        self._plan.set_plan(as_path(path))
        self.reset()

    def reset(self) -> None:
        self._rotating = False
        self._in_window = False
        self._osc_sign_x = self._osc_sign_w = 0.0
        self._osc_flip_pose = None
        self._osc_flipped_x = self._osc_flipped_w = False

    def set_speed_limit(self, speed_limit: float, percentage: bool) -> None:
        if speed_limit == 0.0:
            self._speed_scale = 1.0
        elif percentage:
            self._speed_scale = speed_limit / 100.0
        elif self.config.max_speed_xy > 0:
            self._speed_scale = min(1.0, speed_limit / self.config.max_speed_xy)

    def set_goal_tolerance(self, xy_tolerance: float) -> None:
        self.xy_goal_tolerance = xy_tolerance

    # --- main cycle ------------------------------------------------------------------------
    def compute_velocity_commands(
        self,
        pose: npt.ArrayLike,
        velocity: Twist2D,
        path: npt.ArrayLike | None,
        costmap: LayeredCostmap,
        dt: float | None = None,
    ) -> Twist2D:
        cfg = self.config
        # A new path object replaces the plan (held, so identity cannot be recycled);
        # nodes may instead call set_plan() once per received path and pass None here.
        if path is not None and path is not self._plan_src:
            self.set_plan(path)
            self._plan_src = path
        p = as_pose(pose)
        cm = costmap.master
        max_extent = max(cm.size_x, cm.size_y) * cm.resolution / 2.0
        tpath = self._plan.transform(p, cfg.prune_distance, max_extent)
        # Robot-frame plan -> global frame points for map-grid critics.
        c, s = math.cos(p[2]), math.sin(p[2])
        gpath = np.empty_like(tpath)
        gpath[:, 0] = p[0] + c * tpath[:, 0] - s * tpath[:, 1]
        gpath[:, 1] = p[1] + s * tpath[:, 0] + c * tpath[:, 1]
        gpath[:, 2] = tpath[:, 2] + p[2]
        # transformation_end: the plan ends before its first pose farther (Euclidean) from the
        # robot than min(half the costmap, forward_prune_distance).
        end_threshold = max_extent
        if cfg.shorten_transformed_plan:
            end_threshold = min(max_extent, cfg.forward_prune_distance)
        far = np.nonzero(np.hypot(tpath[:, 0], tpath[:, 1]) > end_threshold)[0]
        if far.size and far[0] > 0:
            gpath = gpath[:far[0]]
        goal = self._plan.plan[-1]

        dt_c = self.sim_period
        vmax_x = cfg.max_vel_x * self._speed_scale
        vx = _axis_samples(velocity.vx, cfg.min_vel_x, vmax_x, cfg.acc_lim_x, cfg.decel_lim_x,
                           dt_c, cfg.vx_samples)
        vy = _axis_samples(velocity.vy, cfg.min_vel_y, cfg.max_vel_y, cfg.acc_lim_y,
                           cfg.decel_lim_y, dt_c, cfg.vy_samples)
        wz = _axis_samples(velocity.wz, -cfg.max_vel_theta, cfg.max_vel_theta, cfg.acc_lim_theta,
                           cfg.decel_lim_theta, dt_c, cfg.vtheta_samples)
        VX, VY, WZ = (a.ravel() for a in np.meshgrid(vx, vy, wz, indexing="ij"))
        speed_xy = np.hypot(VX, VY)
        valid = np.ones(VX.shape, dtype=bool)
        max_xy = cfg.max_speed_xy * self._speed_scale
        if max_xy > 0:
            valid &= speed_xy <= max_xy + 1e-9
        valid &= ~((speed_xy < cfg.min_speed_xy) & (np.abs(WZ) < cfg.min_speed_theta))
        VX, VY, WZ = VX[valid], VY[valid], WZ[valid]
        if VX.size == 0:
            raise NoValidControl("no velocity samples inside the limits")

        traj = self._rollout(p, VX, VY, WZ)  # (S, T, 3)
        total = np.zeros(VX.shape[0])
        legal = np.ones(VX.shape[0], dtype=bool)
        scores: dict[str, npt.NDArray[np.float64]] = {}
        dist_to_goal = math.hypot(goal[0] - p[0], goal[1] - p[1])
        in_goal_window = dist_to_goal <= self.xy_goal_tolerance
        self._cycle_values.clear()
        for name in self._critics:
            scale = float(getattr(cfg, f"{name}_scale"))
            if name == "BaseObstacle":
                sc, ok = critics.score_base_obstacle(traj, cm.data, cm.origin_x, cm.origin_y,
                                                     cm.resolution, cfg.BaseObstacle_sum_scores)
            elif name == "ObstacleFootprint":
                sc, ok = critics.score_obstacle_footprint(
                    traj, np.ascontiguousarray(costmap.footprint), cm.data, cm.origin_x,
                    cm.origin_y, cm.resolution, cfg.ObstacleFootprint_sum_scores)
            elif name in _MAP_GRID:
                sc, ok, scale = self._map_grid(name, traj, p, goal, gpath, costmap, scale)
            elif name == "RotateToGoal":
                sc, ok = self._rotate_to_goal(traj, VX, VY, velocity, goal, in_goal_window)
            elif name == "PreferForward":
                sc, ok = critics.score_prefer_forward(
                    VX, WZ, cfg.PreferForward_penalty, cfg.PreferForward_strafe_x,
                    cfg.PreferForward_strafe_theta, cfg.PreferForward_theta_scale)
            elif name == "Twirling":
                sc, ok = critics.score_twirling(WZ)
            else:
                sc, ok = self._oscillation(VX, WZ, p)
            scores[name] = sc
            legal &= ok
            if scale != 0.0:
                total += scale * sc
        if not np.any(legal):
            raise NoValidControl(f"no valid trajectories out of {VX.shape[0]}")
        total[~legal] = np.inf
        best = int(np.argmin(total))
        self.last_scores = {k: float(v[best]) for k, v in scores.items()}
        cmd = Twist2D(float(VX[best]), float(VY[best]), float(WZ[best]))
        self._update_oscillation(cmd, p)
        return cmd

    # --- rollouts ---------------------------------------------------------------------------
    def _rollout(self, pose: npt.NDArray[np.float64], vx: npt.NDArray[np.float64],
                 vy: npt.NDArray[np.float64], wz: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        cfg = self.config
        T = cfg.sim_time
        if cfg.discretize_by_time:
            steps = max(1, math.ceil(T / cfg.time_granularity))
        else:
            dist = float(np.max(np.hypot(vx, vy))) * T
            ang = float(np.max(np.abs(wz))) * T
            steps = max(1, math.ceil(dist / cfg.linear_granularity), math.ceil(ang / cfg.angular_granularity))
        steps = min(steps, 200)
        out = _rollout_kernel(float(pose[0]), float(pose[1]), float(pose[2]),
                              np.ascontiguousarray(vx), np.ascontiguousarray(vy),
                              np.ascontiguousarray(wz), T, steps)
        if not cfg.include_last_point and steps > 1:
            out = out[:, :-1]
        return out

    # --- critics ------------------------------------------------------------------------------
    def _map_grid(self, name: str, traj: npt.NDArray[np.float64], pose: npt.NDArray[np.float64],
                  goal: npt.NDArray[np.float64], plan: npt.NDArray[np.float64],
                  costmap: LayeredCostmap, scale: float
                  ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_], float]:
        """One map-grid critic: ``prepare`` (wavefront from the transformed plan) and
        ``scoreTrajectory``; returns scores, legality and the effective scale: as upstream's
        ``MapGridCritic::getScale`` every map-grid critic weighs its cell distances by
        ``resolution / 2 · scale`` (PathAlign's is 0 within ``forward_point_distance`` of the
        goal)."""
        cfg = self.config
        cm = costmap.master
        n = traj.shape[0]
        origin = (cm.origin_x, cm.origin_y)
        fwd = 0.0
        scale *= cm.resolution * 0.5
        if name == "PathAlign":
            fwd = cfg.PathAlign_forward_point_distance
            if math.hypot(pose[0] - goal[0], pose[1] - goal[1]) <= fwd:
                return np.zeros(n), np.ones(n, dtype=bool), 0.0
        elif name == "GoalAlign":
            fwd = cfg.GoalAlign_forward_point_distance
            # The nose is drawn to the goal position seen from the robot, not to the goal
            # heading, so a final 180° turn does not pull the robot past the goal.
            ang = math.atan2(goal[1] - pose[1], goal[0] - pose[0])
            plan = plan.copy()
            plan[-1, 0] += fwd * math.cos(ang)
            plan[-1, 1] += fwd * math.sin(ang)
        if name in ("PathDist", "PathAlign"):
            # Both seed from the same plan: one wavefront per cycle serves the two.
            if "path" not in self._cycle_values:
                self._cycle_values["path"] = critics.path_dist_values(plan, cm.data, origin,
                                                                      cm.resolution)
            vals = self._cycle_values["path"]
        else:
            vals = critics.goal_dist_values(plan, cm.data, origin, cm.resolution)
        if vals is None:  # upstream logs the failed prepare and scores nothing
            return np.zeros(n), np.ones(n, dtype=bool), scale
        self.grid_values[name] = vals
        sc, ok = critics.score_map_grid(traj, vals, origin, cm.resolution,
                                        str(getattr(cfg, f"{name}_aggregation_type")),
                                        name in ("PathDist", "GoalDist"), fwd)
        return sc, ok, scale

    def _rotate_to_goal(self, traj: npt.NDArray[np.float64], vx: npt.NDArray[np.float64],
                        vy: npt.NDArray[np.float64], velocity: Twist2D,
                        goal: npt.NDArray[np.float64], in_window: bool
                        ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        n = vx.shape[0]
        # upstream's RotateToGoalCritic::prepare: once inside the goal window (and once
        # rotating) it stays so until the plan is set again; a localization jitter at the
        # window's edge does not send the robot driving again
        self._in_window = self._in_window or in_window
        if not self._in_window:
            return np.zeros(n), np.ones(n, dtype=bool)
        end_yaw = traj[:, -1, 2]
        rot = np.abs(np.arctan2(np.sin(goal[2] - end_yaw), np.cos(goal[2] - end_yaw)))
        cur_sq = velocity.vx ** 2 + velocity.vy ** 2
        self._rotating = self._rotating or cur_sq <= self.config.trans_stopped_velocity ** 2
        speed_sq = vx ** 2 + vy ** 2
        if not self._rotating:
            # "Not slowing down near goal": a sample at or above the current speed is illegal
            ok = speed_sq < cur_sq
            return speed_sq * self.config.RotateToGoal_slowing_factor + rot, ok
        ok = (np.abs(vx) == 0.0) & (np.abs(vy) == 0.0)
        return rot, ok

    def _oscillation(self, vx: npt.NDArray[np.float64], wz: npt.NDArray[np.float64],
                     pose: npt.NDArray[np.float64]
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        n = vx.shape[0]
        ok = np.ones(n, dtype=bool)
        if self._osc_flipped_x:
            ok &= ~(np.sign(vx) == -self._osc_sign_x)
        if self._osc_flipped_w:
            ok &= ~((np.sign(wz) == -self._osc_sign_w) & (vx == 0.0))
        return np.zeros(n), ok

    def _update_oscillation(self, cmd: Twist2D, pose: npt.NDArray[np.float64]) -> None:
        cfg = self.config
        sx = float(np.sign(cmd.vx))
        sw = float(np.sign(cmd.wz))
        if self._osc_flip_pose is not None:
            d = math.hypot(pose[0] - self._osc_flip_pose[0], pose[1] - self._osc_flip_pose[1])
            a = abs(wrap_angle(pose[2] - self._osc_flip_pose[2]))
            if d > cfg.Oscillation_oscillation_reset_dist or a > cfg.Oscillation_oscillation_reset_angle:
                self._osc_flipped_x = self._osc_flipped_w = False
                self._osc_flip_pose = None
        if sx != 0.0 and self._osc_sign_x != 0.0 and sx != self._osc_sign_x:
            self._osc_flipped_x = True
            self._osc_flip_pose = pose.copy()
        if sw != 0.0 and self._osc_sign_w != 0.0 and sw != self._osc_sign_w and cmd.vx == 0.0:
            self._osc_flipped_w = True
            self._osc_flip_pose = pose.copy()
        if sx != 0.0:
            self._osc_sign_x = sx
        if sw != 0.0:
            self._osc_sign_w = sw


__all__ = ["KNOWN_CRITICS", "DWBConfig", "DWBController", "dwb_config_from_params"]
