"""nav2_bt_navigator: ``navigate_to_pose`` and ``navigate_through_poses``.

Each goal runs Nav2's default tree (:mod:`eddiebot.nav.bt.trees`) ticked every
``bt_loop_duration`` ms on the node clock; the tree's nodes talk to the planner, controller
and behaviour servers through action clients and never block. Feedback as Nav2's:
``current_pose``, ``navigation_time``, ``estimated_time_remaining``,
``number_of_recoveries``, ``distance_remaining`` (and ``number_of_poses_remaining``). A new
goal while one runs updates the running tree's goal (the old goal is aborted, as Nav2's
preemption does); cancel halts the tree, which cancels the running server goals. A failed
navigation ends with the error code and message of the server that failed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from py_trees.behaviour import Behaviour
from py_trees.common import Status

from eddiebot.core.action import ActionClient, ActionServer, CancelResponse, ServerGoalHandle, sleep
from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.tf import Buffer, TransformListener
from eddiebot.core.time import Duration
from eddiebot.nav.bt import (
    NavBlackboard,
    NavClients,
    TreeOptions,
    navigate_through_poses_tree,
    navigate_to_pose_tree,
    tick_child,
)
from eddiebot.nav.bt.nodes import path_length_from
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.nodes._common import (
    NavServer,
    path_from_msg,
    pose_is_finite,
    pose_stamped,
    robot_pose,
)

__all__ = ["BtNavigator"]


class BtNavigator(NavServer):
    default_node_name = "bt_navigator"
    PARAMETERS = {
        "global_frame": "map", "robot_base_frame": "base_link", "odom_topic": "odom",
        "transform_tolerance": 0.1, "bt_loop_duration": 10, "default_server_timeout": 20,
        "filter_duration": 0.3, "navigators": ["navigate_to_pose", "navigate_through_poses"],
        "default_nav_to_pose_bt_xml": "", "default_nav_through_poses_bt_xml": "",
        "goal_blackboard_id": "goal", "path_blackboard_id": "path",
        # eddiebot: the default tree's numbers (Nav2 has them in the tree's XML)
        "replanning_frequency": 1.0, "number_of_retries": 6, "feedback_frequency": 10.0,
    }

    def __init__(self, node_name: str = "bt_navigator", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.tf_buffer = Buffer(node=self)
        self._listener: TransformListener | None = None
        self._actions: list[ActionServer] = []
        self._clients: NavClients | None = None
        self._odom_sub: Any = None
        self._speed = 0.0
        self.options = TreeOptions()
        self._handle: ServerGoalHandle | None = None
        self._tree: Behaviour | None = None
        self._kind = ""
        self.bb = NavBlackboard()
        self._start_ns = 0
        self._path_xy: tuple[Any, np.ndarray] = (None, np.zeros((0, 2)))

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            loop = int(self.param("bt_loop_duration"))
            if loop <= 0:
                raise ParameterError(self.get_name(), "bt_loop_duration", loop, "must be > 0 (ms)")
            retries = int(self.param("number_of_retries"))
            if retries < 0:
                raise ParameterError(self.get_name(), "number_of_retries", retries, "must be >= 0")
            hz = float(self.param("replanning_frequency"))
            if hz <= 0.0:
                raise ParameterError(self.get_name(), "replanning_frequency", hz, "must be > 0")
            for key in ("default_nav_to_pose_bt_xml", "default_nav_through_poses_bt_xml"):
                if self.param(key):
                    self.get_logger().warning(
                        f"{key}: behaviour-tree XML files are not read; the default tree is built "
                        f"in code")
            self.options = TreeOptions(replanning_frequency=hz, number_of_retries=retries)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav2_msgs import (
            BackUp,
            ClearEntireCostmap,
            ComputePathThroughPoses,
            ComputePathToPose,
            FollowPath,
            NavigateThroughPoses,
            NavigateToPose,
            Spin,
            Wait,
        )
        from eddiebot.msgs.nav_msgs import Odometry

        self._listener = TransformListener(self.tf_buffer, self)
        self._clients = NavClients(
            compute_path_to_pose=ActionClient(self, ComputePathToPose, "/compute_path_to_pose"),
            compute_path_through_poses=ActionClient(self, ComputePathThroughPoses,
                                                    "/compute_path_through_poses"),
            follow_path=ActionClient(self, FollowPath, "/follow_path"),
            spin=ActionClient(self, Spin, "/spin"),
            backup=ActionClient(self, BackUp, "/backup"),
            wait=ActionClient(self, Wait, "/wait"),
            clear_local_costmap=self.create_client(
                ClearEntireCostmap, "/local_costmap/clear_entirely_local_costmap"),
            clear_global_costmap=self.create_client(
                ClearEntireCostmap, "/global_costmap/clear_entirely_global_costmap"),
        )
        self._odom_sub = self.create_subscription(Odometry, str(self.param("odom_topic")),
                                                  self._on_odom, 10)
        cancel = self._accept_cancel
        navigators = [n for n in self.param("navigators") if n]
        if "navigate_to_pose" in navigators:
            self._actions.append(ActionServer(self, NavigateToPose, "navigate_to_pose",
                                              self._navigate_to_pose, cancel_callback=cancel))
        if "navigate_through_poses" in navigators:
            self._actions.append(ActionServer(self, NavigateThroughPoses, "navigate_through_poses",
                                              self._navigate_through_poses, cancel_callback=cancel))
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        if self._tree is not None:
            self._tree.stop(Status.INVALID)
            self._tree = None
        for a in self._actions:
            a.destroy()
        self._actions = []
        if self._clients is not None:
            for c in vars(self._clients).values():
                if isinstance(c, ActionClient):
                    c.destroy()
                else:
                    self.destroy_client(c)
            self._clients = None
        if self._odom_sub is not None:
            self.destroy_subscription(self._odom_sub)
            self._odom_sub = None
        if self._listener is not None:
            self._listener.unregister()
            self._listener = None
        return TransitionCallbackReturn.SUCCESS

    @staticmethod
    def _accept_cancel(_handle: ServerGoalHandle) -> CancelResponse:
        return CancelResponse.ACCEPT

    def _on_odom(self, msg: Any) -> None:
        t = msg.twist.twist
        self._speed = math.hypot(t.linear.x, t.linear.y)

    def _clock(self) -> int:
        return self.now().nanoseconds

    def _robot_pose(self) -> Any:
        return robot_pose(self.tf_buffer, str(self.param("global_frame")),
                          str(self.param("robot_base_frame")), self.now().nanoseconds,
                          max(float(self.param("transform_tolerance")), 0.5))

    # -- goals --------------------------------------------------------------------------------
    async def _navigate_to_pose(self, handle: ServerGoalHandle) -> Any:
        return await self._navigate(handle, "navigate_to_pose")

    async def _navigate_through_poses(self, handle: ServerGoalHandle) -> Any:
        return await self._navigate(handle, "navigate_through_poses")

    def _load_goal(self, kind: str, goal: Any) -> None:
        gf = str(self.param("global_frame"))
        if kind == "navigate_to_pose":
            g = goal.pose
            if not g.header.frame_id:
                g.header.frame_id = gf
            self.bb.set_goal(g)
        else:
            for g in goal.poses:
                if not g.header.frame_id:
                    g.header.frame_id = gf
            self.bb.set_goals(list(goal.poses))
            if goal.poses:
                self.bb.goal = goal.poses[-1]

    async def _navigate(self, handle: ServerGoalHandle, kind: str) -> Any:
        from eddiebot.msgs.nav2_msgs import NavigateThroughPoses, NavigateToPose

        action = NavigateToPose if kind == "navigate_to_pose" else NavigateThroughPoses
        result = action.Result()
        assert self._clients is not None
        poses = [handle.request.pose] if kind == "navigate_to_pose" else list(handle.request.poses)
        bad = [i for i, ps in enumerate(poses) if not pose_is_finite(ps.pose)]
        if bad:
            # refused before it preempts anything: the planner would answer GOAL_OUTSIDE_MAP
            # (204, or 304 through poses) only after a tick, a NaN yaw never satisfies a goal
            # checker, and no recovery helps either
            result.error_code = 204 if kind == "navigate_to_pose" else 304
            result.error_msg = f"{kind}: goal pose {bad[0]} is not finite"
            self.get_logger().warning(result.error_msg)
            handle.abort()
            return result
        previous = self._handle
        self._handle = handle
        if previous is not None and previous.is_active and self._tree is not None and self._kind == kind:
            self.get_logger().info(f"{kind}: new goal preempts the running one")
            self._load_goal(kind, handle.request)
        else:
            if self._tree is not None:
                self._tree.stop(Status.INVALID)
            self.bb = NavBlackboard(robot_pose=self._robot_pose)
            self._load_goal(kind, handle.request)
            factory = navigate_to_pose_tree if kind == "navigate_to_pose" else navigate_through_poses_tree
            self._tree = factory(self.bb, self._clients, self._clock, self.options)
            self._kind = kind
            self._start_ns = self.now().nanoseconds
            g = pose_stamped_of(self.bb.goal)
            self.get_logger().info(f"{kind}: begin navigating to ({g[0]:.2f}, {g[1]:.2f})")
        loop_s = int(self.param("bt_loop_duration")) / 1000.0
        fb_period_ns = round(1e9 / float(self.param("feedback_frequency")))
        last_fb = 0
        tree = self._tree
        assert tree is not None
        while True:
            if self._handle is not handle:
                handle.abort()
                return result
            if handle.is_cancel_requested:
                tree.stop(Status.INVALID)
                self._finish(handle)
                handle.canceled()
                return result
            status = tick_child(tree)
            now = self.now().nanoseconds
            if status == Status.SUCCESS:
                self.get_logger().info(f"{kind}: goal succeeded")
                self._finish(handle)
                handle.succeed()
                return result
            if status == Status.FAILURE:
                result.error_code = int(self.bb.error_code)
                result.error_msg = self.bb.error_msg or "navigation failed"
                self.get_logger().warning(f"{kind}: goal failed: {result.error_msg}")
                self._finish(handle)
                handle.abort()
                return result
            if now - last_fb >= fb_period_ns:
                last_fb = now
                handle.publish_feedback(self._feedback(action, now))
            await sleep(self, loop_s)

    def _finish(self, handle: ServerGoalHandle) -> None:
        if self._handle is handle:
            self._handle = None
            self._tree = None

    def _feedback(self, action: Any, now: int) -> Any:
        fb = action.Feedback()
        gf = str(self.param("global_frame"))
        pose = robot_pose(self.tf_buffer, gf, str(self.param("robot_base_frame")), now,
                          max(float(self.param("transform_tolerance")), 0.5))
        if pose is not None:
            fb.current_pose = pose_stamped(pose[0], pose[1], pose[2], gf, now)
            if self.bb.path is not None and self.bb.path.poses:
                if self._path_xy[0] is not self.bb.path:  # converted once per new path
                    self._path_xy = (self.bb.path, path_from_msg(self.bb.path)[:, :2])
                d = path_length_from(self._path_xy[1], pose[0], pose[1])
                fb.distance_remaining = float(d)
                if self._speed > 0.01:
                    fb.estimated_time_remaining = Duration.from_seconds(d / self._speed).to_msg()
        fb.navigation_time = Duration(now - self._start_ns).to_msg()
        fb.number_of_recoveries = int(self.bb.number_of_recoveries)
        if hasattr(fb, "number_of_poses_remaining"):
            fb.number_of_poses_remaining = len(self.bb.goals)
        return fb


def pose_stamped_of(ps: Any) -> np.ndarray:
    if ps is None:
        return np.zeros(3)
    return np.array([ps.pose.position.x, ps.pose.position.y, 0.0])
