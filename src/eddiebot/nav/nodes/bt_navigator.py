"""nav2_bt_navigator: ``navigate_to_pose`` and ``navigate_through_poses`` run BT XML.

Each navigator runs a BehaviorTree.CPP v3/v4 XML file (:mod:`eddiebot.nav.bt`):
``default_nav_to_pose_bt_xml`` / ``default_nav_through_poses_bt_xml`` (Nav2 Jazzy's
``navigate_*_w_replanning_and_recovery.xml`` when empty), or the goal's ``behavior_tree``.
The files are loaded and checked at configure (an unknown node or port fails the bring-up
naming file and line); a goal naming a tree that does not load is aborted with that error,
and so is a goal for which TF gives no robot pose in ``global_frame`` within
``initial_pose_timeout`` s (Nav2's "Initial robot pose is not available", at once there).
``plugin_lib_names`` entries are resolved through
:meth:`~eddiebot.nav.bt.BehaviorTreeFactory.load_plugin`. The tree is ticked every
``bt_loop_duration`` ms on the node clock; its nodes reach the servers through action
clients and never block. The goal is on the blackboard as ``goal_blackboard_id`` (``goal``)
or ``goals_blackboard_id`` (``goals``); feedback as Nav2's: ``current_pose``,
``navigation_time``, ``estimated_time_remaining``, ``number_of_recoveries`` (the
blackboard's ``number_recoveries``), ``distance_remaining`` (along
``path_blackboard_id``) and ``number_of_poses_remaining``. A new goal for the same tree
updates the running tree's goal (the old goal is aborted, as Nav2's preemption does); one
for another tree is refused and the running goal continues. A preempting goal does not
succeed on the old goal's path: when the tree ends in success before a plan requested
after the preemption came back, it is started over for the new goal (Nav2 would report
success there, navigation2#920). Cancel halts the tree, which
cancels the running server goals. A failed navigation's error code is the lowest non-zero
one among the blackboard entries named by ``error_code_names`` (Jazzy) and
``<prefix>_error_code`` for each of ``error_code_name_prefixes`` (Kilted).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.action import ActionServer, CancelResponse, ServerGoalHandle, sleep
from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.tf import Buffer, TransformListener
from eddiebot.core.time import Duration
from eddiebot.nav.bt import (
    DEFAULT_TREES,
    BehaviorTreeFactory,
    Blackboard,
    Status,
    Tree,
    TreeContext,
    TreeError,
    resolve_tree_path,
)
from eddiebot.nav.bt.nodes import RECOVERIES_KEY, path_length_from
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.nodes._common import (
    NavServer,
    path_from_msg,
    pose_is_finite,
    pose_stamped,
    robot_pose,
)

__all__ = ["BtNavigator"]

_XML_KEYS = {"navigate_to_pose": "default_nav_to_pose_bt_xml",
             "navigate_through_poses": "default_nav_through_poses_bt_xml"}


class BtNavigator(NavServer):
    default_node_name = "bt_navigator"
    PARAMETERS = {
        "global_frame": "map", "robot_base_frame": "base_link", "odom_topic": "odom",
        "transform_tolerance": 0.1, "bt_loop_duration": 10, "default_server_timeout": 20,
        "wait_for_service_timeout": 1000, "action_server_result_timeout": 900.0,
        "filter_duration": 0.3, "navigators": ["navigate_to_pose", "navigate_through_poses"],
        "default_nav_to_pose_bt_xml": "", "default_nav_through_poses_bt_xml": "",
        "always_reload_bt_xml": False, "plugin_lib_names": [""],
        "error_code_names": ["compute_path_error_code", "follow_path_error_code"],
        # Kilted: entries named <prefix>_error_code (read as well as error_code_names)
        "error_code_name_prefixes": [""],
        "goal_blackboard_id": "goal", "goals_blackboard_id": "goals",
        "path_blackboard_id": "path", "goal_updater_topic": "goal_update",
        # eddiebot: how often feedback is published (Nav2 publishes on every loop)
        "feedback_frequency": 10.0,
        # eddiebot: seconds a goal waits for the robot's pose (localisation starting up)
        # before it is aborted as Nav2 aborts it at once (0: Nav2's behaviour)
        "initial_pose_timeout": 10.0,
    }

    def __init__(self, node_name: str = "bt_navigator", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.tf_buffer = Buffer(node=self)
        self._listener: TransformListener | None = None
        self._actions: list[ActionServer] = []
        self._odom_sub: Any = None
        self._speed = 0.0
        self.factory = BehaviorTreeFactory()
        self.default_trees: dict[str, Path] = {}
        self.tree_context: TreeContext | None = None
        self._handle: ServerGoalHandle | None = None
        #: the loaded tree and its file, per navigator (reused while the file is the same)
        self._trees: dict[str, tuple[Path, Tree]] = {}
        self._tree: Tree | None = None
        self._kind = ""
        self._start_ns = 0
        self._path_xy: tuple[Any, np.ndarray] = (None, np.zeros((0, 2)))

    @property
    def blackboard(self) -> Blackboard | None:
        """The running (or last) tree's blackboard."""
        return self._tree.blackboard if self._tree is not None else None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            loop = int(self.param("bt_loop_duration"))
            if loop <= 0:
                raise ParameterError(self.get_name(), "bt_loop_duration", loop, "must be > 0 (ms)")
            if float(self.param("feedback_frequency")) <= 0.0:
                raise ParameterError(self.get_name(), "feedback_frequency",
                                     self.param("feedback_frequency"), "must be > 0")
            self.factory = BehaviorTreeFactory()
            for lib in self.param("plugin_lib_names") or []:
                if lib:
                    try:
                        self.factory.load_plugin(str(lib))
                    except TreeError as exc:
                        raise ParameterError(self.get_name(), "plugin_lib_names", lib,
                                             str(exc)) from None
            self.default_trees = {}
            self._trees = {}
            for kind, key in _XML_KEYS.items():
                value = str(self.param(key) or "")
                path = resolve_tree_path(value) if value else DEFAULT_TREES[kind]
                # loaded once here so a bad file fails the bring-up, with file and line
                self.factory.create_tree_from_file(path, Blackboard(), TreeContext())
                self.default_trees[kind] = path
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav2_msgs import NavigateThroughPoses, NavigateToPose
        from eddiebot.msgs.nav_msgs import Odometry

        self._listener = TransformListener(self.tf_buffer, self)
        self.tree_context = TreeContext(
            self, clock=self._clock, robot_pose=self._robot_pose_in, speed=lambda: self._speed,
            server_timeout_ms=int(self.param("default_server_timeout")),
            wait_for_service_timeout_ms=int(self.param("wait_for_service_timeout")),
            goal_updater_topic=str(self.param("goal_updater_topic")))
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
        for kind in _XML_KEYS:  # the default trees, with their clients, as Nav2 loads them
            if kind in navigators:
                self.tree_for(kind, "")
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        if self._tree is not None:
            self._tree.halt()
            self._tree = None
        self._trees = {}
        for a in self._actions:
            a.destroy()
        self._actions = []
        if self.tree_context is not None:
            self.tree_context.destroy()
            self.tree_context = None
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

    def _robot_pose_in(self, global_frame: str | None = None, base_frame: str | None = None) -> Any:
        return robot_pose(self.tf_buffer, global_frame or str(self.param("global_frame")),
                          base_frame or str(self.param("robot_base_frame")),
                          self.now().nanoseconds,
                          max(float(self.param("transform_tolerance")), 0.5))

    # -- trees --------------------------------------------------------------------------------
    def tree_for(self, kind: str, requested: str) -> tuple[Path, Tree]:
        """The tree a goal runs: ``requested`` (a file) or the navigator's default; loaded
        anew when the file differs from the last one (or ``always_reload_bt_xml``)."""
        assert self.tree_context is not None
        path = resolve_tree_path(requested) if requested else self.default_trees[kind]
        cached = self._trees.get(kind)
        if cached is not None and cached[0] == path and not bool(self.param("always_reload_bt_xml")):
            return cached
        tree = self.factory.create_tree_from_file(path, Blackboard(), self.tree_context)
        self._trees[kind] = (path, tree)
        return path, tree

    # -- goals --------------------------------------------------------------------------------
    async def _navigate_to_pose(self, handle: ServerGoalHandle) -> Any:
        return await self._navigate(handle, "navigate_to_pose")

    async def _navigate_through_poses(self, handle: ServerGoalHandle) -> Any:
        return await self._navigate(handle, "navigate_through_poses")

    def _load_goal(self, kind: str, goal: Any, bb: Blackboard) -> None:
        gf = str(self.param("global_frame"))
        bb.set(RECOVERIES_KEY, 0)
        if kind == "navigate_to_pose":
            g = goal.pose
            if not g.header.frame_id:
                g.header.frame_id = gf
            bb.set(str(self.param("goal_blackboard_id")), g)
        else:
            for g in goal.poses:
                if not g.header.frame_id:
                    g.header.frame_id = gf
            bb.set(str(self.param("goals_blackboard_id")), list(goal.poses))

    def error_code_keys(self) -> list[str]:
        """The blackboard entries a failed navigation takes its error code from."""
        names = [str(n) for n in self.param("error_code_names") or [] if n]
        names += [f"{p}_error_code" for p in self.param("error_code_name_prefixes") or [] if p]
        return list(dict.fromkeys(names))

    def _error_code(self, bb: Blackboard) -> int:
        codes = []
        for name in self.error_code_keys():
            try:
                code = int(bb.get(str(name), 0) or 0)
            except (TypeError, ValueError):
                continue
            if code:
                codes.append(code)
        return min(codes) if codes else 0

    async def _navigate(self, handle: ServerGoalHandle, kind: str) -> Any:
        from eddiebot.msgs.nav2_msgs import NavigateThroughPoses, NavigateToPose

        action = NavigateToPose if kind == "navigate_to_pose" else NavigateThroughPoses
        result = action.Result()
        assert self.tree_context is not None
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
        wait_ns = round(float(self.param("initial_pose_timeout")) * 1e9)
        deadline = self.now().nanoseconds + wait_ns
        while self._robot_pose_in() is None and self.now().nanoseconds < deadline \
                and not handle.is_cancel_requested:
            await sleep(self, int(self.param("bt_loop_duration")) / 1000.0)
        if handle.is_cancel_requested:
            handle.canceled()
            return result
        if self._robot_pose_in() is None:
            # Nav2's initializeGoalPose: no goal starts before the robot is localised
            result.error_msg = (f"{kind}: initial robot pose is not available "
                                f"({self.param('global_frame')} -> "
                                f"{self.param('robot_base_frame')})")
            self.get_logger().error(result.error_msg)
            handle.abort()
            return result
        requested = str(getattr(handle.request, "behavior_tree", "") or "")
        previous = self._handle
        running = previous is not None and previous.is_active and self._tree is not None \
            and self._kind == kind
        if running:
            path = resolve_tree_path(requested) if requested else self.default_trees[kind]
            if path != self._trees[kind][0]:
                result.error_msg = (f"{kind}: preemption refused: the new goal's tree {path} is "
                                    f"not the running one ({self._trees[kind][0]}); cancel the "
                                    f"running goal first")
                self.get_logger().warning(result.error_msg)
                handle.abort()
                return result
            self._handle = handle
            self.get_logger().info(f"{kind}: new goal preempts the running one")
            assert self._tree is not None
            self._load_goal(kind, handle.request, self._tree.blackboard)
            # the path the controller follows is the old goal's until the tree plans again
            # (its RateController ticks the planner up to a period later): see below
            preempted_at: int | None = self.tree_context.plan_requests
        else:
            preempted_at = None
            try:
                path, tree = self.tree_for(kind, requested)
            except TreeError as exc:
                result.error_msg = f"{kind}: {exc}"
                self.get_logger().error(f"{result.error_msg}; navigation canceled")
                handle.abort()
                return result
            if self._tree is not None:
                self._tree.halt()
            self._handle = handle
            self._tree = tree
            self._kind = kind
            tree.halt()
            self.tree_context.last_error_msg = ""
            self.tree_context.planned_request = None
            for name in self.error_code_keys():
                tree.blackboard.set(name, 0)
            self._load_goal(kind, handle.request, tree.blackboard)
            self._start_ns = self.now().nanoseconds
            g = poses[-1].pose.position if poses else None
            where = f"({g.x:.2f}, {g.y:.2f})" if g is not None else "no pose"
            self.get_logger().info(f"{kind}: begin navigating to {where} with {path.name}")
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
                tree.halt()
                self._finish(handle)
                handle.canceled()
                return result
            status = tree.tick_once()
            now = self.now().nanoseconds
            planned = self.tree_context.planned_request
            if status == Status.SUCCESS and preempted_at is not None and planned is not None \
                    and planned <= preempted_at:
                # the controller finished the preempted goal's path before a plan for this
                # goal came (Nav2's race, navigation2#920): that is not this goal reached.
                # Start the tree over, which plans for this goal at once.
                self.get_logger().info(f"{kind}: the preempted goal's path ended before one to "
                                       "the new goal was made; planning for the new goal")
                tree.halt()
                preempted_at = None
                await sleep(self, loop_s)
                continue
            if status == Status.SUCCESS:
                self.get_logger().info(f"{kind}: goal succeeded")
                tree.halt()
                self._finish(handle)
                handle.succeed()
                return result
            if status in (Status.FAILURE, Status.SKIPPED):
                result.error_code = self._error_code(tree.blackboard)
                result.error_msg = self.tree_context.last_error_msg or "navigation failed"
                self.get_logger().warning(f"{kind}: goal failed: {result.error_msg}")
                tree.halt()
                self._finish(handle)
                handle.abort()
                return result
            if now - last_fb >= fb_period_ns:
                last_fb = now
                handle.publish_feedback(self._feedback(action, now, tree.blackboard))
            await sleep(self, loop_s)

    def _finish(self, handle: ServerGoalHandle) -> None:
        if self._handle is handle:
            self._handle = None

    def _feedback(self, action: Any, now: int, bb: Blackboard) -> Any:
        fb = action.Feedback()
        gf = str(self.param("global_frame"))
        pose = robot_pose(self.tf_buffer, gf, str(self.param("robot_base_frame")), now,
                          max(float(self.param("transform_tolerance")), 0.5))
        path = bb.get(str(self.param("path_blackboard_id")))
        if pose is not None:
            fb.current_pose = pose_stamped(pose[0], pose[1], pose[2], gf, now)
            if path is not None and getattr(path, "poses", None):
                if self._path_xy[0] is not path:  # converted once per new path
                    self._path_xy = (path, path_from_msg(path)[:, :2])
                d = path_length_from(self._path_xy[1], pose[0], pose[1])
                fb.distance_remaining = float(d)
                if self._speed > 0.01:
                    fb.estimated_time_remaining = Duration.from_seconds(d / self._speed).to_msg()
        fb.navigation_time = Duration(now - self._start_ns).to_msg()
        fb.number_of_recoveries = int(bb.get(RECOVERIES_KEY, 0) or 0)
        if hasattr(fb, "number_of_poses_remaining"):
            fb.number_of_poses_remaining = len(bb.get(str(self.param("goals_blackboard_id")))
                                               or [])
        return fb
