"""nav2_controller: the controller server with its local (rolling) costmap.

Parameters as Nav2's ``controller_server`` (``controller_frequency`` 20 Hz,
``controller_plugins``, ``progress_checker_plugins``, ``goal_checker_plugins``, each with
``plugin:``; ``failure_tolerance``; ``odom_topic``) plus the local costmap under the prefix
``local_costmap.``. ``follow_path`` (nav2_msgs/FollowPath) drives ``/cmd_vel_nav`` (remap
``cmd_vel``). A new goal while one runs takes over (the old goal is aborted, the progress
checker keeps its state), as Nav2's preemption does. The path is brought into the costmap's
frame (odom) with the current TF when it arrives.

Never drives blind: a lost or stale robot transform publishes a zero twist and aborts with
TF_ERROR; odometry older than ``odom_timeout`` (s, eddiebot's addition) holds the robot at zero
until it comes back; every failure, cancel and success ends with a zero twist.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.core.action import ActionServer, CancelResponse, ServerGoalHandle, sleep
from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.tf import Buffer, TransformException, TransformListener
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav_msgs import Path
from eddiebot.nav.controllers import ControllerServer as ControllerPlugins
from eddiebot.nav.controllers import build_controller_server
from eddiebot.nav.controllers.follow_path import FollowPathRun, RunStatus
from eddiebot.nav.costmap import LayeredCostmap, build_costmap
from eddiebot.nav.errors import (
    ControllerError,
    ControllerTFError,
    InvalidController,
    InvalidPath,
    NavError,
)
from eddiebot.nav.nodes._common import NavServer, path_from_msg, path_to_msg, twist_to_msg
from eddiebot.nav.nodes._costmap import CostmapHost
from eddiebot.nav.nodes.amcl import LocalizationWatch
from eddiebot.nav.types import Twist2D

__all__ = ["ControllerServer"]


def _first(names: Any, wanted: str) -> str:
    return wanted or (names[0] if names else "")


class ControllerServer(NavServer):
    default_node_name = "controller_server"
    #: see PlannerServer.nested_parameter_nodes
    nested_parameter_nodes = {"local_costmap/local_costmap": "local_costmap"}
    PARAMETERS = {
        "controller_frequency": 20.0, "min_x_velocity_threshold": 0.0001,
        "min_y_velocity_threshold": 0.0001, "min_theta_velocity_threshold": 0.0001,
        "failure_tolerance": 0.0, "speed_limit_topic": "speed_limit",
        "use_realtime_priority": False, "progress_checker_plugins": ["progress_checker"],
        "goal_checker_plugins": ["goal_checker"], "controller_plugins": ["FollowPath"],
        "odom_topic": "odom", "enable_stamped_cmd_vel": False,
        # eddiebot: odometry older than this (s) holds the robot at zero
        "odom_timeout": 0.5,
        # eddiebot (never drive blind): with localization_check, a lost localization (see
        # nav.amcl.LocalizationLimits) holds the robot at zero, and aborts the goal with
        # a TF error once it has lasted localization_lost_timeout s -- the navigator's
        # recovery spin, which the collision monitor lets through, then relocalizes. A
        # robot pose older than the local costmap's transform_tolerance holds it as well,
        # and is a TF error after the same time.
        "localization_check": False, "global_frame_id": "map",
        "localization_pose_topic": "amcl_pose", "localization_tf_timeout": 1.0,
        "localization_max_xy_std": 0.5, "localization_max_yaw_std": 0.5,
        "localization_lost_timeout": 2.0,
    }

    def __init__(self, node_name: str = "controller_server", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.plugins: ControllerPlugins | None = None
        self.costmap: LayeredCostmap | None = None
        self.host: CostmapHost | None = None
        self.tf_buffer = Buffer(node=self)
        self._listener: TransformListener | None = None
        self._action: ActionServer | None = None
        self._cmd_pub: Any = None
        self._local_plan_pub: Any = None
        self._subs: list[Any] = []
        self._velocity = Twist2D()
        self._odom_ns: int | None = None
        self._frun: FollowPathRun | None = None
        self._handle: ServerGoalHandle | None = None
        self._run_controller = ""
        self._watch: LocalizationWatch | None = None
        self._lost_since_ns: int | None = None
        self._stale_since_ns: int | None = None

    # -- lifecycle ----------------------------------------------------------------------------
    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            tree = self.params_tree()
            cm_params = tree.pop("local_costmap", {}) or {}
            for key in ("odom_topic", "enable_stamped_cmd_vel", "odom_timeout", "global_frame_id"):
                tree.pop(key, None)
            for key in [k for k in tree if k.startswith("localization_")]:
                tree.pop(key)
            self.plugins = build_controller_server(tree, server=self.get_name())
            self.costmap = build_costmap(cm_params, "local_costmap")
            self.host = CostmapHost(self, self.costmap, "local_costmap", self.tf_buffer)
            self._cmd_pub = self.create_lifecycle_publisher(Twist, "cmd_vel", 1)
            self._local_plan_pub = self.create_lifecycle_publisher(Path, "/local_plan", 1)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav2_msgs import FollowPath, SpeedLimit
        from eddiebot.msgs.nav_msgs import Odometry

        assert self.host is not None and self.plugins is not None
        self._listener = TransformListener(self.tf_buffer, self)
        self.host.activate()
        self._subs = [
            self.create_subscription(Odometry, str(self.param("odom_topic")), self._on_odom, 10),
            self.create_subscription(SpeedLimit, self.plugins.config.speed_limit_topic,
                                     self._on_speed_limit, 1),
        ]
        if bool(self.param("localization_check")):
            self._watch = LocalizationWatch.from_parameters(self, self.tf_buffer, self.host.global_frame)
        self._action = ActionServer(self, FollowPath, "follow_path", self._follow,
                                    cancel_callback=lambda _h: CancelResponse.ACCEPT)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        self.publish_zero()
        if self._action is not None:
            self._action.destroy()
            self._action = None
        for s in self._subs:
            self.destroy_subscription(s)
        self._subs = []
        if self._watch is not None:
            self._watch.destroy()
            self._watch = None
        if self.host is not None:
            self.host.deactivate()
        if self._listener is not None:
            self._listener.unregister()
            self._listener = None
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        if self.host is not None:
            self.host.destroy()
        for p in (self._cmd_pub, self._local_plan_pub):
            if p is not None:
                self.destroy_lifecycle_publisher(p)
        self.host = self.costmap = self.plugins = None
        self._cmd_pub = self._local_plan_pub = None
        return TransitionCallbackReturn.SUCCESS

    # -- inputs -------------------------------------------------------------------------------
    def _on_odom(self, msg: Any) -> None:
        t = msg.twist.twist
        self._velocity = Twist2D(t.linear.x, t.linear.y, t.angular.z)
        self._odom_ns = self.now().nanoseconds

    def _on_speed_limit(self, msg: Any) -> None:
        if self.plugins is None:
            return
        for c in self.plugins.controllers.values():
            c.set_speed_limit(float(msg.speed_limit), bool(msg.percentage))

    def publish_zero(self) -> None:
        if self._cmd_pub is not None and self._cmd_pub.is_activated:
            self._cmd_pub.publish(twist_to_msg(Twist2D()))

    def _odom_fresh(self, now_ns: int) -> bool:
        return self._odom_ns is not None and \
            (now_ns - self._odom_ns) * 1e-9 <= float(self.param("odom_timeout"))

    # -- follow_path --------------------------------------------------------------------------
    def _path_in_costmap_frame(self, msg: Any) -> npt.NDArray[np.float64]:
        assert self.host is not None
        path = path_from_msg(msg)
        if path.shape[0] == 0:
            raise InvalidPath("received an empty plan")
        frame = msg.header.frame_id or (msg.poses[0].header.frame_id if msg.poses else "")
        target = self.host.global_frame
        if not frame or frame == target:
            return path
        try:
            x, y, yaw = self.tf_buffer.lookup_pose2d(target, frame, 0)
        except TransformException as exc:
            raise ControllerTFError(f"cannot transform the plan from {frame} to {target}: {exc}") from exc
        c, s = math.cos(yaw), math.sin(yaw)
        out = np.empty_like(path)
        out[:, 0] = x + c * path[:, 0] - s * path[:, 1]
        out[:, 1] = y + s * path[:, 0] + c * path[:, 1]
        out[:, 2] = path[:, 2] + yaw
        return out

    def _start_run(self, goal: Any) -> None:
        assert self.plugins is not None
        cfg = self.plugins.config
        cid = _first(cfg.controller_plugins, goal.controller_id)
        if cid not in self.plugins.controllers:
            raise InvalidController(f"FollowPath called with controller name {cid!r}, which does "
                                    f"not exist; have {sorted(self.plugins.controllers)}")
        gid = _first(cfg.goal_checker_plugins, goal.goal_checker_id)
        pid = _first(cfg.progress_checker_plugins, goal.progress_checker_id)
        if gid not in self.plugins.goal_checkers or pid not in self.plugins.progress_checkers:
            raise InvalidController(f"unknown goal checker {gid!r} or progress checker {pid!r}")
        path = self._path_in_costmap_frame(goal.path)
        if self._frun is not None and self._run_controller == cid:
            self._frun.update_path(path)
        else:
            self._frun = FollowPathRun(cfg, self.plugins.controllers[cid],
                                      self.plugins.goal_checkers[gid],
                                      self.plugins.progress_checkers[pid], path,
                                      self.now().nanoseconds)
            self._run_controller = cid
        self._publish_local_plan(path)

    def _publish_local_plan(self, path: npt.NDArray[np.float64]) -> None:
        assert self.host is not None
        self._local_plan_pub.publish(path_to_msg(path, self.host.global_frame, self.now().nanoseconds))

    def _end(self, handle: ServerGoalHandle) -> None:
        self.publish_zero()
        if self._handle is handle:
            self._handle = None
            self._frun = None

    async def _follow(self, handle: ServerGoalHandle) -> Any:
        from eddiebot.msgs.nav2_msgs import FollowPath

        result = FollowPath.Result()
        assert self.host is not None and self.plugins is not None
        previous = self._handle
        self._handle = handle
        self._stale_since_ns = None  # a new goal times a stale pose afresh
        if previous is not None and previous.is_active:
            self.get_logger().info("preempting the running goal with a new path")
        try:
            self._start_run(handle.request)
        except NavError as err:
            return self._abort(handle, result, err)
        period = 1.0 / self.plugins.config.controller_frequency
        while True:
            if self._handle is not handle:  # preempted: the new goal drives now
                handle.abort()
                return result
            if handle.is_cancel_requested:
                self._end(handle)
                handle.canceled()
                return result
            now = self.now().nanoseconds
            pose = self.host.robot_pose()
            if pose is None:
                # a pose older than transform_tolerance holds the robot, as stale odometry
                # does (a loaded machine delays the driver's TF by a few tenths of a second);
                # none at all, or one stale for localization_lost_timeout, is a TF error
                tf_error = ControllerTFError(
                    f"lost the robot pose ({self.host.global_frame} -> {self.host.base_frame})")
                if self.host.latest_robot_pose() is None:
                    return self._abort(handle, result, tf_error)
                if self._stale_since_ns is None:
                    self._stale_since_ns = now
                    self.get_logger().warning("the robot pose is stale: holding the robot")
                if (now - self._stale_since_ns) * 1e-9 >= float(self.param("localization_lost_timeout")):
                    self._stale_since_ns = None
                    return self._abort(handle, result, tf_error)
                self.publish_zero()
                await sleep(self, period)
                continue
            self._stale_since_ns = None
            lost = self._watch.problem(now) if self._watch is not None else ""
            if not lost:
                self._lost_since_ns = None
            if lost:
                if self._lost_since_ns is None:
                    self._lost_since_ns = now
                    self.get_logger().warning(f"{lost}: holding the robot")
                if (now - self._lost_since_ns) * 1e-9 >= float(self.param("localization_lost_timeout")):
                    self._lost_since_ns = None
                    return self._abort(handle, result, ControllerTFError(lost))
                self.publish_zero()
            elif not self._odom_fresh(now):
                self.get_logger().warning("odometry is stale: holding the robot", once=True)
                self.publish_zero()
            else:
                assert self._frun is not None and self.costmap is not None
                step = self._frun.step(pose, self._velocity, self.costmap, now)
                if step.status == RunStatus.SUCCEEDED:
                    self.get_logger().info("reached the goal")
                    self._end(handle)
                    handle.succeed()
                    return result
                if step.status == RunStatus.FAILED:
                    return self._abort(handle, result, step.error or ControllerError("controller failed"))
                self._cmd_pub.publish(twist_to_msg(step.cmd))
                handle.publish_feedback(FollowPath.Feedback(
                    distance_to_goal=float(step.distance_to_goal),
                    speed=float(math.hypot(self._velocity.vx, self._velocity.vy))))
            await sleep(self, period)

    def _abort(self, handle: ServerGoalHandle, result: Any, err: NavError) -> Any:
        self.get_logger().warning(f"follow_path aborted: {err}")
        self._end(handle)
        result.error_code = int(err.result_code or ControllerError.result_code)
        result.error_msg = str(err)
        if handle.is_active:
            handle.abort()
        return result


